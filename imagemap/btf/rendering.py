"""Rendering a material's BTF matrix: every (light, view) image of a hemisphere sampling.

:func:`render_btf_matrix` renders a :class:`~imagemap.btf.materials.Material` (how the
easy and the hard materials are shaded is told in :mod:`imagemap.btf.materials`): cast
shadows by :func:`shadow_mask`, the view rays of the hard materials by :func:`view_hits`.
:func:`ground_truth` is the experiment's material source.

Sampling (:func:`default_sampling`), directions as (theta, phi) in degrees,
theta the polar angle from the normal (the paper's theta_i):

* 33 lights: theta 0 (1), and 8 azimuths (0, 45, .., 315) at each of
  theta 22, 45, 60 and 75; so theta 22 at phi 0, 90, 180, 270 is there, the
  paper's constraint images;
* 9 views: top (0, 0), theta 30 at phi 0, 90, 180, 270 and theta 60 at phi 45,
  135, 225, 315;
* RGB: 33 x 9 x 3 = 891 rows.

Example
-------
>>> from imagemap.btf.materials import make_material
>>> from imagemap.btf.rendering import default_sampling, render_btf_matrix
>>> material = make_material("leather", size=64, seed=0)
>>> lights, views = default_sampling()
>>> S = render_btf_matrix(material, lights, views)
>>> S.shape
(891, 4096)
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from imagemap.btf.materials import (
    FIBRE_COVER,
    VARNISH_MAX_TILT,
    VARNISH_SHININESS,
    Material,
    make_material,
)
from imagemap.io import InputError

__all__ = ["default_sampling", "ground_truth", "render_btf_matrix", "shadow_mask", "view_hits"]


def default_sampling() -> tuple[np.ndarray, np.ndarray]:
    """The hemisphere sampling: 33 light and 9 view directions, (theta, phi) degrees.

    Example
    -------
    >>> lights, views = default_sampling()
    >>> lights.shape, views.shape
    ((33, 2), (9, 2))
    """
    lights = [(0.0, 0.0)]
    for theta in (22.0, 45.0, 60.0, 75.0):
        lights += [(theta, phi) for phi in np.arange(0.0, 360.0, 45.0)]
    views = [(0.0, 0.0)]
    views += [(30.0, phi) for phi in (0.0, 90.0, 180.0, 270.0)]
    views += [(60.0, phi) for phi in (45.0, 135.0, 225.0, 315.0)]
    return np.array(lights, dtype=np.float32), np.array(views, dtype=np.float32)


def _unit(theta: float, phi: float) -> np.ndarray:
    t, p = np.deg2rad(theta), np.deg2rad(phi)
    # x along image columns, y along image rows, z out of the surface.
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], np.float32)


def shadow_mask(
    height: np.ndarray, theta: float, phi: float, *, max_steps: int = 96, softness: float = 0.7
) -> np.ndarray:
    """Lit fraction (1 lit, 0 in cast shadow) of each texel for a light at (theta, phi).

    Marches towards the light one texel at a time: a texel is shadowed where the
    height field, shifted by s steps along the light's horizontal direction, rises
    above the ray's height h + s * cot(theta). Each step is one whole-image shift.

    Example
    -------
    >>> h = np.zeros((16, 16), np.float32); h[:, 8] = 10.0
    >>> bool(shadow_mask(h, 60.0, 0.0, softness=0)[4, 6] < 0.5)  # wall at x=8, light from +x
    True
    """
    height = np.asarray(height, dtype=np.float32)
    if theta <= 0.0:
        return np.ones_like(height)
    if theta >= 90.0:
        return np.zeros_like(height)
    direction = _unit(theta, phi)
    horizontal = direction[:2] / np.linalg.norm(direction[:2])
    rise = float(direction[2] / np.linalg.norm(direction[:2]))  # height per texel
    relief = float(height.max() - height.min())
    steps = int(min(max_steps, np.ceil(relief / max(rise, 1e-6))))
    blocked = np.zeros(height.shape, dtype=bool)
    for step in range(1, steps + 1):
        # The height at p + step * horizontal: shift the image by -step * horizontal.
        ahead = ndimage.shift(
            height, (-step * horizontal[1], -step * horizontal[0]), order=1, mode="nearest"
        )
        blocked |= ahead > height + step * rise
    lit = (~blocked).astype(np.float32)
    if softness > 0:
        lit = ndimage.gaussian_filter(lit, softness)  # a small penumbra, no aliasing
    return lit


def render_btf_matrix(
    material: Material,
    light_dirs: np.ndarray,
    view_dirs: np.ndarray,
    *,
    ambient: float = 0.08,
    intensity: float = 0.85,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Render every (light, view) image into the BTF matrix S, (n_rows, H*W) float32.

    Rows in (light, view, channel) C order, as :class:`imagemap.btf.BTF` expects;
    written straight into ``out`` (or a new array) so no image stack is copied.

    Parameters
    ----------
    material : Material
    light_dirs, view_dirs : (n, 2) (theta, phi) degrees
    ambient : float
        Ambient light, scaled by the local occlusion.
    intensity : float
        Radiance of the directional light.
    out : ndarray, optional
        Preallocated (n_rows, H*W) float32.

    Returns
    -------
    S : ndarray (n_lights * n_views * 3, H*W) float32
    """
    light_dirs = np.asarray(light_dirs, np.float32).reshape(-1, 2)
    view_dirs = np.asarray(view_dirs, np.float32).reshape(-1, 2)
    height = material.height
    size_h, size_w = (n - 2 * material.margin for n in height.shape)
    n_rows = len(light_dirs) * len(view_dirs) * 3
    if out is None:
        out = np.empty((n_rows, size_h * size_w), np.float32)
    elif out.shape != (n_rows, size_h * size_w) or out.dtype != np.float32:
        raise InputError(f"out: expected float32 {(n_rows, size_h * size_w)}, got {out.shape}")
    if material.hard:
        return _render_layered(material, light_dirs, view_dirs, ambient, intensity, out)
    grad_y, grad_x = np.gradient(height.astype(np.float32))
    normals = np.stack([-grad_x, -grad_y, np.ones_like(grad_x)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    # Ambient occlusion: texels below their surroundings see less of the sky.
    cavity = ndimage.gaussian_filter(height, 4.0) - height
    occlusion = np.clip(1.0 - 0.25 * cavity, 0.2, 1.0).astype(np.float32)
    stack = out.reshape(len(light_dirs), len(view_dirs), 3, size_h, size_w)
    for li, (lt, lp) in enumerate(light_dirs):
        light = _unit(float(lt), float(lp))
        cos_light = normals @ light
        lit = shadow_mask(height, float(lt), float(lp)) * (cos_light > 0)
        diffuse = ambient * occlusion + intensity * np.clip(cos_light, 0, None) * lit
        for vi, (vt, vp) in enumerate(view_dirs):
            halfway = light + _unit(float(vt), float(vp))
            halfway /= np.linalg.norm(halfway)
            cos_half = np.clip(normals @ halfway, 0, None)
            specular = intensity * material.gloss * lit * cos_half**material.shininess
            radiance = material.albedo * diffuse[..., None] + specular[..., None]
            stack[li, vi] = np.moveaxis(radiance, 2, 0)
    return out


def view_hits(height: np.ndarray, theta: float, phi: float, margin: int, *, step: float = 0.5):
    """Where each texel's view ray meets the height field: (y, x) in ``height``'s grid.

    The texels are the points p of the reference plane z = 0 in the inner region
    (``margin`` cut off each side). The ray from p towards a viewer at (theta, phi)
    is at p + z tan(theta) (cos phi, sin phi) at height z; marching z down from
    the highest point in steps of ``step`` texels across, the first z with
    h(ray(z)) >= z is the visible surface point (refined linearly between the
    last two steps). Whatever lies above the ray before it is hidden: parallax
    and self-occlusion. A top view (theta 0) sees every texel in place.

    Returns
    -------
    y, x : (h, w) float32 each, coordinates into ``height``.

    Example
    -------
    >>> h = np.zeros((40, 40), np.float32); h[10:30, 10:30] = 4.0
    >>> y, x = view_hits(h, 45.0, 0.0, margin=10)
    >>> float(x[5, 15]) - (15 + 10)  # a plateau texel 4 high is seen 4 texels on
    4.0
    """
    height = np.asarray(height, np.float32)
    full_h, full_w = height.shape
    ys, xs = np.mgrid[margin : full_h - margin, margin : full_w - margin].astype(np.float32)
    if theta <= 0.0:
        return ys, xs
    across = np.tan(np.deg2rad(theta))
    dx = np.float32(across * np.cos(np.deg2rad(phi)))
    dy = np.float32(across * np.sin(np.deg2rad(phi)))
    top, bottom = float(height.max()), float(height.min())
    n_steps = max(int(np.ceil((top - bottom) * across / step)), 1) + 1
    hit = np.full(ys.shape, np.nan, np.float32)
    previous_z, previous_f = None, None
    for z in np.linspace(top, bottom, n_steps, dtype=np.float32):
        ahead = ndimage.map_coordinates(height, [ys + z * dy, xs + z * dx], order=1, mode="nearest")
        f = ahead - z
        new = (f >= 0) & np.isnan(hit)
        if new.any():
            if previous_f is None:
                hit[new] = z
            else:
                # f crosses 0 between the previous z (f < 0) and this one (f >= 0).
                t = previous_f[new] / (previous_f[new] - f[new])
                hit[new] = previous_z + t * (z - previous_z)
        previous_z, previous_f = z, f
    hit = np.where(np.isnan(hit), np.float32(bottom), hit)
    return ys + hit * dy, xs + hit * dx


def _normals(height: np.ndarray) -> np.ndarray:
    grad_y, grad_x = np.gradient(height.astype(np.float32))
    normals = np.stack([-grad_x, -grad_y, np.ones_like(grad_x)], axis=0)
    return normals / np.linalg.norm(normals, axis=0, keepdims=True)


def _varnish_normals(height: np.ndarray) -> np.ndarray:
    """The varnish's own surface: the height field levelled (blurred), tilt clipped."""
    levelled = ndimage.gaussian_filter(height.astype(np.float32), 8.0)
    grad_y, grad_x = np.gradient(levelled)
    slope = np.hypot(grad_x, grad_y)
    limit = np.float32(np.tan(np.deg2rad(VARNISH_MAX_TILT)))
    scale = np.minimum(1.0, limit / np.maximum(slope, 1e-12)).astype(np.float32)
    normals = np.stack([-grad_x * scale, -grad_y * scale, np.ones_like(grad_x)], axis=0)
    return normals / np.linalg.norm(normals, axis=0, keepdims=True)


def _render_layered(material, light_dirs, view_dirs, ambient, intensity, out) -> np.ndarray:
    """Hard materials: ray-marched views, cast shadows at the hit, varnish, fibres.

    Per view, every surface field is looked up where the texel's view ray hits
    the height field (:func:`view_hits`); per light, the cast shadow is computed
    on the whole padded surface (:func:`shadow_mask`) and looked up there too.
    Shading at the hit point:

        base = albedo * (ambient * occlusion + cos(n, l) * shadow)
               + gloss * shadow * cos(n, h) ** shininess
        varnish: + strength * shadow * cos(n_v, h) ** VARNISH_SHININESS
        fibres:  (1 - a) * base + a * fibre_albedo * (ambient + 0.8 sin(theta_l) shadow)
                 + a * 0.15 * forward sheen,   a = 1 - exp(-FIBRE_COVER rho tan theta_v)
    """
    height = material.height
    margin = material.margin
    size_h, size_w = height.shape[0] - 2 * margin, height.shape[1] - 2 * margin
    n_rows = len(light_dirs) * len(view_dirs) * 3
    if out is None:
        out = np.empty((n_rows, size_h * size_w), np.float32)
    elif out.shape != (n_rows, size_h * size_w) or out.dtype != np.float32:
        raise InputError(f"out: expected float32 {(n_rows, size_h * size_w)}, got {out.shape}")
    cavity = ndimage.gaussian_filter(height, 4.0) - height
    occlusion = np.clip(1.0 - 0.25 * cavity, 0.2, 1.0).astype(np.float32)
    fields = {
        "normal": _normals(height),
        "albedo": np.moveaxis(material.albedo, 2, 0),
        "gloss": material.gloss[None],
        "shininess": material.shininess[None],
        "occlusion": occlusion[None],
    }
    if material.varnish is not None:
        fields["varnish"] = material.varnish[None]
        fields["varnish_normal"] = _varnish_normals(height)
    if material.fibres is not None:
        fields["fibres"] = material.fibres[None]
        fields["fibre_albedo"] = np.moveaxis(material.fibre_albedo, 2, 0)
    # Per view: the hit points and every field looked up there.
    views = []
    for vt, vp in view_dirs:
        ys, xs = view_hits(height, float(vt), float(vp), margin)
        if float(vt) <= 0.0:
            inner = (slice(None), slice(margin, margin + size_h), slice(margin, margin + size_w))
            looked = {k: np.ascontiguousarray(f[inner]) for k, f in fields.items()}
        else:
            looked = {
                k: np.stack(
                    [ndimage.map_coordinates(c, [ys, xs], order=1, mode="nearest") for c in f]
                )
                for k, f in fields.items()
            }
        looked["normal"] /= np.linalg.norm(looked["normal"], axis=0, keepdims=True)
        views.append((ys, xs, looked))
    stack = out.reshape(len(light_dirs), len(view_dirs), 3, size_h, size_w)
    for li, (lt, lp) in enumerate(light_dirs):
        light = _unit(float(lt), float(lp))
        shadow = shadow_mask(height, float(lt), float(lp))
        for vi, (vt, vp) in enumerate(view_dirs):
            ys, xs, f = views[vi]
            if float(vt) <= 0.0:
                lit = shadow[margin : margin + size_h, margin : margin + size_w]
            else:
                lit = ndimage.map_coordinates(shadow, [ys, xs], order=1, mode="nearest")
            view = _unit(float(vt), float(vp))
            halfway = light + view
            halfway /= np.linalg.norm(halfway)
            cos_light = np.einsum("c,chw->hw", light, f["normal"])
            lit_here = lit * (cos_light > 0)
            diffuse = (
                ambient * f["occlusion"][0] + intensity * np.clip(cos_light, 0, None) * lit_here
            )
            cos_half = np.clip(np.einsum("c,chw->hw", halfway, f["normal"]), 0, None)
            specular = intensity * f["gloss"][0] * lit_here * cos_half ** f["shininess"][0]
            if "varnish" in f:
                cos_varnish = np.clip(np.einsum("c,chw->hw", halfway, f["varnish_normal"]), 0, None)
                specular = (
                    specular + intensity * f["varnish"][0] * lit * cos_varnish**VARNISH_SHININESS
                )
            radiance = f["albedo"] * diffuse + specular
            if "fibres" in f and float(vt) > 0.0:
                cover = 1.0 - np.exp(-FIBRE_COVER * f["fibres"][0] * np.tan(np.deg2rad(float(vt))))
                side = (
                    light[:2]
                    @ view[:2]
                    / max(float(np.linalg.norm(light[:2]) * np.linalg.norm(view[:2])), 1e-6)
                )
                sheen = 0.15 * intensity * max(-side, 0.0) ** 4 * float(np.sin(np.deg2rad(lt)))
                fibre = (
                    f["fibre_albedo"]
                    * (ambient + 0.8 * intensity * float(np.sin(np.deg2rad(lt))) * lit)
                    + sheen * lit
                )
                radiance = (1.0 - cover) * radiance + cover * fibre
            stack[li, vi] = radiance
    return out


def ground_truth(name: str, size: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Material ``name`` rendered under :func:`default_sampling`: (S, light_dirs, view_dirs).

    The material source of :mod:`imagemap.btf.experiment`, which knows every name in
    :data:`MATERIALS` by this function.
    """
    lights, views = default_sampling()
    return (
        render_btf_matrix(make_material(name, size=size, seed=seed), lights, views),
        lights,
        views,
    )
