"""Fish: a deformed-sphere body, fan-shaped fins and tail, a bulging eye; head to the left.

Parts: back, belly, fins, tail, eye, gill line. Shapes vary in length, height,
thickness, hump, tail size and fork, fin positions and sizes, eye position and bumps;
appearance varies in hues, the back/belly boundary, and the back's pattern (vertical
bars, spots or marble mottling).
"""

from __future__ import annotations

import numpy as np

from data_gen.core import ObjectClass, SurfaceHits, hsv, mix, smoothstep
from data_gen.geometry import Component, _outward, assemble, ellipsoid, sphere_component
from data_gen.procedural import fbm, marble, spots, stripes

__all__ = ["FISH"]

PARTS = ("back", "belly", "fins", "tail", "eye", "gill")
_LABEL = {part: i + 1 for i, part in enumerate(PARTS)}


def sample_params(rng: np.random.Generator) -> dict:
    """Shape and appearance parameters of one fish."""
    u = rng.uniform
    length = u(1.7, 2.0)
    shape = {
        "length": length,
        "height": length * u(0.28, 0.48),
        "thickness": length * u(0.12, 0.18),
        "back_ratio": u(0.45, 0.62),
        "peduncle": u(0.15, 0.3),
        "taper_start": u(0.3, 0.5),
        "hump": u(-0.02, 0.08),
        "bump": u(0.01, 0.04),
        "tail_length": length * u(0.22, 0.34),
        "tail_spread": length * u(0.16, 0.3),
        "tail_fork": u(0.0, 0.45),
        "dorsal_t": u(0.3, 0.5),
        "dorsal_base": length * u(0.15, 0.3),
        "dorsal_height": length * u(0.08, 0.18),
        "dorsal_sweep": u(0.3, 1.1),
        "anal_t": u(0.58, 0.72),
        "anal_height": length * u(0.05, 0.1),
        "pectoral_t": u(0.24, 0.34),
        "pectoral_length": length * u(0.1, 0.17),
        "pectoral_angle": u(-70.0, -30.0),
        "eye_t": u(0.07, 0.12),
        "eye_v": u(0.15, 0.4),
        "eye_radius": length * u(0.025, 0.04),
        "gill_t": u(0.19, 0.26),
        "gill_curve": u(0.03, 0.08),
    }
    back_hue = u(0.0, 1.0)
    appearance = {
        "pattern": str(rng.choice(["bars", "spots", "marble"])),
        "pattern_frequency": u(2.5, 5.0),
        "boundary": u(-0.25, 0.15),
        "boundary_wave": u(0.0, 0.12),
        "boundary_phase": u(0.0, 2 * np.pi),
        "texture_seed": int(rng.integers(2**31)),
        "palette": {
            "back": [
                hsv(back_hue, u(0.45, 0.85), u(0.3, 0.6)),
                hsv(back_hue + u(-0.15, 0.15), u(0.5, 0.95), u(0.6, 0.9)),
            ],
            "belly": [
                hsv(u(0.05, 0.2), u(0.05, 0.35), u(0.8, 0.98)),
                hsv(back_hue, u(0.1, 0.3), u(0.7, 0.9)),
            ],
            "fins": [
                hsv(back_hue + u(0.3, 0.7), u(0.5, 0.9), u(0.6, 0.95)),
                hsv(back_hue + u(0.3, 0.7), u(0.4, 0.9), u(0.3, 0.6)),
            ],
            "tail": [
                hsv(back_hue + u(-0.2, 0.2), u(0.5, 0.9), u(0.5, 0.9)),
                hsv(back_hue + u(0.3, 0.7), u(0.5, 0.9), u(0.2, 0.5)),
            ],
            "eye": [hsv(u(0.05, 0.2), u(0.6, 1.0), u(0.7, 1.0)), [0.03, 0.03, 0.03]],
            "gill": [hsv(back_hue, u(0.3, 0.6), u(0.15, 0.3)), hsv(0.0, u(0.4, 0.7), 0.35)],
        },
    }
    return {"shape": shape, "appearance": appearance}


def _body(shape: dict, seed: int):
    """The body deformation: canonical unit-sphere points -> object space."""
    length, height = shape["length"], shape["height"]

    def deform(c: np.ndarray) -> np.ndarray:
        t = (c[:, 0] + 1.0) / 2.0  # 0 at the head (x = -L/2), 1 at the tail
        taper = 1.0 - (1.0 - shape["peduncle"]) * smoothstep(shape["taper_start"], 1.0, t)
        # Smooth switch between the back and belly half-heights (no crease at the midline).
        upper = 0.5 + 0.5 * np.tanh(3.0 * c[:, 1])
        half_height = height * ((1 - shape["back_ratio"]) + (2 * shape["back_ratio"] - 1) * upper)
        bumps = 1.0 + shape["bump"] * fbm(c * 1.5, octaves=3, seed=seed)
        x = c[:, 0] * length / 2
        y = c[:, 1] * half_height * taper * bumps + shape["hump"] * height * np.sin(np.pi * t)
        z = c[:, 2] * shape["thickness"] / 2 * taper**0.8 * bumps
        return np.stack([x, y, z], axis=1)

    return deform


def _fin(
    name: str,
    base: np.ndarray,
    along: tuple[float, float],
    length: float,
    base_half_width: float,
    tip_half_width: float,
    thickness: float,
    fork: float = 0.0,
    sweep: float = 0.0,
) -> Component:
    """A thin fan: from ``base`` along the 2-D direction ``along``; straight (or forked) tip.

    The unit sphere is mapped onto a slab: s = (x + 1) / 2 along the fin, and the
    (y, z) disc at each s is stretched to the full width, so the ends become flat
    edges. ``sweep`` shears the tip towards the across direction (a raked fin).
    """
    along_vec = np.array([along[0], along[1], 0.0]) / np.hypot(*along)
    across_vec = np.array([-along_vec[1], along_vec[0], 0.0])

    def deform(c: np.ndarray) -> np.ndarray:
        s = (c[:, 0] + 1.0) / 2.0
        ring = np.sqrt(np.maximum(1.0 - c[:, 0] ** 2, 1e-4))
        q = c[:, 1] / ring
        w = c[:, 2] / ring
        half_width = base_half_width + (tip_half_width - base_half_width) * s
        reach = length * s * (1.0 - fork * (1.0 - q**2))
        across = q * half_width + sweep * reach
        thick = thickness * (1.0 - 0.6 * s) * w
        return (
            base
            + reach[:, None] * along_vec
            + across[:, None] * across_vec
            + thick[:, None] * [0, 0, 1]
        )

    canonical_sphere = sphere_component(name, deform, subdivisions=3)
    # Canonical coordinates of a fin: s along, q across, in [0, 1] x [-1, 1].
    c = canonical_sphere.canonical
    ring = np.sqrt(np.maximum(1.0 - c[:, 0] ** 2, 1e-4))
    canonical_sphere.canonical = np.stack([(c[:, 0] + 1) / 2, c[:, 1] / ring, c[:, 2] / ring], 1)
    return _outward(canonical_sphere)


def _surface_point(deform, t: float, v: float) -> np.ndarray:
    """Point of the body's near (+z) side at body fraction t and height fraction v."""
    cx = 2 * t - 1
    cz = np.sqrt(max(1.0 - cx**2 - v**2, 0.0))
    return deform(np.array([[cx, v, cz]]))[0]


def build(params: dict):
    """The fish mesh: body, tail, dorsal, anal and pectoral fins, eye."""
    shape = params["shape"]
    seed = params["appearance"]["texture_seed"]
    deform = _body(shape, seed)
    body = sphere_component("body", deform, subdivisions=4)
    length, height = shape["length"], shape["height"]
    thin = 0.012 * length

    tail_base = deform(np.array([[0.93, 0.0, 0.0]]))[0]
    half_peduncle = 0.5 * shape["peduncle"] * height * 0.5
    tail = _fin(
        "tail",
        tail_base,
        (1.0, 0.0),
        shape["tail_length"],
        half_peduncle,
        shape["tail_spread"],
        thin,
        fork=shape["tail_fork"],
    )
    top = deform(np.array([[2 * shape["dorsal_t"] - 1, 1.0 - 1e-3, 0.0]]))[0]
    top[1] -= 0.03 * height
    dorsal = _fin(
        "dorsal_fin",
        top,
        (0.0, 1.0),
        shape["dorsal_height"],
        shape["dorsal_base"] / 2,
        shape["dorsal_base"] / 5,
        thin,
        sweep=-shape["dorsal_sweep"],
    )
    bottom = deform(np.array([[2 * shape["anal_t"] - 1, -(1.0 - 1e-3), 0.0]]))[0]
    bottom[1] += 0.03 * height
    anal = _fin(
        "anal_fin",
        bottom,
        (0.0, -1.0),
        shape["anal_height"],
        shape["dorsal_base"] / 3,
        shape["dorsal_base"] / 8,
        thin,
        sweep=shape["dorsal_sweep"] * 0.8,
    )
    side = _surface_point(deform, shape["pectoral_t"], -0.25)
    angle = np.radians(shape["pectoral_angle"])
    side[2] += 0.4 * thin
    pectoral = _fin(
        "pectoral_fin",
        side,
        (np.cos(angle), np.sin(angle)),
        shape["pectoral_length"],
        0.04 * length,
        0.06 * length,
        thin * 0.6,
    )
    radius = shape["eye_radius"]
    eye_center = _surface_point(deform, shape["eye_t"], shape["eye_v"])
    eye_center[2] -= 0.45 * radius
    eye = ellipsoid("eye", eye_center, (radius, radius, radius), subdivisions=2)
    return assemble([body, tail, dorsal, anal, pectoral, eye])


def colorize(params: dict, hits: SurfaceHits) -> tuple[np.ndarray, np.ndarray]:
    """Part labels and unlit colours of the hits."""
    shape, look = params["shape"], params["appearance"]
    palette, seed = look["palette"], look["texture_seed"]
    n = len(hits.component)
    labels = np.zeros(n, dtype=np.uint8)
    rgb = np.zeros((n, 3), dtype=np.float32)
    c = hits.canonical
    grain = 1.0 + 0.08 * fbm(c, octaves=4, seed=seed + 1, frequency=4.0)

    body = hits.where("body")
    cb = c[body]
    t = (cb[:, 0] + 1) / 2
    v = cb[:, 1]
    boundary = (
        look["boundary"]
        + look["boundary_wave"] * np.sin(2 * np.pi * 1.5 * t + look["boundary_phase"])
        + 0.06 * fbm(cb, seed=seed + 2, frequency=3.0)
    )
    gill_offset = t - (shape["gill_t"] + shape["gill_curve"] * v**2)
    gill = (np.abs(gill_offset) < 0.012) & (np.abs(v) < 0.75)
    back = (v > boundary) & ~gill
    belly = ~back & ~gill
    if look["pattern"] == "bars":
        pattern = stripes(
            cb, direction=(1, 0, 0), frequency=look["pattern_frequency"], warp=0.15, seed=seed
        )
    elif look["pattern"] == "spots":
        pattern = spots(cb, frequency=look["pattern_frequency"] * 1.5, radius=0.3, seed=seed)
    else:
        pattern = marble(
            cb, direction=(1, 0.3, 0), frequency=look["pattern_frequency"] / 2, seed=seed
        )
    body_rgb = np.empty((len(cb), 3), dtype=np.float32)
    body_rgb[back] = mix(palette["back"], pattern[back], grain[body][back])
    counter_shade = smoothstep(-1.0, 0.3, v[belly])  # belly darkens towards the flank
    body_rgb[belly] = mix(palette["belly"], counter_shade, grain[body][belly])
    body_rgb[gill] = mix(palette["gill"], 0.5 + 0.5 * np.sin(40 * v[gill]))
    body_labels = np.where(gill, _LABEL["gill"], np.where(back, _LABEL["back"], _LABEL["belly"]))
    labels[body], rgb[body] = body_labels, body_rgb

    fins = hits.where("dorsal_fin", "anal_fin", "pectoral_fin")
    rays = stripes(c[fins][:, [1, 0, 2]], direction=(1, 0, 0), frequency=4.0, sharpness=2.0)
    fin_shade = 0.6 * rays * (0.3 + 0.7 * c[fins][:, 0])
    labels[fins], rgb[fins] = _LABEL["fins"], mix(palette["fins"], fin_shade, grain[fins])

    tail = hits.where("tail")
    ct = c[tail]
    tail_band = smoothstep(0.55, 0.75, ct[:, 0]) * (0.6 + 0.4 * np.abs(ct[:, 1]))
    tail_rays = 0.25 * stripes(ct[:, [1, 0, 2]], direction=(1, 0, 0), frequency=5.0)
    rgb[tail] = mix(palette["tail"], np.clip(tail_band + tail_rays, 0, 1), grain[tail])
    labels[tail] = _LABEL["tail"]

    eye = hits.where("eye")
    radial = np.hypot(c[eye][:, 0], c[eye][:, 1])
    pupil = smoothstep(0.5, 0.42, radial)
    labels[eye], rgb[eye] = _LABEL["eye"], mix(palette["eye"], pupil)
    return labels, rgb


FISH = ObjectClass(
    name="fish",
    parts=PARTS,
    default_size=(200, 150),
    frame=(-1.02, 1.62, -0.68, 0.76),
    depth_range=(-0.15, 0.28),
    sample_params=sample_params,
    build=build,
    colorize=colorize,
)
