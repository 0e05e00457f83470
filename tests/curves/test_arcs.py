"""Biarc and polyline approximation of cubic Béziers: geometry within tolerance."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad.curves.arcs import (
    Arc,
    Line,
    bezier_to_arcs,
    bezier_to_polyline,
    inflections,
    sample_segments,
    segments_distance,
)
from pde2cad.curves.bezier import derivative, evaluate
from pde2cad.errors import InputError

_K = 4.0 / 3.0 * np.tan(np.pi / 8.0)  # quarter-circle Bézier handle length (unit radius)
_T = np.linspace(0.0, 1.0, 4001)


def quarter_circles(cx: float = 50.0, cy: float = 50.0, r: float = 40.0) -> NDArray[np.float64]:
    """A circle as 4 cubic Béziers (4, 4, 2), counter-clockwise in a y-up frame."""
    out = []
    for q in range(4):
        a0, a1 = q * np.pi / 2.0, (q + 1) * np.pi / 2.0
        p0, p3 = np.array([np.cos(a0), np.sin(a0)]), np.array([np.cos(a1), np.sin(a1)])
        t0, t1 = np.array([-np.sin(a0), np.cos(a0)]), np.array([-np.sin(a1), np.cos(a1)])
        out.append(np.array([p0, p0 + _K * t0, p3 - _K * t1, p3]) * r + [cx, cy])
    return np.array(out)


def polyline_distance(pts: NDArray[np.float64], verts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance (n,) from points (n, 2) to the open polyline through ``verts`` (m, 2)."""
    a, d = verts[:-1], np.diff(verts, axis=0)  # (m-1, 2)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    out = np.empty(len(pts))
    for i in range(0, len(pts), 256):  # chunks keep the (chunk, m-1) arrays small
        rx = pts[i : i + 256, 0, None] - a[:, 0]  # (c, m-1)
        ry = pts[i : i + 256, 1, None] - a[:, 1]
        t = np.clip((rx * d[:, 0] + ry * d[:, 1]) / dd, 0.0, 1.0)
        gx, gy = rx - t * d[:, 0], ry - t * d[:, 1]
        out[i : i + 256] = np.sqrt(np.min(gx * gx + gy * gy, axis=1))
    return out


def hausdorff_to_bezier(ctrl: NDArray[np.float64], segs: list) -> tuple[float, float]:
    """(max Bézier->segments distance, max segments->Bézier distance), both sampled densely."""
    forward = float(np.max(segments_distance(evaluate(ctrl, _T), segs)))
    dense = evaluate(ctrl, _T[::4])  # 1001 points: chord sag far below any tolerance here
    back = float(np.max(polyline_distance(sample_segments(segs, 50), dense)))
    return forward, back


def assert_chain(ctrl: NDArray[np.float64], segs: list, g1: bool) -> None:
    """Segments are contiguous (exactly), start/end at the Bézier ends, optionally G1."""
    assert np.array_equal(segs[0].start, ctrl[0])
    assert np.array_equal(segs[-1].end, ctrl[3])
    for a, b in zip(segs[:-1], segs[1:]):
        assert np.allclose(a.end, b.start, atol=1e-12, rtol=0)
        if g1:
            assert float(a.tangent_at_end() @ b.tangent_at_start()) > 1.0 - 1e-9
    for s in segs:
        if isinstance(s, Arc):
            assert np.hypot(*(s.start - s.center)) == pytest.approx(s.radius, rel=1e-9)
            assert np.hypot(*(s.end - s.center)) == pytest.approx(s.radius, rel=1e-9)
            assert 0.0 < s.sweep < np.pi  # small arcs: bulges far from the full-circle pole


@pytest.mark.parametrize("tol", [1.0, 0.1, 0.01, 0.001])
def test_circle_within_tolerance_and_g1(tol: float) -> None:
    total = 0
    for ctrl in quarter_circles():
        segs = bezier_to_arcs(ctrl, tol)
        total += len(segs)
        fwd, back = hausdorff_to_bezier(ctrl, segs)
        assert fwd <= tol
        assert back <= tol + 1e-6
        assert_chain(ctrl, segs, g1=True)
        # A circle arc turns the same way everywhere (ccw in a y-up frame).
        assert all(isinstance(s, Arc) and s.ccw for s in segs)
    if tol >= 0.1:
        # The incenter biarc of a quarter circle Bézier (radius 40) is already within
        # 0.011, so each quarter needs exactly two arcs.
        assert total == 8
    assert total <= 64


def test_first_tangent_matches_bezier() -> None:
    ctrl = quarter_circles()[0]
    segs = bezier_to_arcs(ctrl, 0.01)
    d0 = derivative(ctrl, np.array([0.0]))[0]
    d1 = derivative(ctrl, np.array([1.0]))[0]
    assert np.allclose(segs[0].tangent_at_start(), d0 / np.linalg.norm(d0), atol=1e-12)
    assert np.allclose(segs[-1].tangent_at_end(), d1 / np.linalg.norm(d1), atol=1e-9)


def test_s_curve_split_at_inflection() -> None:
    ctrl = np.array([[0.0, 0.0], [10.0, 20.0], [20.0, -20.0], [30.0, 0.0]])
    t = inflections(ctrl)
    assert t == pytest.approx([0.5])  # point-symmetric S: inflection in the middle
    segs = bezier_to_arcs(ctrl, 0.01)
    fwd, back = hausdorff_to_bezier(ctrl, segs)
    assert fwd <= 0.01 and back <= 0.01 + 1e-6
    assert_chain(ctrl, segs, g1=True)
    arcs = [s for s in segs if isinstance(s, Arc)]
    assert {s.ccw for s in arcs} == {True, False}  # both turning directions present


def test_straight_bezier_is_one_line() -> None:
    ctrl = np.array([[0.0, 0.0], [2.0, 1.0], [6.0, 3.0], [10.0, 5.0]])
    segs = bezier_to_arcs(ctrl, 0.01)
    assert len(segs) == 1 and isinstance(segs[0], Line)
    assert np.array_equal(segs[0].start, ctrl[0]) and np.array_equal(segs[0].end, ctrl[3])


def test_collinear_overshoot_follows_the_path() -> None:
    # Collinear control points with P1 beyond P3: the curve runs past P3 and comes back.
    ctrl = np.array([[0.0, 0.0], [20.0, 0.0], [-5.0, 0.0], [10.0, 0.0]])
    segs = bezier_to_arcs(ctrl, 0.01)
    assert all(isinstance(s, Line) for s in segs)
    fwd, back = hausdorff_to_bezier(ctrl, segs)
    assert fwd < 1e-9 and back < 1e-9
    assert max(s.end[0] for s in segs) == pytest.approx(np.max(evaluate(ctrl, _T)[:, 0]), abs=1e-4)


@pytest.mark.parametrize(
    "ctrl",
    [
        [[0.0, 0.0], [0.0, 0.0], [10.0, 10.0], [20.0, 0.0]],  # P1 == P0
        [[0.0, 0.0], [10.0, 10.0], [20.0, 0.0], [20.0, 0.0]],  # P2 == P3
        [[0.0, 0.0], [0.0, 0.0], [20.0, 0.0], [20.0, 0.0]] ,  # both: a straight line
        [[0.0, 0.0], [30.0, 30.0], [-30.0, 30.0], [0.0, 0.0]],  # closed loop, P0 == P3
        [[0.0, 0.0], [30.0, 30.0], [0.0, 30.0], [30.0, 0.0]],  # cusp
    ],
)
def test_degenerate_tangents_loops_and_cusps(ctrl: list) -> None:
    c = np.array(ctrl)
    segs = bezier_to_arcs(c, 0.01)
    fwd, back = hausdorff_to_bezier(c, segs)
    assert fwd <= 0.01
    assert back <= 0.01 + 1e-6
    assert_chain(c, segs, g1=False)


def test_degenerate_start_tangent_points_to_p2() -> None:
    c = np.array([[0.0, 0.0], [0.0, 0.0], [10.0, 10.0], [20.0, 0.0]])
    segs = bezier_to_arcs(c, 0.01)
    assert np.allclose(segs[0].tangent_at_start(), [np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)


def test_point_curve_gives_nothing() -> None:
    assert bezier_to_arcs(np.ones((4, 2)), 0.1) == []


def test_random_cubics_within_tolerance() -> None:
    rng = np.random.default_rng(7)
    for _ in range(40):
        c = rng.uniform(-50.0, 50.0, size=(4, 2))
        segs = bezier_to_arcs(c, 0.05)
        fwd, back = hausdorff_to_bezier(c, segs)
        assert fwd <= 0.05
        assert back <= 0.05 + 1e-4
        assert_chain(c, segs, g1=False)
        # Inside one Bézier everything is G1 except at cusps; random cubics have none.
        for a, b in zip(segs[:-1], segs[1:]):
            assert float(a.tangent_at_end() @ b.tangent_at_start()) > 1.0 - 1e-6


def test_smaller_tolerance_more_segments() -> None:
    c = np.array([[0.0, 0.0], [10.0, 40.0], [50.0, 40.0], [60.0, 5.0]])
    n = [len(bezier_to_arcs(c, tol)) for tol in (1.0, 0.1, 0.01, 0.001)]
    assert n == sorted(n) and n[-1] > n[0]


def test_arc_bulge_and_sweep() -> None:
    a = Arc(np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.zeros(2), 1.0, True)
    assert a.sweep == pytest.approx(np.pi / 2)
    assert a.bulge == pytest.approx(np.tan(np.pi / 8))
    b = Arc(np.array([0.0, 1.0]), np.array([1.0, 0.0]), np.zeros(2), 1.0, False)
    assert b.sweep == pytest.approx(np.pi / 2)
    assert b.bulge == pytest.approx(-np.tan(np.pi / 8))
    assert np.allclose(a.sample(3)[1], [np.sqrt(0.5), np.sqrt(0.5)])


@pytest.mark.parametrize("tol", [1.0, 0.1, 0.01])
def test_polyline_chord_error(tol: float) -> None:
    s_curve = np.array([[0.0, 0.0], [10.0, 20.0], [20.0, -20.0], [30.0, 0.0]])
    for ctrl in [*quarter_circles(), s_curve]:
        verts = bezier_to_polyline(ctrl, tol)
        assert np.array_equal(verts[0], ctrl[0]) and np.array_equal(verts[-1], ctrl[3])
        dense = evaluate(ctrl, _T)
        assert np.max(polyline_distance(dense, verts)) <= tol
        # Vertices are points of the curve (de Casteljau split points).
        assert np.max(polyline_distance(verts, dense)) < 1e-3 * tol + 1e-9
        # Chord midpoints: the other direction of the Hausdorff distance.
        mids = 0.5 * (verts[:-1] + verts[1:])
        assert np.max(polyline_distance(mids, dense)) <= tol + 1e-6


def test_polyline_more_points_for_smaller_tolerance() -> None:
    ctrl = quarter_circles()[0]
    n = [len(bezier_to_polyline(ctrl, tol)) for tol in (1.0, 0.1, 0.01)]
    assert n[0] < n[1] < n[2]
    # Chord error of a circle ~ r theta^2 / 8: about sqrt(8 tol / r) radians per chord.
    assert n[1] - 1 <= 4 * int(np.ceil((np.pi / 2) / np.sqrt(8 * 0.1 / 40.0)))


def test_straight_polyline_is_two_points() -> None:
    ctrl = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    assert bezier_to_polyline(ctrl, 0.01).shape == (2, 2)


@pytest.mark.parametrize("fn", [bezier_to_arcs, bezier_to_polyline])
def test_bad_input(fn) -> None:
    good = quarter_circles()[0]
    with pytest.raises(InputError, match="tolerance"):
        fn(good, 0.0)
    with pytest.raises(InputError, match="NaN"):
        fn(np.full((4, 2), np.nan), 0.1)
    with pytest.raises(InputError, match="shape"):
        fn(np.zeros((3, 2)), 0.1)
