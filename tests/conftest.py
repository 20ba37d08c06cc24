"""Small synthetic databases for fast tests (data_gen makes the realistic ones)."""

from __future__ import annotations

import numpy as np
import pytest

from imagemap.database import Database, Example


@pytest.fixture(scope="session", autouse=True)
def library_cache_of_the_session(tmp_path_factory):
    """The library's cache (``IMAGEMAP_CACHE``: the mesh examples' renders in ``meshes/``,
    the examples' padded textures in ``padded/``) in a folder of the test session's, not
    the user's ``~/.cache/imagemap``: a test that does not set its own writes nothing to
    the home folder, and finds no cache a run before it left. A test that sets its own
    (``monkeypatch.setenv``) has it for that test; this one again after. Subprocesses
    inherit it.

    imageio's user folder (``IMAGEIO_USERDIR``) too: reading a file no plugin knows
    (tests/test_io.py, tests/test_fuzz.py) makes an empty ``~/.imageio`` while imageio
    looks for its plugins' libraries. (Checked with ``HOME`` an empty folder: the default
    run, 1207 tests, left only that ``.imageio`` there; those two files leave nothing now.)"""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("IMAGEMAP_CACHE", str(tmp_path_factory.mktemp("imagemap_cache")))
        patch.setenv("IMAGEIO_USERDIR", str(tmp_path_factory.mktemp("imageio_user")))
        yield


def blob(shape=(48, 64), centre=(24, 32), radii=(16, 26), bumps=0.0, seed=0):
    """An ellipsoid depth map (nearer = larger, background 0) with optional bumps."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = ((yy - centre[0]) / radii[0]) ** 2 + ((xx - centre[1]) / radii[1]) ** 2
    depth = np.where(u < 1, 0.3 + 0.6 * np.sqrt(np.clip(1 - u, 0, 1)), 0).astype(np.float32)
    if bumps:
        rng = np.random.default_rng(seed)
        phase = rng.uniform(0, 2 * np.pi)
        depth = np.where(depth > 0, depth + bumps * np.sin(xx / 3.0 + phase), 0)
    return depth.astype(np.float32)


def painted(depth, palette):
    """Colour by position relative to the object: top, bottom and a stripe band."""
    mask = depth > 0
    ys, xs = np.nonzero(mask)
    yc = ys.mean()
    xmin, xmax = xs.min(), xs.max()
    h, w = depth.shape
    yy, xx = np.mgrid[0:h, 0:w]
    image = np.zeros((h, w, 3), dtype=np.float32)
    top = yy < yc
    image[mask & top] = palette[0]
    image[mask & ~top] = palette[1]
    stripe = mask & (xx > xmin + 0.7 * (xmax - xmin)) & (xx < xmin + 0.8 * (xmax - xmin))
    image[stripe] = palette[2]
    shade = (0.75 + 0.25 * depth / max(depth.max(), 1e-6))[..., None]
    return np.clip(image * shade, 0, 1).astype(np.float32)


PALETTE = [(0.85, 0.25, 0.2), (0.95, 0.9, 0.7), (0.1, 0.2, 0.5)]


@pytest.fixture
def blob_database():
    """Five ellipsoids of varied size and position, painted the same way."""
    examples = []
    for i, (cy, cx, ry, rx) in enumerate(
        [(24, 32, 16, 26), (23, 30, 15, 24), (25, 33, 17, 27), (24, 31, 14, 28), (22, 34, 16, 25)]
    ):
        depth = blob(centre=(cy, cx), radii=(ry, rx), bumps=0.02, seed=i)
        examples.append(Example.from_arrays(f"blob_{i}", depth, painted(depth, PALETTE)))
    return Database(examples)


@pytest.fixture
def query_blob():
    depth = blob(centre=(24, 32), radii=(15, 25), bumps=0.02, seed=9)
    return depth, painted(depth, PALETTE)


@pytest.fixture(scope="session")
def shared_heads(tmp_path_factory):
    """A folder of two textured heads in one UV layout, ``head_00.glb`` and ``head_01.glb``.

    Generated (:func:`data_gen.heads.write_shared_layout_heads`, seed 0): the stand-in for
    the FFHQ-UV heads the tests used before, whose licence did not allow committing them.
    The same faces and UVs, two shapes, two people's textures (mean |RGB| 42 apart over
    the used texels).
    """
    from data_gen.heads import write_shared_layout_heads

    folder = tmp_path_factory.mktemp("shared_heads")
    write_shared_layout_heads(folder, count=2, seed=0)
    return folder


@pytest.fixture(scope="session")
def grey_sphere_files(tmp_path_factory):
    """A folder holding a photometric-stereo set as psmImages lays one out: ``gray.0.png``
    .. ``gray.11.png``, ``mask.png`` and ``lights.txt`` (a count line, then vectors).

    Generated (:func:`data_gen.photometric.write_grey_sphere`, seed 0): a glossy grey
    sphere with attached and cast shadows, ambient light, noise, 8-bit levels and a few
    clipped highlights; the stand-in for psmImages' grey sphere, which has no licence.
    """
    from data_gen.photometric import write_grey_sphere

    folder = tmp_path_factory.mktemp("grey_sphere")
    write_grey_sphere(folder, seed=0)
    return folder


@pytest.fixture
def no_work(monkeypatch):
    """Any synthesis started is a failure: refusals come before the work."""
    # The mesh route binds colorize_mesh when it is first imported: imported here, before
    # the patch, and patched by name too, so that a first import inside this fixture
    # cannot keep `refuse` for the tests after it.
    import imagemap.batch.work
    import imagemap.depth.pipeline
    import imagemap.mesh
    import imagemap.mesh.colorize
    import imagemap.mesh.route

    def refuse(*args, **kwargs):
        raise AssertionError("work started before the refusal")

    monkeypatch.setattr(imagemap.depth.pipeline, "colorize", refuse)
    monkeypatch.setattr(imagemap.mesh, "colorize_mesh", refuse, raising=False)
    monkeypatch.setattr(imagemap.mesh.colorize, "colorize_mesh", refuse)
    monkeypatch.setattr(imagemap.mesh.route, "colorize_mesh", refuse)
    monkeypatch.setattr(imagemap.batch.work, "process_job", refuse)
