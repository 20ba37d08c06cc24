"""Busts: head (eye sockets, brow, nose, lips, ears, hair volume), neck and shoulders.

Parts: skin, hair, eyebrows, eyes, lips, clothing. Shapes vary in head size and
proportions, jaw, eye spacing and height, socket depth, brow ridge, nose length and
projection, mouth, neck length and width, shoulder width, hair line and volume;
appearance in skin, hair, eye, lip and clothing colours, the neckline, and the cloth
pattern (plain, stripes, checks or mottled).
"""

from __future__ import annotations

import numpy as np

from data_gen.core import ObjectClass, SurfaceHits, hsv, mix, smoothstep
from data_gen.geometry import assemble, ellipsoid, limb, sphere_component
from data_gen.procedural import fbm, marble, stripes

__all__ = ["BUSTS"]

PARTS = ("skin", "hair", "eyebrows", "eyes", "lips", "clothing")
_LABEL = {part: i + 1 for i, part in enumerate(PARTS)}


def sample_params(rng: np.random.Generator) -> dict:
    """Shape and appearance parameters of one bust."""
    u = rng.uniform
    shape = {
        "head_width": u(0.27, 0.33),
        "head_height": u(0.37, 0.43),
        "head_depth": u(0.34, 0.4),
        "head_y": u(0.32, 0.4),
        "jaw": u(0.15, 0.35),
        "eye_spacing": u(0.3, 0.4),
        "eye_height": u(0.02, 0.14),
        "eye_width": u(0.2, 0.26),
        "socket": u(0.03, 0.07),
        "brow": u(0.02, 0.05),
        "nose_length": u(0.24, 0.36),
        "nose_projection": u(0.07, 0.13),
        "nose_width": u(0.04, 0.06),
        "mouth_y": u(-0.5, -0.4),
        "mouth_width": u(0.2, 0.3),
        "lip_height": u(0.04, 0.07),
        "neck_radius": u(0.12, 0.16),
        "neck_bottom": u(-0.36, -0.28),
        "shoulder_width": u(0.62, 0.74),
        "hairline": u(0.3, 0.62),
        "hair_back": u(-0.6, -0.1),
        "hair_volume": u(0.02, 0.09),
        "neckline": str(rng.choice(["round", "v"])),
        "neckline_depth": u(0.05, 0.25),
    }
    skin_hue, skin_value = u(0.03, 0.09), u(0.45, 0.95)
    hair_hue = u(0.04, 0.12)
    cloth_hue = u(0.0, 1.0)
    appearance = {
        "cloth_pattern": str(rng.choice(["plain", "stripes", "checks", "mottled"])),
        "cloth_frequency": u(3.0, 7.0),
        "texture_seed": int(rng.integers(2**31)),
        "palette": {
            "skin": [
                hsv(skin_hue, u(0.25, 0.5), skin_value),
                hsv(skin_hue - 0.02, u(0.4, 0.6), skin_value * 0.9),
            ],
            "hair": [
                hsv(hair_hue, u(0.2, 0.8), u(0.08, 0.8)),
                hsv(hair_hue, u(0.2, 0.8), u(0.05, 0.5)),
            ],
            "eyebrows": [hsv(hair_hue, u(0.3, 0.7), u(0.05, 0.3)), [0.05, 0.04, 0.03]],
            "eyes": [hsv(0.1, u(0.0, 0.1), u(0.8, 0.95)), hsv(u(0.05, 0.65), u(0.4, 0.8), 0.35)],
            "lips": [hsv(u(0.95, 1.02), u(0.35, 0.65), u(0.45, 0.8)), hsv(0.98, 0.5, 0.3)],
            "clothing": [
                hsv(cloth_hue, u(0.3, 0.9), u(0.25, 0.9)),
                hsv(cloth_hue + u(0.2, 0.8), u(0.1, 0.9), u(0.2, 0.95)),
            ],
        },
    }
    return {"shape": shape, "appearance": appearance}


def _gauss(d2: np.ndarray, sigma: float) -> np.ndarray:
    return np.exp(-d2 / (2 * sigma**2))


def _hair_mask(shape: dict, c: np.ndarray, seed: int) -> np.ndarray:
    """Soft hair region on the canonical head: above a line that falls from front to back."""
    front = smoothstep(-0.3, 0.9, c[:, 2])
    line = shape["hair_back"] + (shape["hairline"] - shape["hair_back"]) * front
    line = line - 0.25 * c[:, 0] ** 2 * front + 0.05 * fbm(c, seed=seed, frequency=3.0)
    return smoothstep(-0.03, 0.03, c[:, 1] - line)


def _head(shape: dict, seed: int):
    es, ey = shape["eye_spacing"], shape["eye_height"]
    center = np.array([0.0, shape["head_y"], 0.0])
    radii = np.array([shape["head_width"], shape["head_height"], shape["head_depth"]])

    def deform(c: np.ndarray) -> np.ndarray:
        front = np.clip(c[:, 2], 0, 1)
        lower = np.clip(-c[:, 1], 0, 1)
        scale = np.ones(len(c))
        sockets = _gauss((np.abs(c[:, 0]) - es) ** 2 + (c[:, 1] - ey) ** 2, 0.08)
        brow = _gauss((c[:, 1] - ey - 0.16) ** 2, 0.04) * _gauss(c[:, 0] ** 2, 0.35)
        lips = _gauss(
            (c[:, 0] / shape["mouth_width"]) ** 2 + ((c[:, 1] - shape["mouth_y"]) / 0.06) ** 2, 0.5
        )
        scale += front**2 * (shape["brow"] * brow - shape["socket"] * sockets + 0.03 * lips)
        scale += shape["hair_volume"] * _hair_mask(shape, c, seed)
        scale += 0.015 * fbm(c, octaves=3, seed=seed + 5, frequency=2.0)
        points = c * scale[:, None] * radii
        points[:, 0] *= 1.0 - shape["jaw"] * lower**1.5
        points[:, 2] *= 1.0 - 0.3 * shape["jaw"] * lower**1.5
        return points + center

    return deform


def build(params: dict):
    """The bust mesh: head, nose, ears, neck, torso and shoulders."""
    shape = params["shape"]
    seed = params["appearance"]["texture_seed"]
    deform = _head(shape, seed)
    head = sphere_component("head", deform, subdivisions=4)
    ey = shape["eye_height"]
    bridge = deform(np.array([[0.0, ey - 0.05, 0.99]]))[0]
    tip_c = np.array([[0.0, ey - shape["nose_length"], 0.97]])
    tip = deform(tip_c)[0] + np.array([0.0, 0.0, shape["nose_projection"]])
    bridge[2] -= 0.03
    nose = limb("nose", bridge, tip, 0.025, shape["nose_width"], subdivisions=2)
    ear_y = shape["head_y"] + 0.02 * shape["head_height"]
    ears = [
        ellipsoid(
            "ear",
            (side * shape["head_width"] * 0.95, ear_y, -0.02),
            (0.035, 0.08, 0.055),
            subdivisions=2,
        )
        for side in (-1, 1)
    ]
    neck_top = (0.0, shape["head_y"] - 0.5 * shape["head_height"], -0.05)
    neck = limb(
        "neck",
        neck_top,
        (0.0, shape["neck_bottom"], -0.04),
        shape["neck_radius"],
        shape["neck_radius"] * 1.15,
        subdivisions=2,
    )
    width = shape["shoulder_width"]
    torso_y = shape["neck_bottom"] - 0.74
    torso = ellipsoid("torso", (0.0, torso_y, -0.05), (width, 0.8, 0.26), subdivisions=3)
    shoulders = [
        limb(
            "torso",
            (0.0, shape["neck_bottom"] - 0.02, -0.05),
            (side * width * 0.82, shape["neck_bottom"] - 0.2, -0.05),
            0.13,
            0.15,
            subdivisions=2,
        )
        for side in (-1, 1)
    ]
    return assemble([head, nose, *ears, neck, torso, *shoulders])


def colorize(params: dict, hits: SurfaceHits) -> tuple[np.ndarray, np.ndarray]:
    """Part labels and unlit colours of the hits."""
    shape, look = params["shape"], params["appearance"]
    palette, seed = look["palette"], look["texture_seed"]
    n = len(hits.component)
    labels = np.full(n, _LABEL["skin"], dtype=np.uint8)
    c = hits.canonical
    grain = 1.0 + 0.06 * fbm(c, octaves=4, seed=seed + 1, frequency=5.0)
    es, ey = shape["eye_spacing"], shape["eye_height"]

    # Skin everywhere first: blush on the cheeks (canonical head coordinates).
    cheeks = _gauss((np.abs(c[:, 0]) - 0.45) ** 2 + (c[:, 1] - ey + 0.3) ** 2, 0.12)
    blush = np.where(hits.where("head"), cheeks, 0.0)
    rgb = mix(palette["skin"], blush, grain)

    head = hits.where("head") & (c[:, 2] > 0)
    eye_d = ((np.abs(c[:, 0]) - es) / (0.5 * shape["eye_width"])) ** 2 + (
        (c[:, 1] - ey) / (0.22 * shape["eye_width"])
    ) ** 2
    eyes = head & (eye_d < 1.0)
    iris = np.hypot(np.abs(c[:, 0]) - es, (c[:, 1] - ey)) < 0.2 * shape["eye_width"]
    rgb[eyes] = mix(palette["eyes"], iris[eyes].astype(np.float32))
    pupil = eyes & (np.hypot(np.abs(c[:, 0]) - es, (c[:, 1] - ey)) < 0.08 * shape["eye_width"])
    rgb[pupil] *= 0.25
    labels[eyes] = _LABEL["eyes"]

    arch = ey + 0.13 + 0.04 * (1 - ((np.abs(c[:, 0]) - es) / (0.7 * shape["eye_width"])) ** 2)
    brows = (
        head
        & (np.abs(c[:, 1] - arch) < 0.03)
        & (np.abs(np.abs(c[:, 0]) - es) < 0.7 * shape["eye_width"])
    )
    rgb[brows] = mix(palette["eyebrows"], 0.5 + 0.5 * fbm(c[brows], seed=seed, frequency=20.0))
    labels[brows] = _LABEL["eyebrows"]

    mouth = (c[:, 0] / (0.5 * shape["mouth_width"])) ** 2 + (
        (c[:, 1] - shape["mouth_y"]) / shape["lip_height"]
    ) ** 2
    lips = head & (mouth < 1.0)
    lip_line = np.abs(c[:, 1] - shape["mouth_y"]) < 0.008
    rgb[lips] = mix(palette["lips"], lip_line[lips].astype(np.float32) * 0.8, grain[lips])
    labels[lips] = _LABEL["lips"]

    hair = hits.where("head") & (_hair_mask(shape, c, seed) > 0.5) & ~eyes & ~brows
    strands = marble(c[hair], direction=(0.2, 1, 0.3), frequency=6.0, amplitude=2.0, seed=seed + 3)
    rgb[hair] = mix(palette["hair"], strands, grain[hair])
    labels[hair] = _LABEL["hair"]

    # Clothing on the torso and shoulders, with a neckline of skin (object coordinates).
    torso = hits.where("torso")
    p = hits.points
    neck_x = np.abs(p[:, 0]) / (shape["neck_radius"] * 1.8)
    if shape["neckline"] == "v":
        cut = shape["neck_bottom"] - 0.05 - shape["neckline_depth"] * np.clip(1 - neck_x, 0, 1)
    else:
        cut = (
            shape["neck_bottom"]
            - 0.05
            - shape["neckline_depth"] * np.sqrt(np.clip(1 - neck_x**2, 0, 1))
        )
    cloth = torso & ~((p[:, 1] > cut) & (p[:, 2] > -0.05) & (neck_x < 1))
    pc = p[cloth]
    frequency = look["cloth_frequency"]
    if look["cloth_pattern"] == "stripes":
        weave = stripes(pc, direction=(0, 1, 0), frequency=frequency, sharpness=6.0)
    elif look["cloth_pattern"] == "checks":
        weave = 0.5 * (
            stripes(pc, direction=(0, 1, 0), frequency=frequency, sharpness=6.0)
            + stripes(pc, direction=(1, 0, 0), frequency=frequency, sharpness=6.0)
        )
    elif look["cloth_pattern"] == "mottled":
        weave = 0.5 + 0.5 * fbm(pc, octaves=5, persistence=0.6, seed=seed + 4, frequency=4.0)
    else:
        weave = 0.15 * (1 + fbm(pc, seed=seed + 4, frequency=8.0))
    rgb[cloth] = mix(palette["clothing"], weave, grain[cloth])
    labels[cloth] = _LABEL["clothing"]
    return labels, rgb


BUSTS = ObjectClass(
    name="busts",
    parts=PARTS,
    default_size=(150, 200),
    frame=(-0.76, 0.76, -1.05, 0.85),
    depth_range=(-0.35, 0.6),
    sample_params=sample_params,
    build=build,
    colorize=colorize,
)
