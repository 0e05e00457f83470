"""Bisection break points, G1 joins and closed loops (Algorithm 1), in 2D and 3D."""

from __future__ import annotations

import numpy as np
import pytest

from pde2cad.curves.distance import points_to_curves
from pde2cad.curves.piecewise import fit_chain, fit_closed
from pde2cad.errors import InputError


def _angle_deg(u, v):
    return np.degrees(np.arctan2(abs(u[0] * v[1] - u[1] * v[0]) if len(u) == 2 else np.linalg.norm(np.cross(u, v)), np.dot(u, v)))


def _helix(n=400):
    s = np.linspace(0, 4 * np.pi, n)
    return np.c_[10 * np.cos(s), 10 * np.sin(s), 2 * s]


@pytest.mark.parametrize("tol", [0.1, 0.01])
def test_chain_honours_the_tolerance_in_3d(tol):
    pts = _helix()
    chain = fit_chain(pts, tol)
    d = points_to_curves(pts, chain.curves)
    assert d.max() <= tol
    # A helix turn needs about 4 cubics at 1e-3 of its radius; the count stays economical.
    assert len(chain.curves) <= (8 if tol == 0.1 else 12)


def test_chain_joins_are_g1_and_continuous():
    pts = _helix()
    chain = fit_chain(pts, 0.01)
    c = chain.curves
    assert len(c) > 1
    assert np.abs(c[1:, 0] - c[:-1, 3]).max() == 0.0
    for a, b in zip(c[:-1], c[1:]):
        assert _angle_deg(a[3] - a[2], b[1] - b[0]) < 1e-6


def test_c0_chain_without_g1_has_sharp_joins_recorded():
    pts = _helix()
    chain = fit_chain(pts, 0.01, g1=False)
    assert chain.corners == list(range(1, len(chain.curves)))
    assert points_to_curves(pts, chain.curves).max() <= 0.01


def test_bisection_finds_the_longest_first_piece():
    # Half a circle followed by a straight line: the first curve must cover the arc's worth of
    # points that one cubic can take, not stop at an arbitrary midpoint.
    s = np.linspace(0, np.pi / 2, 200)
    arc = np.c_[100 * np.cos(s), 100 * np.sin(s)]
    chain = fit_chain(arc, 0.05, rounds=30)
    assert len(chain.curves) == 1  # a quarter circle fits one cubic to 2.7e-4 of its radius


def test_closed_square_with_corners_is_four_lines():
    side = np.arange(10.0)
    sq = np.concatenate([
        np.c_[side, np.zeros(10)], np.c_[np.full(10, 10.0), side],
        np.c_[10 - side, np.full(10, 10.0)], np.c_[np.zeros(10), 10 - side],
    ])
    chain, offset = fit_closed(sq, 0.5, corners=np.array([0, 10, 20, 30]))
    assert len(chain.curves) == 4
    assert chain.max_error < 1e-9
    assert chain.corners == [0, 1, 2, 3]


def test_closed_circle_without_corners_is_closed_and_g1_everywhere():
    th = np.linspace(0, 2 * np.pi, 600, endpoint=False)
    circle = np.c_[50 * np.cos(th), 50 * np.sin(th)]
    chain, _ = fit_closed(circle, 0.05, smooth=False)
    c = chain.curves
    assert 4 <= len(c) <= 5
    assert np.abs(c[0, 0] - c[-1, 3]).max() < 1e-12  # closed
    for a, b in zip(c, np.roll(c, -1, axis=0)):
        assert _angle_deg(a[3] - a[2], b[1] - b[0]) < 1e-6
    assert points_to_curves(circle, c).max() <= 0.05


def test_bad_input_is_refused():
    with pytest.raises(InputError, match="NaN"):
        fit_chain(np.array([[0.0, 0.0], [np.nan, 1.0], [2.0, 2.0]]), 1.0)
    with pytest.raises(InputError, match="tolerance"):
        fit_chain(np.zeros((5, 2)) + np.arange(5)[:, None], 0.0)
    with pytest.raises(InputError, match="n >= 2"):
        fit_chain(np.zeros((1, 2)), 1.0)


def test_blunt_corner_between_straight_sides_moves_to_the_lines_meeting_point():
    from pde2cad.curves.piecewise import corner_positions

    # Two straight sides meeting at (20, 0), with the tip vertex cut off by half a unit.
    side_a = np.c_[np.arange(0.0, 20.0), np.zeros(20)]
    side_b = np.c_[np.full(20, 20.0), np.arange(0.0, 20.0) + 0.5]
    loop = np.vstack([side_a, [[19.6, 0.4]], side_b, [[0.0, 19.5]]])
    tip = corner_positions(loop, np.array([20]), max_shift=1.0)[0]
    assert np.abs(tip - [20.0, 0.0]).max() < 1e-9
    # A corner whose sides curve keeps its own point.
    th = np.linspace(0, np.pi, 20)
    arc = np.c_[np.cos(th), np.sin(th)] * 6
    kept = corner_positions(np.vstack([arc, arc[::-1] * [1, -1]]), np.array([19]))[0]
    assert np.array_equal(kept, arc[-1])


def _scalloped(n_sides=6, per_side=30, bulge=3.0):
    """A closed loop of ``n_sides`` arcs bulging outwards between sharp corners."""
    corners = 40.0 * np.c_[np.cos(2 * np.pi * np.arange(n_sides) / n_sides), np.sin(2 * np.pi * np.arange(n_sides) / n_sides)]
    pts = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        u = np.linspace(0.0, 1.0, per_side, endpoint=False)[:, None]
        normal = np.array([b[1] - a[1], a[0] - b[0]]) / np.linalg.norm(b - a)
        pts.append(a + u * (b - a) + bulge * np.sin(np.pi * u) * -normal)
    return np.vstack(pts), np.arange(n_sides) * per_side


def test_corner_runs_fitted_together_give_the_same_curves_in_fewer_batches(monkeypatch):
    # fit_closed fits every run between corners as one piece up front, in one batch (and
    # one for the other parameterizations): the same curves as run by run, fewer batches.
    from pde2cad.curves import batchfit, piecewise

    pts, corners = _scalloped()
    calls = []
    real = batchfit.fit_batch

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(batchfit, "fit_batch", counted)
    piecewise.clear_fit_cache()
    together, _ = fit_closed(pts, 0.5, corners=corners)
    n_together = len(calls)
    monkeypatch.setattr(piecewise, "prefetch_whole_runs", lambda *args: None)
    piecewise.clear_fit_cache()
    calls.clear()
    alone, _ = fit_closed(pts, 0.5, corners=corners)
    assert len(together.curves) == len(alone.curves) == 6  # one arc per side
    assert np.abs(together.curves - alone.curves).max() < 1e-9
    assert points_to_curves(pts, together.curves).max() <= 0.5
    assert n_together < len(calls)
