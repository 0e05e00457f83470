"""Least-squares cubic fitting (Eqs. 3.3-3.9, corrected) in 2D and 3D."""

from __future__ import annotations

import numpy as np
import pytest

from pde2cad.curves import bezier
from pde2cad.curves.fit import fit_cubic, fit_with_parameters, solve_cubic
from pde2cad.curves.parameterize import METHODS

CTRL_2D = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 2.5], [4.0, 0.5]])
CTRL_3D = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 1.0], [3.0, 2.5, -1.0], [4.0, 0.5, 2.0]])


@pytest.mark.parametrize("ctrl", [CTRL_2D, CTRL_3D])
def test_exact_parameters_recover_the_curve(ctrl):
    t = np.linspace(0, 1, 30)
    pts = bezier.evaluate(ctrl, t)
    got = solve_cubic(pts, t, pts[0], pts[-1])
    assert np.abs(got - ctrl).max() < 1e-10


def test_matches_the_corrected_normal_equations():
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0, 1, 40))
    t[0], t[-1] = 0.0, 1.0
    pts = bezier.evaluate(CTRL_2D, t) + rng.normal(0, 0.05, (40, 2))
    p0, p3 = pts[0], pts[-1]
    a, b = 3 * t * (1 - t) ** 2, 3 * t**2 * (1 - t)
    c = (1 - t)[:, None] ** 3 * p0 + (t**3)[:, None] * p3 - pts
    lhs = np.array([[a @ a, a @ b], [a @ b, b @ b]])
    rhs = -np.stack([a @ c, b @ c])
    expected = np.linalg.solve(lhs, rhs)
    got = solve_cubic(pts, t, p0, p3)
    assert np.abs(got[1:3] - expected).max() < 1e-9


@pytest.mark.parametrize("ctrl", [CTRL_2D, CTRL_3D])
def test_unknown_parameters_are_found_by_newton(ctrl):
    # Points uniformly spaced in arc length, not in t: the parameterization must be found.
    dense = bezier.evaluate(ctrl, np.linspace(0, 1, 4001))
    s = np.r_[0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
    pts = dense[np.searchsorted(s, np.linspace(0, s[-1], 50)).clip(0, 4000)]
    fit = fit_cubic(pts, rounds=30)
    assert fit.max_error < 3e-3  # 1e-3 of the curve's size
    assert fit.method in METHODS


def test_tangent_constraints_are_honoured():
    t = np.linspace(0, 1, 40)
    pts = bezier.evaluate(CTRL_2D, t)
    tan0 = np.array([1.0, 0.2])
    tan3 = np.array([1.0, -1.0])
    fit = fit_with_parameters(pts, t, pts[0], pts[-1], tan0 / np.linalg.norm(tan0), tan3 / np.linalg.norm(tan3))
    d0 = fit.ctrl[1] - fit.ctrl[0]
    d3 = fit.ctrl[3] - fit.ctrl[2]
    assert abs(d0[0] * tan0[1] - d0[1] * tan0[0]) < 1e-12 and d0 @ tan0 > 0
    assert abs(d3[0] * tan3[1] - d3[1] * tan3[0]) < 1e-12 and d3 @ tan3 > 0


def test_true_tangents_recover_the_curve():
    t = np.linspace(0, 1, 40)
    pts = bezier.evaluate(CTRL_3D, t)
    tan0 = CTRL_3D[1] - CTRL_3D[0]
    tan3 = CTRL_3D[3] - CTRL_3D[2]
    got = solve_cubic(pts, t, pts[0], pts[-1], tan0 / np.linalg.norm(tan0), tan3 / np.linalg.norm(tan3))
    assert np.abs(got - CTRL_3D).max() < 1e-10


@pytest.mark.parametrize("n", [2, 3])
def test_too_few_points_give_a_straight_line_not_an_error(n):
    pts = np.linspace([0.0, 0.0], [3.0, 3.0], n)
    fit = fit_cubic(pts)
    assert fit.max_error < 1e-12
    mid = bezier.evaluate(fit.ctrl, np.array([0.5]))[0]
    assert abs(mid[0] - mid[1]) < 1e-12
