"""The fine copy (:mod:`imagemap.core.finecopy`): one copy at full resolution through a
coarser source map, for the depth maps above the search size, the uv-space textures and
the views (issues #44, #46)."""

from __future__ import annotations

import numpy as np

from imagemap.core.finecopy import copy_steps, fine_positions

#: The known answers' factor (fine pixels per coarse pixel).
FACTOR = 4
#: Positions equal up to float64 rounding of the bilinear weights.
EXACT = 1e-9


def _full_size(position: np.ndarray) -> np.ndarray:
    """A coarse position in the full-size example's pixels, rounded to the nearest."""
    return np.floor((position + 0.5) * FACTOR).astype(np.int64)


def test_a_copy_drifting_by_one_coarse_pixel_steps_one_source_pixel_at_a_time():
    """One row of coarse pixels copying a translated patch whose offset grows by one coarse
    pixel every two: at full size the offset steps by one pixel at a time (by blocks alone
    it would jump by FACTOR at a block's edge), and over the row it gains the drift."""
    cols = 6
    offsets = np.array([0, 0, 1, 1, 2, 2])
    source = np.zeros((1, cols, 3), np.int64)
    source[0, :, 2] = np.arange(cols) + offsets
    _, _, x = fine_positions(source, FACTOR, (FACTOR, FACTOR * cols))
    fine_offset = _full_size(x[0]) - np.arange(FACTOR * cols)
    steps = np.diff(fine_offset)
    assert set(steps.tolist()) == {0, 1}
    assert fine_offset[-1] - fine_offset[0] == 2 * FACTOR
    blocks = FACTOR * np.repeat(offsets, FACTOR)  # the blocks' own offsets, for comparison
    assert np.abs(np.diff(blocks)).max() == FACTOR


def test_a_turned_copy_gives_the_turned_positions():
    """A copy turned by 30 degrees (float sources: the turn exact at the coarse centres)
    gives exactly the turned positions of the fine pixels, up to the map's sides, where
    the copy is continued at its step (:func:`copy_steps`: the turn)."""
    angle = np.radians(30.0)
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    rows, cols = 6, 7
    centres = np.moveaxis(np.indices((rows, cols)), 0, -1).astype(np.float64)
    source = np.zeros((rows, cols, 3))
    source[..., 1:] = centres @ turn.T + (20.0, 30.0)
    steps = copy_steps(source, 1)
    assert np.allclose(steps[0], turn)
    _, y, x = fine_positions(source, FACTOR, (FACTOR * rows, FACTOR * cols), steps=steps)
    fine = (np.moveaxis(np.indices(y.shape), 0, -1) + 0.5) / FACTOR - 0.5
    truth = fine @ turn.T + (20.0, 30.0)
    assert np.abs(y - truth[..., 0]).max() < EXACT
    assert np.abs(x - truth[..., 1]).max() < EXACT


def test_neighbouring_patches_from_far_apart_places_are_never_mixed():
    """A checkerboard of two translated patches (one example, 40 pixels apart) and a strip
    of another example: every fine pixel reads its own coarse pixel's patch at the same
    place in the source's block, as a translated copy of its own."""
    rows, cols = 5, 6
    yy, xx = np.indices((rows, cols))
    far = (yy + xx) % 2 == 1
    source = np.stack([np.zeros_like(yy), yy + 3, xx + 3 + 40 * far], axis=-1)
    source[:, 5, 0] = 1  # another example
    index, y, x = fine_positions(source, FACTOR, (FACTOR * rows, FACTOR * cols))
    fy, fx = np.indices(y.shape)
    own = source[fy // FACTOR, fx // FACTOR]
    assert np.array_equal(index, own[..., 0])
    # The same place within the source's block: block position times FACTOR plus the
    # pixel's own place in its block.
    assert np.array_equal(_full_size(y), FACTOR * own[..., 1] + fy % FACTOR)
    assert np.array_equal(_full_size(x), FACTOR * own[..., 2] + fx % FACTOR)


def test_the_uv_copy_never_reads_an_examples_unused_gap_its_own_block_avoids():
    # A copy drifting over a narrow unused gap of its example (a mouth's slit between the
    # lips' charts, whose padding is the surface beyond the seam): the interpolated rows
    # cross the gap, the block copy does not; given the used texels, the copy keeps out.
    from imagemap.mesh.uvspace import fine_texture

    texture = np.repeat(np.arange(16, dtype=np.float32)[:, None, None] / 16, 16, axis=1)
    source = np.zeros((4, 4, 3), np.int32)
    source[..., 1] = np.array([0, 0, 2, 3])[:, None]  # rows drift by one working texel
    source[..., 2] = np.arange(4)[None, :]
    used = np.ones((16, 16), bool)
    used[4:8] = False  # the example's rows between the two blocks the copy reads
    correction = np.zeros((4, 4, 1), np.float32)
    _, free = fine_texture([texture], source, correction, 16)
    _, kept = fine_texture([texture], source, correction, 16, used=[used])
    gap = (free[..., 1] >= 4) & (free[..., 1] < 8)
    assert gap.any()  # the interpolated copy reads the gap
    assert not ((kept[..., 1] >= 4) & (kept[..., 1] < 8)).any()
    assert np.array_equal(np.any(kept != free, axis=-1), gap)  # only there


def test_each_fine_pixel_knows_its_coarse_pixel_and_its_place_in_it():
    """At 2.5 fine pixels per coarse one, fine pixel ``i`` lies in coarse pixel
    ``floor((i + 0.5) / 2.5)``, at ``(i + 0.5) / 2.5`` minus that from its edge; a
    translated copy reads its coarse pixel's source plus that place (minus the half pixel
    to the centre), and the result unpacks as (index, y, x)."""
    factor, rows, cols = 2.5, 4, 6
    yy, xx = np.indices((rows, cols))
    source = np.stack([np.zeros_like(yy), yy + 7, xx + 2], axis=-1)
    at = fine_positions(source, factor, (10, 15))
    centres_y, centres_x = (np.arange(10) + 0.5) / factor, (np.arange(15) + 0.5) / factor
    assert at.cell_y.tolist() == np.floor(centres_y).astype(int).tolist()
    assert at.cell_x.tolist() == np.floor(centres_x).astype(int).tolist()
    assert np.abs(at.within_y - (centres_y - at.cell_y)).max() < EXACT
    own_y = source[at.cell_y][:, at.cell_x, 1] + at.within_y[:, None] - 0.5
    own_x = source[at.cell_y][:, at.cell_x, 2] + at.within_x[None, :] - 0.5
    assert np.abs(at.y - own_y).max() < EXACT and np.abs(at.x - own_x).max() < EXACT
    index, y, x = at
    assert index is at.index and y is at.y and x is at.x
