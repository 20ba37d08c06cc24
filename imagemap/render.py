"""Previews: normals from height or depth maps, normal maps, bump-mapped shading, relief views.

The classic tools of texture mapping (lecture notes "More Texture Mapping"):
surface normals from a height map by central finite differences, normal maps stored as RGB,
Lambert and Blinn-Phong shading of a bumped surface under a chosen light, and a textured
relief view of a depth map with its image-map like Fig. 2d-e of Hassner & Basri,
*Automatic Depth-Map Colorization* (2006).

Frame
-----
All vectors live in the image frame: x along the columns (to the right), y up the screen
(towards row 0) and z out of the screen towards the viewer, a right-handed frame. A height
(or depth, larger = nearer) is a displacement along +z, so a flat height map has the normal
(0, 0, 1) and a light (0, 0, 1) shines straight down on it.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from imagemap.io import InputError

__all__ = [
    "BACKGROUND",
    "decode_normal_map",
    "direction_from_angles",
    "display_gamma",
    "encode_normal_map",
    "normals_from_depth",
    "normals_from_height",
    "preview_pair",
    "relief_view",
    "shade",
]

#: Background colour of previews (light grey: neither black nor white image-maps vanish).
BACKGROUND = (0.82, 0.82, 0.84)

#: Display gamma of linear renderings (BTF images, relit previews).
DISPLAY_GAMMA = 2.2


def display_gamma(linear: np.ndarray, gamma: float = DISPLAY_GAMMA) -> np.ndarray:
    """Linear radiance clipped to [0, 1] and gamma-encoded for display.

    Examples
    --------
    >>> float(display_gamma(np.array(0.25), 2.0))
    0.5
    """
    return np.clip(np.asarray(linear, dtype=np.float32), 0.0, 1.0) ** np.float32(1.0 / gamma)


def direction_from_angles(elevation: float, azimuth: float) -> np.ndarray:
    """Unit vector from an elevation above the surface and an azimuth, both in degrees.

    Azimuth 0 points along +x (right), 90 along +y (up the screen); elevation 90 is +z.

    Examples
    --------
    >>> direction_from_angles(90.0, 0.0).round(6)
    array([0., 0., 1.], dtype=float32)
    """
    el, az = np.deg2rad(elevation), np.deg2rad(azimuth)
    return np.array(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], dtype=np.float32
    )


def _unit(vector, name: str) -> np.ndarray:
    vector = np.asarray(vector, dtype=np.float32).reshape(-1)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise InputError(f"{name}: expected a finite 3-vector, got {vector!r}")
    norm = float(np.linalg.norm(vector))
    if norm == 0.0:
        raise InputError(f"{name}: zero vector has no direction")
    return vector / norm


def normals_from_height(
    height: np.ndarray, *, scale: float = 1.0, periodic: bool = False
) -> np.ndarray:
    """Unit surface normals of a height map by central finite differences.

    The outward normal of the surface z = scale * h(x, y) is (-dz/dx, -dz/dy, 1), normalized
    (lecture, "Bump Map"); derivatives are central differences, one-sided at the border.

    Parameters
    ----------
    height : ndarray, shape (H, W)
        Height in units of ``1 / scale`` pixels.
    scale : float
        Height of one unit of ``height`` in pixels (the bump strength).
    periodic : bool
        Wrap around at the borders (tileable height maps, no border artefact).

    Returns
    -------
    normals : ndarray of float32, shape (H, W, 3)

    Examples
    --------
    >>> normals_from_height(np.zeros((4, 4)))[0, 0]
    array([0., 0., 1.], dtype=float32)
    """
    height = np.asarray(height, dtype=np.float32)
    if height.ndim != 2:
        raise InputError(f"height: expected a 2-D array, got shape {height.shape}")
    if periodic:
        d_row = (np.roll(height, -1, axis=0) - np.roll(height, 1, axis=0)) / 2.0
        d_col = (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1)) / 2.0
    else:
        d_row, d_col = np.gradient(height)
    # y points up the screen, i.e. against the row index.
    normals = np.stack([0.0 - scale * d_col, scale * d_row, np.ones_like(height)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return normals.astype(np.float32)


def normals_from_depth(
    depth: np.ndarray, *, relief: float | None = None, mask: np.ndarray | None = None
) -> np.ndarray:
    """Normals of a depth map (larger = nearer, 0 = background) without silhouette cliffs.

    Background pixels take the depth of the nearest foreground pixel before differencing, so
    the jump at the silhouette does not tilt the rim normals; background normals are (0, 0, 1).

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Depth in [0, 1]; background 0.
    relief : float, optional
        Pixels of relief for one unit of depth; default a quarter of the larger image side.
    mask : ndarray of bool, optional
        Foreground; default ``depth > 0``.

    Returns
    -------
    normals : ndarray of float32, shape (H, W, 3)
    """
    depth = np.asarray(depth, dtype=np.float32)
    if depth.ndim != 2:
        raise InputError(f"depth: expected a 2-D array, got shape {depth.shape}")
    mask = depth > 0 if mask is None else np.asarray(mask, dtype=bool)
    relief = 0.25 * max(depth.shape) if relief is None else float(relief)
    filled = depth
    if mask.any() and not mask.all():
        nearest = ndimage.distance_transform_edt(~mask, return_distances=False, return_indices=True)
        filled = depth[tuple(nearest)]
    normals = normals_from_height(filled, scale=relief)
    normals[~mask] = (0.0, 0.0, 1.0)
    return normals


def encode_normal_map(normals: np.ndarray) -> np.ndarray:
    """Normal map to RGB in [0, 1]: (N + 1) / 2 (the lecture's 255 (N + 1) / 2, unit range).

    Examples
    --------
    >>> encode_normal_map(np.array([[[0.0, 0.0, 1.0]]]))
    array([[[0.5, 0.5, 1. ]]], dtype=float32)
    """
    normals = np.asarray(normals, dtype=np.float32)
    if normals.shape[-1] != 3:
        raise InputError(f"normals: last axis must have 3 components, got shape {normals.shape}")
    return np.clip((normals + 1.0) / 2.0, 0.0, 1.0).astype(np.float32)


def decode_normal_map(rgb: np.ndarray) -> np.ndarray:
    """RGB normal map in [0, 1] (or uint8) back to unit normals: N = 2 RGB - 1, renormalized.

    Renormalizing undoes most of the quantization of an 8-bit file.
    """
    rgb = np.asarray(rgb)
    if rgb.shape[-1] != 3:
        raise InputError(f"normal map: last axis must have 3 channels, got shape {rgb.shape}")
    if rgb.dtype == np.uint8:
        rgb = rgb.astype(np.float32) / 255.0
    normals = 2.0 * rgb.astype(np.float32) - 1.0
    norm = np.linalg.norm(normals, axis=-1, keepdims=True)
    return (normals / np.maximum(norm, 1e-12)).astype(np.float32)


def shade(
    normals: np.ndarray,
    albedo: np.ndarray | float = 1.0,
    *,
    light: np.ndarray | tuple = (0.0, 0.0, 1.0),
    view: np.ndarray | tuple = (0.0, 0.0, 1.0),
    model: str = "lambert",
    light_intensity: float = 1.0,
    ambient: float = 0.0,
    specular: float = 0.3,
    shininess: float = 32.0,
    mask: np.ndarray | None = None,
    background=BACKGROUND,
) -> np.ndarray:
    """Shade a surface given by its normals under one distant light.

    Lambert: ``albedo * (ambient + I * max(0, n.l))``; Blinn-Phong adds
    ``I * specular * max(0, n.h) ** shininess`` with the half vector h = (l + v) / |l + v|,
    only where n.l > 0. Bump mapping is this function applied to
    :func:`normals_from_height` of a height map.

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)
        Unit normals in the image frame (see module docstring).
    albedo : ndarray (H, W, 3) or (H, W), or float
        Diffuse reflectance (the image-map).
    light, view : 3-vectors
        Directions towards the light and towards the viewer (normalized here).
    model : {"lambert", "blinn_phong"}
    light_intensity, ambient, specular, shininess : float
    mask : ndarray of bool (H, W), optional
        Where the surface is; elsewhere ``background``.
    background : 3 floats

    Returns
    -------
    image : ndarray of float32, shape (H, W, 3); not clipped (values may exceed 1).

    Examples
    --------
    >>> flat = np.zeros((2, 2, 3), np.float32); flat[..., 2] = 1
    >>> round(float(shade(flat, 0.5, light=(0, 1, 1))[0, 0, 0]), 4)
    0.3536
    """
    normals = np.asarray(normals, dtype=np.float32)
    if normals.ndim != 3 or normals.shape[2] != 3:
        raise InputError(f"normals: expected shape (H, W, 3), got {normals.shape}")
    if model not in ("lambert", "blinn_phong"):
        raise InputError(f"model: expected 'lambert' or 'blinn_phong', got {model!r}")
    light_dir = _unit(light, "light")
    albedo = np.asarray(albedo, dtype=np.float32)
    if albedo.ndim == 2:
        albedo = albedo[..., None]
    if albedo.ndim == 3 and albedo.shape[:2] != normals.shape[:2]:
        raise InputError(f"albedo: shape {albedo.shape} does not match normals {normals.shape}")
    cosine = normals @ light_dir
    lit = np.maximum(cosine, 0.0)[..., None]
    image = albedo * (ambient + light_intensity * lit)
    if model == "blinn_phong":
        half = _unit(light_dir + _unit(view, "view"), "light + view")
        highlight = np.maximum(normals @ half, 0.0) ** shininess * (cosine > 0)
        image = image + light_intensity * specular * highlight[..., None]
    image = np.broadcast_to(image, normals.shape).astype(np.float32, copy=True)
    if mask is not None:
        image[~np.asarray(mask, dtype=bool)] = background
    return image


def relief_view(
    depth: np.ndarray,
    image: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    tilt: float = 40.0,
    turn: float = -25.0,
    relief: float | None = None,
    light: np.ndarray | tuple = (-0.4, 0.5, 0.77),
    ambient: float = 0.25,
    supersample: int = 2,
    output_shape: tuple[int, int] | None = None,
    background=BACKGROUND,
) -> np.ndarray:
    """Textured 3D view of a depth map with its image-map (Fig. 2e of the depth-map paper).

    Every foreground pixel becomes a surface point (x, y, relief * depth) coloured by the
    image-map and Lambert-shaded from its depth normals; the points are turned about the
    screen's vertical axis by ``turn``, tipped back by ``tilt`` about the horizontal axis,
    projected orthographically and splatted with a z-buffer (nearest point wins) on a
    ``supersample``-times finer canvas, which is then reduced by area averaging.

    Parameters
    ----------
    depth : ndarray (H, W)
        Depth in [0, 1], larger = nearer, background 0.
    image : ndarray (H, W, 3)
        The image-map, aligned with ``depth``.
    mask : ndarray of bool, optional
        Foreground; default ``depth > 0``.
    tilt, turn : float
        Degrees; ``tilt=0, turn=0`` is the front view.
    relief : float, optional
        Pixels of relief per unit depth; default a quarter of the larger side.
    light : 3-vector
        Light direction in the object's frame.
    ambient : float
    supersample : int
        Splatting resolution factor (holes on steep slopes shrink with it).
    output_shape : (int, int), optional
        Default the shape of ``depth``.
    background : 3 floats

    Returns
    -------
    view : ndarray of float32, shape output_shape + (3,), in [0, 1]

    Examples
    --------
    >>> d = np.zeros((32, 32), np.float32); d[8:24, 8:24] = 0.5
    >>> relief_view(d, np.ones((32, 32, 3), np.float32)).shape
    (32, 32, 3)
    """
    depth = np.asarray(depth, dtype=np.float32)
    image = np.asarray(image, dtype=np.float32)
    if depth.ndim != 2:
        raise InputError(f"depth: expected a 2-D array, got shape {depth.shape}")
    if image.shape != depth.shape + (3,):
        raise InputError(f"image: shape {image.shape} does not match depth {depth.shape}")
    mask = depth > 0 if mask is None else np.asarray(mask, dtype=bool)
    height, width = depth.shape
    out_h, out_w = output_shape or (height, width)
    relief = 0.25 * max(height, width) if relief is None else float(relief)
    canvas = np.empty((out_h * supersample, out_w * supersample, 3), np.float32)
    canvas[:] = background
    if not mask.any():
        return _reduce(canvas, supersample)

    normals = normals_from_depth(depth, relief=relief, mask=mask)
    colour = shade(normals, image, light=light, ambient=ambient, light_intensity=1.0 - ambient)
    # Upsample the surface so that neighbouring points land on neighbouring canvas pixels.
    zoom = float(supersample) * 1.5
    rows, cols = np.nonzero(ndimage.zoom(mask.astype(np.float32), zoom, order=0) > 0.5)
    src_r = (rows + 0.5) / zoom - 0.5
    src_c = (cols + 0.5) / zoom - 0.5
    coords = np.stack([src_r, src_c])
    # Interpolate a background-filled depth: the rim must not droop towards depth 0.
    nearest = ndimage.distance_transform_edt(~mask, return_distances=False, return_indices=True)
    z = ndimage.map_coordinates(depth[tuple(nearest)], coords, order=1, mode="nearest") * relief
    rgb = np.stack(
        [
            ndimage.map_coordinates(colour[..., c], coords, order=1, mode="nearest")
            for c in range(3)
        ],
        axis=-1,
    )
    x = src_c - (width - 1) / 2.0
    y = (height - 1) / 2.0 - src_r
    turn_r, tilt_r = np.deg2rad(turn), np.deg2rad(tilt)
    x1 = x * np.cos(turn_r) + z * np.sin(turn_r)
    z1 = -x * np.sin(turn_r) + z * np.cos(turn_r)
    # Tipping the top away from the viewer: screen-up mixes y and z, nearness likewise.
    screen_y = y * np.cos(tilt_r) + z1 * np.sin(tilt_r)
    nearness = z1 * np.cos(tilt_r) - y * np.sin(tilt_r)
    span = max(np.ptp(x1), np.ptp(screen_y), 1.0)
    fit = 0.92 * min(out_h, out_w) * supersample / span
    col = np.round((x1 - (x1.max() + x1.min()) / 2) * fit + canvas.shape[1] / 2).astype(np.int64)
    row = np.round(canvas.shape[0] / 2 - (screen_y - (screen_y.max() + screen_y.min()) / 2) * fit)
    row = row.astype(np.int64)
    inside = (row >= 0) & (row < canvas.shape[0]) & (col >= 0) & (col < canvas.shape[1])
    flat = row[inside] * canvas.shape[1] + col[inside]
    order = np.lexsort((nearness[inside], flat))  # by pixel, then nearest last
    last = np.r_[flat[order][1:] != flat[order][:-1], True]
    winners = order[last]
    canvas.reshape(-1, 3)[flat[winners]] = rgb[inside][winners]
    # Steep slopes spread the points apart: fill the gaps that lie inside the closed
    # footprint from the nearest written pixel (a standard splatting hole fill).
    written = np.zeros(canvas.shape[:2], bool)
    written.reshape(-1)[flat[winners]] = True
    footprint = ndimage.binary_closing(written, structure=np.ones((2 * supersample + 3,) * 2))
    holes = footprint & ~written
    if holes.any():
        nearest = ndimage.distance_transform_edt(
            ~written, return_distances=False, return_indices=True
        )
        canvas[holes] = canvas[nearest[0][holes], nearest[1][holes]]
    return np.clip(_reduce(canvas, supersample), 0.0, 1.0)


def _reduce(canvas: np.ndarray, factor: int) -> np.ndarray:
    if factor == 1:
        return canvas
    h, w = canvas.shape[0] // factor, canvas.shape[1] // factor
    return canvas.reshape(h, factor, w, factor, 3).mean(axis=(1, 3)).astype(np.float32)


def preview_pair(
    depth: np.ndarray,
    synthesized_rgb: np.ndarray,
    reference_rgb: np.ndarray,
    *,
    reference_mask: np.ndarray | None = None,
    light: np.ndarray | tuple = (-0.4, 0.5, 0.77),
    tilt: float = 40.0,
    turn: float = -25.0,
    relief: float | None = None,
    gutter: int = 4,
) -> np.ndarray:
    """The result rendered on its depth beside the best example's map on the same depth.

    A 2 x 2 sheet like Fig. 2d-e of the depth-map paper: left column the synthesized
    image-map, right column the reference (best database example's) image-map; top row the
    depth seen from the front, bump-shaded (Lambert) with the map as albedo; bottom row a
    textured relief view (:func:`relief_view`). Foreground pixels that the reference map does
    not cover (``reference_mask`` False) are painted red, as in Fig. 4 of the paper.

    Parameters
    ----------
    depth : ndarray (H, W)
        Query depth in [0, 1], background 0.
    synthesized_rgb : ndarray (H, W, 3)
        The synthesized image-map for ``depth``.
    reference_rgb : ndarray (h, w, 3)
        The reference image-map, already aligned with ``depth``; resized (bilinear) if its
        shape differs.
    reference_mask : ndarray of bool, optional
        Where the reference map has colour (its own foreground), aligned like the map.
    light : 3-vector
    tilt, turn, relief : see :func:`relief_view`.
    gutter : int
        Pixels of background between the panels.

    Returns
    -------
    sheet : ndarray of float32, shape (2 H + 3 gutter, 2 W + 3 gutter, 3), in [0, 1]

    Examples
    --------
    >>> d = np.zeros((32, 32), np.float32); d[8:24, 8:24] = 0.5
    >>> preview_pair(d, np.ones((32, 32, 3)), np.zeros((32, 32, 3)), gutter=2).shape
    (70, 70, 3)
    """
    from skimage.transform import resize  # deferred: start-up (0.4 s; only the preview resizes)

    depth = np.asarray(depth, dtype=np.float32)
    if depth.ndim != 2:
        raise InputError(f"depth: expected a 2-D array, got shape {depth.shape}")
    synthesized = np.asarray(synthesized_rgb, dtype=np.float32)
    if synthesized.shape != depth.shape + (3,):
        raise InputError(
            f"synthesized image-map: shape {synthesized.shape} does not match depth {depth.shape}"
        )
    reference = np.asarray(reference_rgb, dtype=np.float32)
    if reference.ndim != 3 or reference.shape[2] != 3:
        raise InputError(f"reference image-map: expected (h, w, 3), got {reference.shape}")
    if reference.shape[:2] != depth.shape:
        reference = resize(reference, depth.shape, order=1, anti_aliasing=True)
    mask = depth > 0
    if reference_mask is not None:
        covered = np.asarray(reference_mask, dtype=bool)
        if covered.shape != depth.shape:
            covered = resize(covered.astype(np.float32), depth.shape, order=0) > 0.5
        reference = reference.copy()
        reference[mask & ~covered] = (1.0, 0.0, 0.0)
    normals = normals_from_depth(depth, relief=relief, mask=mask)
    panels = []
    for image_map in (synthesized, reference):
        front = shade(normals, image_map, light=light, ambient=0.25, light_intensity=0.75)
        front[~mask] = BACKGROUND
        oblique = relief_view(depth, image_map, tilt=tilt, turn=turn, relief=relief, light=light)
        panels.append((np.clip(front, 0.0, 1.0), oblique))
    height, width = depth.shape
    sheet = np.empty((2 * height + 3 * gutter, 2 * width + 3 * gutter, 3), np.float32)
    sheet[:] = BACKGROUND
    for column, (front, oblique) in enumerate(panels):
        x0 = gutter + column * (width + gutter)
        sheet[gutter : gutter + height, x0 : x0 + width] = front
        sheet[2 * gutter + height : 2 * gutter + 2 * height, x0 : x0 + width] = oblique
    return sheet
