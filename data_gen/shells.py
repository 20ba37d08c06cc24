"""Shells: a tortoise seen from above, its carapace divided into plates by grooves.

Parts: plate, groove, rim, skin. The carapace is an elongated dome (length, width,
height, flatness of the top, where its crest lies, a sloping rim) whose upper part is
divided into plates: the Voronoi cells of a jittered hexagonal grid of seeds (spacing,
jitter, phase and turn of the grid differ in every instance, so do the number, size and
places of the plates); below them a rim of marginal plates. The grooves between plates
are carved into the mesh (the surface moved inwards by a groove profile of the distance
to the nearest plate border), so the depth shows them; the paint follows the same
borders: each plate in the instance's palette with growth rings around its own seed and
radial streaks, the grooves dark, the marginals in their own tones. Head, neck, legs and
tail are the skin.

The plate layout and the groove profile are one function of the surface's canonical
coordinates (:func:`plate_field`), evaluated at the mesh's vertices for the relief and
at every ray hit for the paint, so relief and paint agree wherever the mesh resolves
the groove.

Example
-------
>>> import data_gen
>>> data_gen.CLASSES["shells"].parts, data_gen.CLASSES["shells"].default_size
(('plate', 'groove', 'rim', 'skin'), (200, 150))
>>> shell = data_gen.make_instance("shells", 0, seed=0)  # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np

from data_gen.core import ObjectClass, SurfaceHits, hsv, mix, smoothstep
from data_gen.geometry import Component, _outward, assemble, ellipsoid, limb
from data_gen.procedural import fbm

__all__ = ["SHELLS", "plate_field", "ring_sphere", "uv_layout"]

PARTS = ("plate", "groove", "rim", "skin")
_LABEL = {part: i + 1 for i, part in enumerate(PARTS)}
#: The carapace's mesh: rings of latitude on the unit sphere this far apart (radians)
#: above the equator, their vertices as far apart along the ring, so that edges are
#: 0.011-0.016 object units (0.7-1.1 px at the default 200x150) and a groove of
#: half-width 0.018-0.026 spans a few vertices (about 57,000 faces); underneath, which the
#: view does not see, rings 0.3 apart.
CARAPACE_STEP = 0.015
PLASTRON_STEP = 0.3
#: A point is in a groove (label and dark paint) within this many groove half-widths of
#: a plate border: where the groove profile exp(-b^2 / 2 w^2) is deeper than half.
GROOVE_LABEL_WIDTHS = float(np.sqrt(2.0 * np.log(2.0)))


def _quarter_meridian(a: float, c: float) -> float:
    """A quarter of the perimeter of the ellipse of semi-axes a and c (Ramanujan)."""
    return float(np.pi / 4 * (3 * (a + c) - np.sqrt((3 * a + c) * (a + 3 * c))))


def _unrolled_to_canonical(
    u: np.ndarray, v: np.ndarray, reach: tuple[float, float], theta_max: float
) -> np.ndarray:
    """Canonical unit-sphere points (N, 3) of unrolled dome coordinates (object units).

    (u, v) are arc lengths from the top of the dome (along the length and the width):
    the polar angle grows linearly with them, to ``theta_max`` (the rim) at ``reach``.
    """
    s = np.hypot(u / reach[0], v / reach[1])
    return _from_polar(theta_max * s, np.arctan2(v / reach[1], u / reach[0]))


def sample_params(rng: np.random.Generator) -> dict:
    """Shape, plate layout and appearance parameters of one tortoise."""
    u = rng.uniform
    length = u(1.75, 2.1)
    shape = {
        "length": length,
        "width": length * u(0.66, 0.8),
        "height": length * u(0.22, 0.32),
        "dome_power": u(0.55, 0.9),  # below 1: a flatter top and steeper sides
        "crest": u(-0.08, 0.12),  # the highest point moves back (+) or forward (-)
        "rim_band": u(0.17, 0.24),  # canonical polar angle (radians) of the rim
        "brim": u(0.08, 0.15),  # the rim's share of the footprint's half-axes
        "rim_height": u(0.15, 0.3),  # the rim's upper edge, a share of the height
        "plastron": u(0.06, 0.12),
        "groove_width": u(0.018, 0.026),
        "groove_depth": u(0.03, 0.05),
        "plate_bulge": u(0.0, 0.025),
        "plate_spacing": u(0.34, 0.52),
        "plate_jitter": u(0.1, 0.3),
        "grid_angle": u(-20.0, 20.0),
        "grid_phase": [u(0.0, 1.0), u(0.0, 1.0)],
        "marginals": int(rng.integers(16, 29)),
        "marginal_phase": u(0.0, 1.0),
        "head_length": length * u(0.14, 0.19),
        "head_turn": u(-20.0, 20.0),
        "neck_out": u(0.5, 1.0),
        "leg_length": length * u(0.08, 0.12),
        "leg_spread": [u(20.0, 50.0) for _ in range(4)],
        "tail_length": length * u(0.04, 0.07),
    }
    shape["marginal_jitter"] = [u(-0.2, 0.2) for _ in range(shape["marginals"])]
    shape["plate_seeds"] = _plate_seeds(shape, rng)
    hue = u(0.02, 0.2)
    appearance = {
        "rings": int(rng.integers(3, 7)),
        "ring_strength": u(0.3, 0.7),
        "streaks": int(rng.integers(5, 10)),
        "streak_strength": u(0.0, 0.55),
        "areola": u(0.12, 0.3),
        "areola_dark": bool(rng.random() < 0.5),
        "plate_shades": [u(0.88, 1.0) for _ in shape["plate_seeds"]],
        "texture_seed": int(rng.integers(2**31)),
        "palette": {
            "plate": [
                hsv(hue, u(0.35, 0.75), u(0.55, 0.9)),
                hsv(hue + u(-0.04, 0.04), u(0.5, 0.9), u(0.18, 0.42)),
            ],
            "groove": [
                hsv(hue, u(0.3, 0.6), u(0.05, 0.12)),
                hsv(hue + u(-0.03, 0.03), u(0.2, 0.5), u(0.12, 0.2)),
            ],
            "rim": [
                hsv(hue + u(-0.05, 0.05), u(0.3, 0.7), u(0.5, 0.85)),
                hsv(hue + u(-0.05, 0.05), u(0.5, 0.9), u(0.2, 0.4)),
            ],
            "skin": [
                hsv(u(0.05, 0.2), u(0.15, 0.5), u(0.4, 0.7)),
                hsv(u(0.05, 0.2), u(0.2, 0.6), u(0.15, 0.32)),
            ],
        },
    }
    return {"shape": shape, "appearance": appearance}


def _reach(shape: dict) -> tuple[float, float]:
    """Arc lengths from the top of the dome to the rim, along the length and the width."""
    rise = shape["height"] * (1.0 - shape["rim_height"])
    inner = 1.0 - shape["brim"]
    return (
        _quarter_meridian(inner * shape["length"] / 2, rise),
        _quarter_meridian(inner * shape["width"] / 2, rise),
    )


def _plate_seeds(shape: dict, rng: np.random.Generator) -> list[list[float]]:
    """Canonical points (x, y, z) of the plates' seeds: a jittered, turned and shifted
    hexagonal grid on the unrolled dome, kept above the rim."""
    spacing = shape["plate_spacing"]
    reach = _reach(shape)
    extent = max(reach) + spacing
    rows = np.arange(-np.ceil(extent / spacing) - 1, np.ceil(extent / spacing) + 2)
    cols = rows.copy()
    grid_row, grid_col = np.meshgrid(rows, cols, indexing="ij")
    x = (grid_col + 0.5 * (grid_row % 2) + shape["grid_phase"][0]) * spacing
    y = (grid_row + shape["grid_phase"][1]) * spacing * np.sqrt(3) / 2
    angle = np.radians(shape["grid_angle"])
    u = np.cos(angle) * x.ravel() - np.sin(angle) * y.ravel()
    v = np.sin(angle) * x.ravel() + np.cos(angle) * y.ravel()
    jitter = rng.uniform(-1.0, 1.0, (2, u.size)) * shape["plate_jitter"] * spacing
    u, v = u + jitter[0], v + jitter[1]
    rim_theta = 0.5 * np.pi - shape["rim_band"]
    canonical = _unrolled_to_canonical(u, v, reach, rim_theta)
    # A third of a plate inside the rim: the outer plates end at the rim's groove.
    radius = np.hypot(u / reach[0], v / reach[1])
    keep = radius < 1.0 - 0.35 * spacing / min(reach)
    keep[np.argmin(radius)] = True  # one plate at least
    return [[float(c) for c in p] for p in canonical[keep]]


def _zip_rings(upper: np.ndarray, lower: np.ndarray, start_upper: float, start_lower: float):
    """Triangles (N, 3) joining two rings of vertex ids (angles ascending from their start).

    Each triangle goes upper, lower, next, so the strip is consistently wound; a ring of
    one vertex (a pole) makes a fan.
    """
    m, n = len(upper), len(lower)
    angle_upper = start_upper + 2 * np.pi * np.arange(m + 1) / m
    angle_lower = start_lower + 2 * np.pi * np.arange(n + 1) / n
    i = j = 0
    triangles = []
    while i < m or j < n:
        if j < n and (i == m or angle_lower[j + 1] < angle_upper[i + 1]):
            triangles.append((upper[i % m], lower[j % n], lower[(j + 1) % n]))
            j += 1
        else:
            triangles.append((upper[i % m], lower[j % n], upper[(i + 1) % m]))
            i += 1
    faces = np.array(triangles, dtype=np.int64)
    keep = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    return faces[keep]


def ring_sphere(step: float, step_below: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed triangulated unit sphere of rings of latitude: (vertices (V, 3), faces (F, 3)).

    Above the equator the rings are ``step`` apart (radians) and each ring's vertices
    about ``step`` apart along it; below, ``step_below``. The equator is one of the rings.

    Example
    -------
    >>> import trimesh
    >>> vertices, faces = ring_sphere(0.3, 0.6)
    >>> sphere = trimesh.Trimesh(vertices, faces, process=False)
    >>> sphere.is_watertight, sphere.is_winding_consistent, round(float(sphere.area), 1)
    (True, True, 12.0)
    """
    above = int(np.ceil(0.5 * np.pi / step))
    below = int(np.ceil(0.5 * np.pi / step_below))
    thetas = np.concatenate(
        [np.linspace(0.0, 0.5 * np.pi, above + 1), np.linspace(0.5 * np.pi, np.pi, below + 1)[1:]]
    )
    vertices, rings, starts = [], [], []
    count = 0
    for k, theta in enumerate(thetas):
        spacing = step if theta <= 0.5 * np.pi + 1e-9 else step_below
        m = 1 if np.sin(theta) < 1e-9 else max(6, int(round(2 * np.pi * np.sin(theta) / spacing)))
        start = 0.5 * (k % 2) * 2 * np.pi / m  # rings staggered by half a step
        phi = start + 2 * np.pi * np.arange(m) / m
        vertices.append(_from_polar(np.full(m, theta), phi))
        rings.append(np.arange(count, count + m))
        starts.append(start)
        count += m
    faces = [
        _zip_rings(rings[k], rings[k + 1], starts[k], starts[k + 1]) for k in range(len(rings) - 1)
    ]
    return np.concatenate(vertices), np.concatenate(faces)


def _polar(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = c / np.linalg.norm(c, axis=1, keepdims=True)
    return np.arccos(np.clip(c[:, 2], -1.0, 1.0)), np.arctan2(c[:, 1], c[:, 0])


def _from_polar(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    return np.stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1
    )


def _dome(shape: dict):
    """The carapace without grooves: canonical unit-sphere points -> object space.

    By the polar angle theta of the canonical point: the dome from the top (theta 0) to
    the rim's upper edge (``rim_band`` above the equator), over the ellipse of the
    footprint less the brim; the rim, a sloping brim out to the full footprint, from
    there to the equator; the plastron underneath.
    """
    a, b, height = shape["length"] / 2, shape["width"] / 2, shape["height"]
    brim, rim_height = shape["brim"], shape["rim_height"] * height
    rim_theta = 0.5 * np.pi - shape["rim_band"]
    edge_height = 0.35 * rim_height

    def deform(c: np.ndarray) -> np.ndarray:
        theta, phi = _polar(c)
        dome = np.clip(theta / rim_theta, 0.0, 1.0)
        lip = np.clip((theta - rim_theta) / shape["rim_band"], 0.0, 1.0)
        below = np.clip((theta - 0.5 * np.pi) / (0.5 * np.pi), 0.0, 1.0)
        spread = np.where(
            theta < rim_theta,
            (1.0 - brim) * np.sin(0.5 * np.pi * dome),
            (1.0 - brim) + brim * lip,
        )
        spread = spread * (1.0 - 0.15 * smoothstep(0.0, 0.5, below))
        top = np.clip(np.cos(0.5 * np.pi * dome), 0.0, 1.0) ** shape["dome_power"]
        crest = 1.0 + shape["crest"] * spread * np.cos(phi)
        z_dome = rim_height + (height - rim_height) * top * crest
        z_rim = rim_height - (rim_height - edge_height) * lip**1.5
        z_under = (
            edge_height - (edge_height + shape["plastron"]) * np.sin(0.5 * np.pi * below) ** 0.7
        )
        z = np.where(theta < rim_theta, z_dome, np.where(below > 0, z_under, z_rim))
        return np.stack([a * spread * np.cos(phi), b * spread * np.sin(phi), z], axis=1)

    return deform


def plate_field(shape: dict, canonical: np.ndarray) -> dict[str, np.ndarray]:
    """The plate layout at carapace points given by canonical coordinates (N, 3).

    Returns arrays of length N: ``cell`` (plates 0..K-1, marginals K.. on the rim),
    ``rim`` (bool), ``border`` (object units to the nearest plate border: the Voronoi
    border between plate seeds, the rim's upper edge, or a divider between marginals),
    ``radius`` (to the cell's own seed: for a marginal, to the middle of its outer
    edge) and ``angle`` (of the point around its seed, in the top view).

    Example
    -------
    >>> from data_gen.core import instance_rng
    >>> params = sample_params(instance_rng("shells", 0, 0))
    >>> field = plate_field(params["shape"], np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))
    >>> field["rim"].tolist()
    [False, True]
    """
    deform = _dome(shape)
    points = deform(canonical)
    theta, phi = _polar(canonical)
    n = len(canonical)
    rim_theta = 0.5 * np.pi - shape["rim_band"]
    rim = theta >= rim_theta
    # Distance to the rim's edge: the chord to the point of the same azimuth on it.
    edge = deform(_from_polar(np.full(n, rim_theta), phi))
    to_edge = np.linalg.norm(points - edge, axis=1)

    seeds_c = np.asarray(shape["plate_seeds"], dtype=np.float64).reshape(-1, 3)
    seeds = deform(seeds_c)
    k = len(seeds)
    squared = ((points[:, None, :] - seeds[None, :, :]) ** 2).sum(axis=2)  # (N, K)
    nearest = np.argmin(squared, axis=1)
    d1 = np.take_along_axis(squared, nearest[:, None], axis=1)
    separation = np.linalg.norm(seeds[:, None] - seeds[None, :], axis=2)  # (K, K)
    sep = separation[nearest]
    with np.errstate(divide="ignore", invalid="ignore"):
        to_bisector = (squared - d1) / (2.0 * sep)
    to_bisector[np.arange(n), nearest] = np.inf
    voronoi = to_bisector.min(axis=1) if k > 1 else np.full(n, np.inf)

    # Marginals: dividers at jittered, evenly spaced azimuths.
    count = shape["marginals"]
    step = 2 * np.pi / count
    dividers = (
        (np.arange(count) + shape["marginal_phase"] + np.asarray(shape["marginal_jitter"])) * step
    ) % (2 * np.pi)
    dividers = np.sort(dividers)
    position = np.searchsorted(dividers, phi % (2 * np.pi))
    before = dividers[(position - 1) % count]
    after = dividers[position % count]
    theta_rim = np.maximum(theta, rim_theta)
    to_before = np.linalg.norm(points - deform(_from_polar(theta_rim, before)), axis=1)
    to_after = np.linalg.norm(points - deform(_from_polar(theta_rim, after)), axis=1)
    marginal = k + (position - 1) % count

    border = np.where(rim, np.minimum(to_edge, np.minimum(to_before, to_after)), 0.0)
    border = np.where(rim, border, np.minimum(voronoi, to_edge))
    cell = np.where(rim, marginal, nearest)
    # The radius and the angle around the cell's own centre (a marginal's: the middle of
    # its outer edge, on the equator).
    middle = np.angle(np.exp(1j * before) + np.exp(1j * after))
    centre_c = np.where(
        rim[:, None], _from_polar(np.full(n, 0.5 * np.pi), middle), seeds_c[nearest]
    )
    centre = deform(centre_c)
    offset = points - centre
    return {
        "cell": cell.astype(np.int64),
        "rim": rim,
        "border": border,
        "radius": np.linalg.norm(offset, axis=1),
        "angle": np.arctan2(offset[:, 1], offset[:, 0]),
    }


def _groove_profile(shape: dict, border: np.ndarray) -> np.ndarray:
    """Depth of the groove (object units, >= 0) at a distance from the plate border, less
    the plate's gentle bulge towards its middle."""
    width = shape["groove_width"]
    groove = shape["groove_depth"] * np.exp(-0.5 * (border / width) ** 2)
    bulge = shape["plate_bulge"] * smoothstep(0.0, 0.5 * shape["plate_spacing"], border)
    return groove - bulge


def _normals(deform, c: np.ndarray, step: float = 1e-4) -> np.ndarray:
    """Unit outward normals of a deformed unit sphere at canonical points ``c`` (N, 3)."""
    axis = np.where(np.abs(c[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(c, axis)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    second = np.cross(c, first)
    points = deform(c)
    normal = np.cross(deform(c + step * first) - points, deform(c + step * second) - points)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    # Outward: away from the origin, which lies inside the carapace.
    outward = np.sign(np.einsum("ij,ij->i", normal, points))
    return normal * np.where(outward == 0, 1.0, outward)[:, None]


def _carapace(shape: dict):
    """The carapace's deformation: the dome, moved inwards by the groove profile."""
    dome = _dome(shape)

    def deform(c: np.ndarray) -> np.ndarray:
        c = c / np.linalg.norm(c, axis=1, keepdims=True)
        points = dome(c)
        field = plate_field(shape, c)
        # Inwards along the dome's normal; not underneath, where the plastron is smooth.
        depth = _groove_profile(shape, field["border"]) * smoothstep(-0.15, 0.0, c[:, 2])
        return points - depth[:, None] * _normals(dome, c)

    return deform


def build(params: dict):
    """The tortoise mesh: carapace (with its grooves), head and neck, four legs, tail."""
    shape = params["shape"]
    canonical, faces = ring_sphere(CARAPACE_STEP, PLASTRON_STEP)
    carapace = _outward(Component("carapace", _carapace(shape)(canonical), faces, canonical))
    a, b = shape["length"] / 2, shape["width"] / 2
    turn = np.radians(shape["head_turn"])
    head_length = shape["head_length"]
    neck_base = np.array([-0.75 * a, 0.0, 0.02])
    reach = a + shape["neck_out"] * head_length * 0.6
    head_center = np.array([-reach * np.cos(turn), -reach * np.sin(turn) * 0.8, 0.06])
    neck = limb("neck", neck_base, head_center, 0.3 * head_length, 0.26 * head_length)
    rotation = np.array(
        [[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1.0]]
    )
    head = ellipsoid(
        "head",
        head_center,
        (0.55 * head_length, 0.36 * head_length, 0.3 * head_length),
        rotation=rotation,
        subdivisions=3,
    )
    legs = []
    for k, (sx, sy) in enumerate([(-1, 1), (-1, -1), (1, 1), (1, -1)]):
        spread = np.radians(shape["leg_spread"][k])
        root = np.array([sx * 0.55 * a, sy * 0.7 * b, -0.02])
        outward = np.array([sx * np.sin(spread), sy * np.cos(spread), 0.0])
        edge = np.array([root[0], sy * b, -0.02])
        tip = edge + outward * 0.7 * shape["leg_length"] + np.array([0.0, 0.0, -0.03])
        radius = 0.45 * shape["leg_length"]
        legs.append(limb("leg", root, tip, radius, 0.8 * radius))
    tail = limb(
        "tail",
        np.array([0.85 * a, 0.0, 0.0]),
        np.array([a + shape["tail_length"], 0.0, -0.02]),
        0.05,
        0.012,
    )
    return assemble([carapace, neck, head, *legs, tail])


def colorize(params: dict, hits: SurfaceHits) -> tuple[np.ndarray, np.ndarray]:
    """Part labels and unlit colours of the hits."""
    shape, look = params["shape"], params["appearance"]
    palette, seed = look["palette"], look["texture_seed"]
    n = len(hits.component)
    labels = np.zeros(n, dtype=np.uint8)
    rgb = np.zeros((n, 3), dtype=np.float32)
    grain = 1.0 + 0.06 * fbm(hits.points, octaves=3, seed=seed + 1, frequency=8.0)

    shell = hits.where("carapace")
    field = plate_field(shape, hits.canonical[shell])
    cell, border, radius = field["cell"], field["border"], field["radius"]
    groove = border < GROOVE_LABEL_WIDTHS * shape["groove_width"]
    rim = field["rim"] & ~groove
    plate = ~field["rim"] & ~groove
    shell_labels = np.where(groove, _LABEL["groove"], np.where(rim, _LABEL["rim"], 0))
    shell_labels = np.where(plate, _LABEL["plate"], shell_labels)
    shell_rgb = np.empty((len(cell), 3), dtype=np.float32)
    shell_grain = grain[shell]

    # Plates: rings parallel to the border around the areola, radial streaks, darker at
    # the border; each plate a shade of its own.
    position = radius / np.maximum(radius + border, 1e-6)  # 0 at the seed, 1 at the border
    rings = 0.5 + 0.5 * np.cos(2 * np.pi * look["rings"] * position)
    phases = (np.arange(len(look["plate_shades"])) * 2.399) % (2 * np.pi)  # golden angle
    k = np.minimum(cell, len(phases) - 1)
    streaks = 0.5 + 0.5 * np.cos(look["streaks"] * field["angle"] + phases[k])
    weight = look["ring_strength"] * rings**2 + look["streak_strength"] * streaks**3
    weight = weight * smoothstep(0.0, 0.35, position) + 0.5 * smoothstep(0.7, 1.0, position)
    areola = position < look["areola"]
    weight = np.where(areola, 0.85 if look["areola_dark"] else 0.0, np.clip(weight, 0, 1))
    shades = np.asarray(look["plate_shades"], dtype=np.float32)[k]
    shell_rgb[plate] = mix(palette["plate"], weight[plate], (shell_grain * shades)[plate])

    # Grooves: dark, darkest at their middle.
    middle = smoothstep(0.0, GROOVE_LABEL_WIDTHS * shape["groove_width"], border)
    shell_rgb[groove] = mix(palette["groove"], middle[groove], shell_grain[groove])

    # Marginals: light, with a dark wedge from the middle of the outer edge and a darker
    # band along it.
    theta, _ = _polar(hits.canonical[shell])
    band = smoothstep(0.5 * np.pi - shape["rim_band"], 0.5 * np.pi + 0.1, theta)
    wedge = smoothstep(0.5 * shape["width"] * 0.12, 0.0, radius * (1.0 - 0.7 * band))
    marginal = np.clip(0.7 * wedge + 0.4 * band**2, 0.0, 1.0)
    shell_rgb[rim] = mix(palette["rim"], marginal[rim], shell_grain[rim])
    labels[shell], rgb[shell] = shell_labels, shell_rgb

    skin = hits.where("neck", "head", "leg", "tail")
    scales = 0.5 + 0.5 * fbm(hits.points[skin], octaves=3, seed=seed + 2, frequency=10.0)
    labels[skin] = _LABEL["skin"]
    rgb[skin] = mix(palette["skin"], smoothstep(0.35, 0.75, scales), grain[skin])
    return labels, rgb


#: The atlas of :func:`uv_layout`: the carapace's upper half a disc (centre, radius), its
#: underside a small disc, the skin's charts (xatlas) scaled into a square (corner, side).
_TOP_CHART = ((0.36, 0.5), 0.35)
_UNDER_CHART = ((0.86, 0.86), 0.125)
_SKIN_CHARTS = ((0.73, 0.02), 0.26)


def uv_layout(params: dict, assembly) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The texture atlas of a tortoise: (source vertex ids, faces, uv), faces in order.

    The carapace (about 57,000 faces, which xatlas took 50 s to chart) is
    charted by its canonical polar angle and azimuth: the upper half as a disc around
    the top of the dome, the underside as a disc around the bottom, split along the
    equator (one of its rings); the skin's few thousand faces go to xatlas.
    """
    import xatlas  # deferred: only for --meshes

    mesh = assembly.mesh
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertex_count = len(mesh.vertices)
    shell_faces = assembly.face_component == assembly.component_names.index("carapace")
    theta, phi = _polar(assembly.vertex_canonical.astype(np.float64))
    equator = 0.5 * np.pi
    underneath = shell_faces & (theta[faces] > equator + 1e-6).any(axis=1)

    def disc(chart, angle):
        (cx, cy), radius = chart
        return np.stack([cx + radius * angle * np.cos(phi), cy + radius * angle * np.sin(phi)], 1)

    top_uv = disc(_TOP_CHART, theta / equator)
    under_uv = disc(_UNDER_CHART, (np.pi - theta) / equator)
    # The underside's vertices are copies (ids vertex_count + i), so the equator is a seam.
    new_faces = faces.copy()
    new_faces[underneath] += vertex_count
    source = [np.arange(vertex_count), np.arange(vertex_count)]
    uv = [top_uv, under_uv]
    skin = ~shell_faces
    used = np.unique(faces[skin])
    local = np.full(vertex_count, -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    mapping, indices, skin_uv = xatlas.parametrize(
        np.asarray(mesh.vertices, dtype=np.float32)[used], local[faces[skin]].astype(np.uint32)
    )
    (left, bottom), side = _SKIN_CHARTS
    new_faces[skin] = indices.astype(np.int64) + 2 * vertex_count
    source.append(used[mapping.astype(np.int64)])
    uv.append(np.array([left, bottom]) + side * skin_uv.astype(np.float64))
    return np.concatenate(source), new_faces, np.concatenate(uv)


SHELLS = ObjectClass(
    name="shells",
    parts=PARTS,
    default_size=(200, 150),
    frame=(-1.6, 1.4, -1.15, 1.15),
    depth_range=(-0.2, 0.9),
    sample_params=sample_params,
    build=build,
    colorize=colorize,
    uv_layout=uv_layout,
)
