"""Humans: full figures of tapered capsules and ellipsoids in varied poses, facing the camera.

Parts: skin, hair, shirt, trousers, shoes. Shapes vary in height, build (shoulder and
hip width, girth, leg length, head size) and pose (arm abduction and swing, elbow
bend, leg spread and swing, knee bend, a turn of the whole body); appearance in skin,
hair, shirt, trouser and shoe colours, sleeve and trouser lengths, and the shirt
pattern (plain, stripes, checks, spots).
"""

from __future__ import annotations

import numpy as np
import trimesh

from data_gen.core import ObjectClass, SurfaceHits, hsv, mix
from data_gen.geometry import assemble, ellipsoid, limb
from data_gen.procedural import fbm, spots, stripes

__all__ = ["HUMANS"]

PARTS = ("skin", "hair", "shirt", "trousers", "shoes")
_LABEL = {part: i + 1 for i, part in enumerate(PARTS)}


def sample_params(rng: np.random.Generator) -> dict:
    """Shape, pose and appearance parameters of one figure."""
    u = rng.uniform
    shape = {
        "height": u(1.6, 1.8),
        "shoulder_width": u(0.85, 1.15),
        "hip_width": u(0.85, 1.15),
        "girth": u(0.85, 1.2),
        "leg_ratio": u(0.95, 1.05),
        "head_size": u(0.9, 1.1),
        "turn": u(-25.0, 25.0),
        "arms": [
            {"abduction": u(5.0, 55.0), "swing": u(-30.0, 40.0), "elbow": u(0.0, 90.0)}
            for _ in range(2)
        ],
        "legs": [
            {"abduction": u(0.0, 15.0), "swing": u(-20.0, 25.0), "knee": u(0.0, 40.0)}
            for _ in range(2)
        ],
        "hairline": u(0.1, 0.5),
        "hair_back": u(-0.7, -0.1),
        "sleeve": float(rng.choice([0.0, 0.5, 1.0])),  # fraction of the forearm covered
        "trouser": float(rng.choice([0.0, 0.7, 1.0])),  # fraction of the shin covered
    }
    skin_hue, skin_value = u(0.03, 0.09), u(0.45, 0.95)
    shirt_hue = u(0.0, 1.0)
    appearance = {
        "shirt_pattern": str(rng.choice(["plain", "stripes", "checks", "spots"])),
        "shirt_frequency": u(6.0, 12.0),
        "texture_seed": int(rng.integers(2**31)),
        "palette": {
            "skin": [
                hsv(skin_hue, u(0.25, 0.5), skin_value),
                hsv(skin_hue - 0.02, u(0.4, 0.6), skin_value * 0.85),
            ],
            "hair": [
                hsv(u(0.04, 0.12), u(0.2, 0.8), u(0.08, 0.8)),
                hsv(u(0.04, 0.12), u(0.2, 0.8), u(0.05, 0.4)),
            ],
            "shirt": [
                hsv(shirt_hue, u(0.3, 0.95), u(0.3, 0.95)),
                hsv(shirt_hue + u(0.2, 0.8), u(0.1, 0.9), u(0.2, 0.95)),
            ],
            "trousers": [
                hsv(u(0.55, 0.7), u(0.2, 0.8), u(0.15, 0.6)),
                hsv(u(0.0, 1.0), u(0.1, 0.5), u(0.1, 0.4)),
            ],
            "shoes": [hsv(u(0.0, 1.0), u(0.0, 0.6), u(0.05, 0.9)), [0.1, 0.1, 0.1]],
        },
    }
    return {"shape": shape, "appearance": appearance}


def _direction(side: float, outward: float, forward: float) -> np.ndarray:
    """Unit vector pointing down, tilted ``outward`` (degrees, to ``side``) and ``forward``."""
    a, f = np.radians(outward), np.radians(forward)
    return np.array([side * np.sin(a) * np.cos(f), -np.cos(a) * np.cos(f), np.sin(f)])


def build(params: dict):
    """The figure: head, neck, torso, pelvis, arms with hands, legs with feet."""
    shape = params["shape"]
    s = shape["height"] / 1.75  # proportions are set for a 1.75 m figure, then scaled
    girth = shape["girth"]
    hip_y = 0.93 * s * shape["leg_ratio"]
    chest_y = hip_y + 0.5 * s
    shoulder_x = 0.19 * s * shape["shoulder_width"]
    hip_x = 0.09 * s * shape["hip_width"]
    head_r = 0.11 * s * shape["head_size"]
    head_y = chest_y + 0.1 * s + head_r

    parts = [
        ellipsoid("head", (0, head_y, 0), (0.85 * head_r, head_r, 0.95 * head_r), subdivisions=3),
        limb(
            "neck",
            (0, chest_y - 0.02 * s, -0.01),
            (0, head_y - 0.5 * head_r, 0),
            0.05 * s,
            0.045 * s,
        ),
        limb(
            "torso",
            (0, hip_y + 0.12 * s, 0),
            (0, chest_y - 0.03 * s, 0),
            0.15 * s * girth,
            0.17 * s * girth,
            flatten=0.65,
            up_hint=(1, 0, 0),
            subdivisions=3,
        ),
        ellipsoid(
            "chest", (0, chest_y - 0.06 * s, 0), (shoulder_x + 0.03 * s, 0.09 * s, 0.11 * s * girth)
        ),
        ellipsoid(
            "pelvis",
            (0, hip_y + 0.02 * s, 0),
            (hip_x + 0.08 * s * girth, 0.11 * s, 0.11 * s * girth),
        ),
    ]
    for side, arm in zip((-1.0, 1.0), shape["arms"], strict=True):
        shoulder = np.array([side * shoulder_x, chest_y - 0.04 * s, 0.0])
        upper = _direction(side, arm["abduction"], arm["swing"])
        elbow = shoulder + 0.3 * s * upper
        lower = _direction(side, arm["abduction"] * 0.7, arm["swing"] + arm["elbow"])
        wrist = elbow + 0.26 * s * lower
        hand = wrist + 0.08 * s * lower
        r = 0.045 * s * girth
        parts += [
            limb("upper_arm", shoulder, elbow, r * 1.1, r * 0.85),
            limb("forearm", elbow, wrist, r * 0.85, r * 0.65),
            limb("hand", wrist, hand, r * 0.7, r * 0.6, flatten=0.6),
        ]
    for side, leg in zip((-1.0, 1.0), shape["legs"], strict=True):
        hip = np.array([side * hip_x, hip_y, 0.0])
        thigh = _direction(side, leg["abduction"], leg["swing"])
        knee = hip + 0.44 * s * shape["leg_ratio"] * thigh
        shin = _direction(side, leg["abduction"] * 0.5, leg["swing"] - leg["knee"])
        ankle = knee + 0.42 * s * shape["leg_ratio"] * shin
        toe = ankle + s * np.array([side * 0.03, -0.06, 0.2])
        r = 0.07 * s * girth
        parts += [
            limb("thigh", hip, knee, r * 1.05, r * 0.75, subdivisions=3),
            limb("shin", knee, ankle, r * 0.72, r * 0.5),
            limb(
                "foot",
                ankle + s * np.array([0, -0.02, -0.03]),
                toe,
                0.04 * s,
                0.045 * s,
                flatten=0.6,
                up_hint=(1, 0, 0),
            ),
        ]
    assembly = assemble(parts)
    # Turn the whole figure about the vertical axis through its middle.
    turn = trimesh.transformations.rotation_matrix(np.radians(shape["turn"]), [0, 1, 0])
    assembly.mesh.apply_transform(turn)
    return assembly


def colorize(params: dict, hits: SurfaceHits) -> tuple[np.ndarray, np.ndarray]:
    """Part labels and unlit colours of the hits."""
    shape, look = params["shape"], params["appearance"]
    palette, seed = look["palette"], look["texture_seed"]
    n = len(hits.component)
    c = hits.canonical
    grain = 1.0 + 0.06 * fbm(c, octaves=4, seed=seed + 1, frequency=5.0)
    labels = np.full(n, _LABEL["skin"], dtype=np.uint8)
    rgb = mix(palette["skin"], 0.3 + 0.3 * fbm(c, seed=seed + 2, frequency=2.0), grain)

    # The trunk's pattern is laid in body coordinates (turn undone), the limbs' along them.
    unturn = trimesh.transformations.rotation_matrix(np.radians(-shape["turn"]), [0, 1, 0])
    body_points = trimesh.transform_points(hits.points, unturn)
    trunk = hits.where("torso", "chest")
    pattern_points = np.where(trunk[:, None], body_points, c * np.array([0.05, 0.05, 0.3]))

    # along-limb fraction t is canonical[:, 2] for limbs
    shirt = trunk | hits.where("upper_arm") | (hits.where("forearm") & (c[:, 2] < shape["sleeve"]))
    sp = pattern_points[shirt]
    frequency = look["shirt_frequency"]
    if look["shirt_pattern"] == "stripes":
        weave = stripes(sp, direction=(0, 1, 0), frequency=frequency, sharpness=6.0)
    elif look["shirt_pattern"] == "checks":
        weave = 0.5 * (
            stripes(sp, direction=(0, 1, 0), frequency=frequency, sharpness=6.0)
            + stripes(sp, direction=(1, 0, 0), frequency=frequency, sharpness=6.0)
        )
    elif look["shirt_pattern"] == "spots":
        weave = spots(sp, frequency=frequency, radius=0.25, seed=seed)
    else:
        weave = 0.15 * (1 + fbm(sp, seed=seed + 4, frequency=10.0))
    rgb[shirt] = mix(palette["shirt"], weave, grain[shirt])
    labels[shirt] = _LABEL["shirt"]

    trousers = hits.where("pelvis", "thigh") | (hits.where("shin") & (c[:, 2] < shape["trouser"]))
    folds = 0.5 + 0.5 * fbm(c[trousers] * np.array([1.0, 1.0, 4.0]), seed=seed + 5)
    rgb[trousers] = mix(palette["trousers"], folds, grain[trousers])
    labels[trousers] = _LABEL["trousers"]

    shoes = hits.where("foot")
    sole = (c[shoes][:, 0] ** 2 > 0.6).astype(np.float32)  # the rim of the flattened side
    rgb[shoes] = mix(palette["shoes"], sole, grain[shoes])
    labels[shoes] = _LABEL["shoes"]

    head = hits.where("head")
    front = np.clip((c[:, 2] + 0.3) / 1.2, 0, 1)
    line = shape["hair_back"] + (shape["hairline"] - shape["hair_back"]) * front
    line = line + 0.05 * fbm(c, seed=seed + 6, frequency=3.0)
    hair = head & (c[:, 1] > line)
    strands = 0.5 + 0.5 * fbm(c[hair] * np.array([6.0, 1.0, 6.0]), seed=seed + 7)
    rgb[hair] = mix(palette["hair"], strands, grain[hair])
    labels[hair] = _LABEL["hair"]
    return labels, rgb


HUMANS = ObjectClass(
    name="humans",
    parts=PARTS,
    default_size=(150, 200),
    frame=(-0.72, 0.72, -0.05, 1.87),
    depth_range=(-0.6, 0.75),
    sample_params=sample_params,
    build=build,
    colorize=colorize,
)
