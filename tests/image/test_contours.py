"""Tests of pde2cad.image.contours: exact crack loops, orientation, nesting."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage

from pde2cad.errors import InputError
from pde2cad.image.contours import ContourLoop, signed_area, trace_loops


def _steps(loop: ContourLoop) -> NDArray[np.float64]:
    """(n, 2) steps from each vertex to the next, including last -> first."""
    return np.roll(loop.points, -1, axis=0) - loop.points


def _assert_unit_axis_steps(loop: ContourLoop) -> None:
    steps = _steps(loop)
    assert np.all(np.abs(steps).sum(axis=1) == 1.0), "every step is one unit along x or y"
    assert np.all((steps[:, 0] == 0) | (steps[:, 1] == 0))
    assert np.array_equal(loop.points, np.round(loop.points))
    assert len(loop.points) >= 4
    assert not np.array_equal(loop.points[0], loop.points[-1]), "closed implicitly"


def _rectangle_boundary(x0: int, x1: int, y0: int, y1: int) -> set[tuple[float, float]]:
    pts = set()
    for x in range(x0, x1 + 1):
        pts |= {(float(x), float(y0)), (float(x), float(y1))}
    for y in range(y0, y1 + 1):
        pts |= {(float(x0), float(y)), (float(x1), float(y))}
    return pts


def _check_exact(mask: NDArray[np.bool_]) -> list[ContourLoop]:
    """Check every loop of ``mask`` against pixel counts and the topology from scipy."""
    loops = trace_loops(mask)
    labels, n_shapes = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    counts = np.bincount(labels.ravel(), minlength=n_shapes + 1)[1:]
    area = np.zeros(n_shapes)
    outer_area = np.zeros(n_shapes)
    for loop in loops:
        _assert_unit_axis_steps(loop)
        a = signed_area(loop.points)
        assert (a < 0) == loop.is_hole, "outer loops positive, holes negative"
        area[loop.shape] += a
        if not loop.is_hole:
            outer_area[loop.shape] += a
    # outer area - sum(hole areas) == pixel count, for every shape.
    np.testing.assert_array_equal(area, counts)
    # One outer loop per shape, and as many holes as enclosed background regions.
    assert sum(not lp.is_hole for lp in loops) == n_shapes
    _, n_bg = ndimage.label(~np.pad(mask, 1), structure=ndimage.generate_binary_structure(2, 1))
    assert sum(lp.is_hole for lp in loops) == n_bg - 1
    # Order: by shape id, the outer loop first.
    keys = [(lp.shape, lp.is_hole) for lp in loops]
    assert keys == sorted(keys)
    return loops


def test_rectangle_exact_vertices() -> None:
    mask = np.zeros((9, 13), dtype=bool)
    mask[2:6, 3:10] = True  # rows 2..5, cols 3..9
    (loop,) = trace_loops(mask)
    assert not loop.is_hole and loop.shape == 0 and loop.parent == -1 and loop.depth == 0
    pts = {tuple(p) for p in loop.points.tolist()}
    assert pts == _rectangle_boundary(3, 10, 2, 6)
    assert len(loop.points) == 2 * (7 + 4)  # one vertex per unit step, each once
    _assert_unit_axis_steps(loop)
    assert signed_area(loop.points) == 28.0 == loop.signed_area
    # Starts at the top-left vertex and runs +x first: clockwise on a y-down screen.
    np.testing.assert_array_equal(loop.points[0], [3.0, 2.0])
    np.testing.assert_array_equal(loop.points[1], [4.0, 2.0])


def test_foreground_on_the_left() -> None:
    """For each step d from p, the pixel at p + d/2 + (-dy, dx)/2 is foreground."""
    rng = np.random.default_rng(7)
    mask = rng.random((25, 31)) < 0.45
    for loop in trace_loops(mask):
        d = _steps(loop)
        left = loop.points + d / 2 + np.column_stack([-d[:, 1], d[:, 0]]) / 2
        right = loop.points + d / 2 - np.column_stack([-d[:, 1], d[:, 0]]) / 2
        # Pixel centres (j + 1/2, i + 1/2) -> (row i, col j).
        li, lj = np.floor(left[:, 1]).astype(int), np.floor(left[:, 0]).astype(int)
        ri, rj = np.floor(right[:, 1]).astype(int), np.floor(right[:, 0]).astype(int)
        assert np.all(mask[li, lj])
        padded = np.pad(mask, 1)
        assert not np.any(padded[ri + 1, rj + 1])


def test_single_pixel() -> None:
    mask = np.zeros((3, 3), dtype=bool)
    mask[1, 1] = True
    (loop,) = trace_loops(mask)
    np.testing.assert_array_equal(loop.points, [[1, 1], [2, 1], [2, 2], [1, 2]])
    assert loop.signed_area == 1.0


def test_empty_mask() -> None:
    assert trace_loops(np.zeros((5, 7), dtype=bool)) == []
    assert trace_loops(np.zeros((0, 4), dtype=bool)) == []


def test_full_mask_is_the_image_border() -> None:
    (loop,) = trace_loops(np.ones((4, 6), dtype=bool))
    assert {tuple(p) for p in loop.points.tolist()} == _rectangle_boundary(0, 6, 0, 4)
    assert loop.signed_area == 24.0
    assert loop.points.min() == 0.0 and loop.points[:, 0].max() == 6.0


def test_saddle_is_one_shape() -> None:
    for mask in (np.array([[1, 0], [0, 1]], dtype=bool), np.array([[0, 1], [1, 0]], dtype=bool)):
        (loop,) = trace_loops(mask)
        assert loop.shape == 0 and not loop.is_hole
        assert len(loop.points) == 8
        # The loop passes through the saddle vertex (1, 1) twice.
        assert sum(1 for p in loop.points.tolist() if p == [1.0, 1.0]) == 2
        assert loop.signed_area == 2.0
        _assert_unit_axis_steps(loop)


def test_saddle_background_is_4_connected() -> None:
    """A diagonal gap in a ring does not open it: the hole stays a hole."""
    mask = np.ones((5, 5), dtype=bool)
    mask[1:4, 1:4] = False
    mask[0, 0] = False  # still closed: the corner touches the hole only diagonally
    mask[1, 1] = False
    loops = _check_exact(mask)
    assert [lp.is_hole for lp in loops] == [False, True]


def test_nesting_ring_with_dot() -> None:
    mask = np.zeros((9, 9), dtype=bool)
    mask[1:8, 1:8] = True
    mask[2:7, 2:7] = False
    mask[4, 4] = True
    loops = _check_exact(mask)
    assert [(lp.shape, lp.is_hole, lp.parent, lp.depth) for lp in loops] == [
        (0, False, -1, 0),
        (0, True, 0, 1),
        (1, False, 0, 2),
    ]
    assert loops[1].signed_area == -25.0  # the hole encloses the dot as well
    np.testing.assert_array_equal(loops[2].points[0], [4, 4])


def test_nesting_three_levels_and_siblings() -> None:
    mask = np.zeros((15, 24), dtype=bool)
    mask[0:15, 0:15] = True  # shape 0 touches the image border
    mask[1:14, 1:14] = False
    mask[2:13, 2:13] = True  # shape 1 inside the hole of shape 0
    mask[3:12, 3:12] = False
    mask[4:11, 4:11] = True  # shape 2, with a hole
    mask[6:9, 6:9] = False
    mask[7, 7] = True  # shape 3 in the hole of shape 2
    mask[2:5, 17:20] = True  # a second top-level shape, outside the frame
    loops = _check_exact(mask)
    depth = {(lp.shape, lp.is_hole): lp.depth for lp in loops}
    parent = {(lp.shape, lp.is_hole): lp.parent for lp in loops}
    # Shapes by raster order of first pixel: 0 (frame, row 0), 1 (row 2, col 2),
    # 2 (row 2, col 17), 3 (row 4), 4 (the dot).
    assert depth == {
        (0, False): 0, (0, True): 1,
        (1, False): 2, (1, True): 3,
        (2, False): 0,
        (3, False): 4, (3, True): 5,
        (4, False): 6,
    }
    assert parent == {
        (0, False): -1, (0, True): 0,
        (1, False): 0, (1, True): 1,
        (2, False): -1,
        (3, False): 1, (3, True): 3,
        (4, False): 3,
    }


def test_shape_ids_follow_scipy_label() -> None:
    rng = np.random.default_rng(3)
    mask = rng.random((40, 50)) < 0.3
    labels, _ = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    for loop in trace_loops(mask):
        if loop.is_hole:
            continue
        # The first vertex is the top-left corner of the shape's first pixel.
        x, y = loop.points[0].astype(int)
        assert labels[y, x] == loop.shape + 1
        first = np.argwhere(labels == loop.shape + 1)[0]
        assert (y, x) == tuple(first)


def test_shape_ids_without_holes() -> None:
    """Without holes no labelling runs; the ids must still match ndimage.label."""
    rng = np.random.default_rng(5)
    mask = rng.random((60, 70)) < 0.08
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    loops = _check_exact(mask)
    assert not any(lp.is_hole for lp in loops) and len(loops) == n
    for loop in loops:
        x, y = loop.points[0].astype(int)
        assert labels[y, x] == loop.shape + 1
        assert loop.parent == -1 and loop.depth == 0


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("density", [0.2, 0.5, 0.75])
def test_random_masks_exact(seed: int, density: float) -> None:
    """Area identity per shape on random masks: the tracer is exact, saddles included."""
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 60, size=2)
    mask = rng.random((h, w)) < density
    _check_exact(mask)


def test_random_nesting_matches_containment() -> None:
    """An outer loop's parent is the shape whose hole region contains the shape."""
    rng = np.random.default_rng(11)
    mask = ndimage.binary_opening(rng.random((80, 80)) < 0.55)
    loops = _check_exact(mask)
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    outer = {lp.shape: lp for lp in loops if not lp.is_hole}
    for s, lp in outer.items():
        # Depth is twice the number of ancestors.
        d, p = 0, lp.parent
        while p != -1:
            d += 2
            p = outer[p].parent
        assert lp.depth == d
        if lp.parent == -1:
            continue
        # The filled outer boundary of the parent contains this shape's pixels.
        filled = ndimage.binary_fill_holes(labels == lp.parent + 1)
        assert np.all(filled[labels == s + 1])
    assert len(outer) == n


def test_integer_mask_and_bad_input() -> None:
    (loop,) = trace_loops(np.array([[0, 2], [0, 1]], dtype=np.uint8))
    assert loop.signed_area == 2.0
    with pytest.raises(InputError, match="2-D"):
        trace_loops(np.zeros((2, 2, 2), dtype=bool))
    with pytest.raises(InputError, match="boolean"):
        trace_loops(np.zeros((2, 2), dtype=np.float64))


def test_points_are_read_only_views() -> None:
    (loop,) = trace_loops(np.ones((2, 2), dtype=bool))
    with pytest.raises(ValueError):
        loop.points[0, 0] = 5.0


@pytest.mark.slow
def test_large_disc_is_fast() -> None:
    import time

    n = 3000
    y, x = np.ogrid[:n, :n]
    mask = (x - n / 2 + 0.3) ** 2 + (y - n / 2 - 0.2) ** 2 < (0.45 * n) ** 2
    t0 = time.process_time()
    (loop,) = trace_loops(mask)
    assert time.process_time() - t0 < 10.0
    assert loop.signed_area == mask.sum()
