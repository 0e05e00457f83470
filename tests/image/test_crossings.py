"""Crossings between fitted curves, and the vectorizer's untangling (issue 11)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pde2cad
from pde2cad.curves import bezier
from pde2cad.curves.distance import points_to_curves
from pde2cad.image.crossings import find_crossings, trim_corner_crossings
from pde2cad.image.evaluate import outline_error
from pde2cad.image.raster import read_image

ROOT = Path(__file__).resolve().parents[2]


def _despeckled(mask: np.ndarray, area: int) -> np.ndarray:
    """The mask without 8-connected specks and 4-connected holes of at most ``area`` px
    (scipy, independent of the vectorizer's own despeckling)."""
    from scipy import ndimage

    out = mask.copy()
    lab, _ = ndimage.label(out, structure=np.ones((3, 3), bool))
    small = np.bincount(lab.ravel()) <= area
    small[0] = False
    out[small[lab]] = False
    lab, _ = ndimage.label(~np.pad(out, 1))
    small = np.bincount(lab.ravel()) <= area
    small[0] = False
    out[small[lab][1:-1, 1:-1]] = True
    return out


def _line(a, b) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.stack([a, a + (b - a) / 3, a + 2 * (b - a) / 3, b])


def test_crossing_of_two_lines_refined_to_the_point() -> None:
    # Two separate loops: a square and a diamond through it.
    square = np.stack([_line((0, 0), (4, 0)), _line((4, 0), (4, 4)), _line((4, 4), (0, 4)), _line((0, 4), (0, 0))])
    diamond = np.stack([_line((2, -1), (5, 2)), _line((5, 2), (2, 5)), _line((2, 5), (-1, 2)), _line((-1, 2), (2, -1))])
    found = find_crossings([square, diamond])
    assert len(found) == 8 and not any(c.adjacent for c in found)
    curves = np.concatenate([square, diamond])
    for c in found:
        pa = bezier.evaluate(curves[c.a], [c.ta])[0]
        pb = bezier.evaluate(curves[c.b], [c.tb])[0]
        assert np.linalg.norm(pa - pb) < 1e-9


def test_simple_loop_has_no_crossings() -> None:
    t = np.linspace(0, 2 * np.pi, 9)
    pts = np.column_stack([10 * np.cos(t), 10 * np.sin(t)])
    loop = np.stack([_line(pts[i], pts[i + 1]) for i in range(8)])
    assert find_crossings([loop]) == []


def _fishtail() -> tuple[np.ndarray, np.ndarray]:
    """A closed loop whose first curve overshoots the corner at (10, 0) and crosses the
    next one a fraction of a pixel after the joint."""
    a = np.array([[0, 0], [6, 0], [10.6, 0.3], [10, 0]], float)  # arrives from beyond x = 10
    b = _line((10, 0), (10, 10))
    rest = np.stack([_line((10, 10), (0, 10)), _line((0, 10), (0, 0))])
    crack = np.array([[x, 0] for x in range(10)] + [[10, y] for y in range(10)]
                     + [[x, 10] for x in range(10, 0, -1)] + [[0, y] for y in range(10, 0, -1)], float)
    return np.concatenate([np.stack([a, b]), rest]), crack


def test_crossing_next_to_a_joint_is_found_and_trimmed() -> None:
    loop, crack = _fishtail()
    found = find_crossings([loop])
    assert [(c.a, c.b, c.adjacent) for c in found] == [(0, 1, True)]
    fixed, n_fixed, n_left = trim_corner_crossings(loop, crack, 1.0)
    assert (n_fixed, n_left) == (1, 0)
    assert find_crossings([fixed]) == []
    assert np.array_equal(fixed[0, 3], fixed[1, 0])  # still joined
    # The boundary stays within the tolerance of the trimmed loop.
    assert points_to_curves(crack, fixed).max() <= 1.0



def test_two_curve_sliver_is_trimmed_at_both_joints() -> None:
    # A 2-px diagonal sliver (logo2) fitted by two cubics that cross just inside both
    # joints: each crossing is reported at the joint it is next to and both are trimmed.
    loop = np.array([[[311.0, 46.0], [311.921, 50.391], [305.315, 40.298], [306.0, 43.0]],
                     [[306.0, 43.0], [305.079, 38.609], [311.685, 48.702], [311.0, 46.0]]])
    upper = [[306 + (i + 1) // 2, 42 + i // 2] for i in range(10)]  # (306, 42), (307, 42), ...
    pts = np.array(upper + [[x, y + 1] for x, y in upper[::-1]], float)
    crack = np.vstack([pts, 0.5 * (pts + np.roll(pts, -1, axis=0))])
    found = find_crossings([loop])
    assert sorted((c.a, c.b, c.ta > 0.5) for c in found) == [(0, 1, True), (1, 0, True)]
    fixed, n_fixed, n_left = trim_corner_crossings(loop, crack, 0.98)
    assert (n_fixed, n_left) == (2, 0)
    assert find_crossings([fixed]) == []
    assert np.array_equal(fixed[0, 3], fixed[1, 0]) and np.array_equal(fixed[1, 3], fixed[0, 0])
    assert points_to_curves(crack, fixed).max() <= 0.98

@pytest.mark.parametrize("source", ["noisy_blob", "logo2"])
def test_photo_outlines_do_not_cross(source: str) -> None:
    # Regression (issue 11): curves crossed just before sharp corners, so CAD faces failed.
    if source == "noisy_blob":
        mask = read_image(ROOT / "examples" / "images" / "noisy_blob.png")
    else:
        matplotlib = pytest.importorskip("matplotlib")
        from PIL import Image

        from pde2cad.image.raster import to_mask

        path = Path(matplotlib.__file__).parent / "mpl-data" / "sample_data" / "logo2.png"
        mask = to_mask(np.asarray(Image.open(path).convert("L")))
    d = pde2cad.vectorize(mask, 1.0)
    for group in d.shapes():
        assert find_crossings([lp.curves for lp in group]) == []
        for lp in group:  # every loop is closed exactly
            assert np.abs(np.roll(lp.curves[:, 0], -1, axis=0) - lp.curves[:, 3]).max() < 1e-9
    err = outline_error(_despeckled(mask, 2), [lp.curves for lp in d.loops])
    assert err["max_boundary_to_curve"] <= 1.0
    assert err["max_curve_to_boundary"] <= 1.05


def test_crossing_fit_is_redone_with_converged_pieces_before_crack_lines() -> None:
    # A smooth random blob (a DEM-like level set): the break search's 3-round pieces of its
    # outline cross, and untangling would patch crack-polygon lines in (13 -> 21 curves);
    # the loop is fitted again with converged pieces, which do not cross.
    from scipy import ndimage

    from pde2cad.curves.fit import NEWTON_ROUNDS
    from pde2cad.curves.piecewise import PIECE_ROUNDS
    from pde2cad.image import vectorize as vec
    from pde2cad.image.contours import trace_loops
    from pde2cad.image.corners import CORNER_ANGLE, detect_corners

    z = ndimage.gaussian_filter(np.random.default_rng(0).random((72, 72)), 5)
    mask = z > np.median(z)
    loop = max(trace_loops(mask), key=lambda c: len(c.points))
    pts, corners = loop.points, detect_corners(loop.points)
    quick = vec._plain_fit(pts, corners, 1.0, True, "optimal", None, PIECE_ROUNDS)
    patched = vec._untangle(pts, vec._close_gaps(quick.curves), list(quick.lines) or [False] * len(quick.curves), 1.0)
    assert PIECE_ROUNDS < NEWTON_ROUNDS and patched is not None and len(patched[0]) > len(quick.curves)
    fitted = vec._fit_loop(loop, 1.0, True, True, "optimal", CORNER_ANGLE)
    assert len(fitted.curves) <= len(quick.curves) and "crack" not in fitted.parameterizations
    assert not find_crossings([fitted.curves])
    drawing = pde2cad.vectorize(mask, tolerance=1.0)
    err = outline_error(mask, [lp.curves for lp in drawing.loops])
    assert max(err["max_boundary_to_curve"], err["max_curve_to_boundary"]) <= 1.0
