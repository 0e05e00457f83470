"""Knot removal: C1 chains lose their triple knots exactly, real kinks keep them."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad.bspline import (
    BSplineCurve,
    BSplineSurface,
    coons_to_bspline,
    curve_to_bspline,
    reduce_curve,
    reduce_surface,
    remove_knot,
)
from pde2cad.errors import InputError
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import BilinearCoons, three_sided

RNG = np.random.default_rng(1207)
GRID = np.linspace(0.0, 1.0, 401)


def _c1_chain(
    start: NDArray[np.float64], end: NDArray[np.float64], breaks: list[float], kink: float = 0.0
) -> PiecewiseBezier:
    """Random cubic chain, C1 in the global parameter at every break (the handles on both
    sides are collinear with the break and scaled by the span lengths); ``kink`` moves the
    first break's outgoing handle sideways by that much (a C0 corner)."""
    b = np.array([0.0, *breaks, 1.0])
    k, h = b.size - 1, np.diff(b)
    nodes = start + b[:, None] * (end - start) + RNG.normal(scale=0.2, size=(k + 1, 3))
    nodes[0], nodes[-1] = start, end
    tangents = RNG.normal(size=(k + 1, 3)) + (end - start)
    ctrl = np.empty((k, 4, 3))
    ctrl[:, 0], ctrl[:, 3] = nodes[:-1], nodes[1:]
    ctrl[:, 1] = nodes[:-1] + tangents[:-1] * h[:, None] / 3.0
    ctrl[:, 2] = nodes[1:] - tangents[1:] * h[:, None] / 3.0
    ctrl[1, 1] += kink * np.array([0.0, 0.0, 1.0])
    return PiecewiseBezier(ctrl, b)


def _max_dev(a: BSplineCurve, b: BSplineCurve) -> float:
    return float(np.linalg.norm(a.evaluate(GRID) - b.evaluate(GRID), axis=-1).max())


def test_c1_chain_comes_back_with_double_knots_exactly() -> None:
    chain = _c1_chain(np.zeros(3), np.array([5.0, 1.0, 0.0]), [0.2, 0.45, 0.7])
    full = curve_to_bspline(chain)
    reduced = reduce_curve(full)
    _, mults = reduced.multiplicities()
    np.testing.assert_array_equal(mults[1:-1], [2, 2, 2])
    assert _max_dev(full, reduced) < 1e-12
    np.testing.assert_allclose(reduced.evaluate(GRID), chain.evaluate(GRID), atol=1e-12)


def test_c2_spline_with_extra_knots_returns_to_single_knots() -> None:
    knots = np.r_[[0.0] * 4, 0.3, 0.6, [1.0] * 4]
    base = BSplineCurve(RNG.normal(size=(6, 3)), knots, 3)
    padded = base.with_knots_inserted([0.3, 0.3, 0.6])
    reduced = reduce_curve(padded)
    np.testing.assert_array_equal(reduced.knots, knots)
    np.testing.assert_allclose(reduced.poles, base.poles, atol=1e-12)


def test_a_corner_keeps_its_triple_knot() -> None:
    chain = _c1_chain(np.zeros(3), np.array([5.0, 1.0, 0.0]), [0.3, 0.6], kink=0.05)
    reduced = reduce_curve(curve_to_bspline(chain))
    values, mults = reduced.multiplicities()
    assert dict(zip(values[1:-1].tolist(), mults[1:-1].tolist())) == {0.3: 3, 0.6: 2}


@pytest.mark.parametrize("kink", [1e-7, 1e-4])
def test_deviation_stays_within_the_tolerance(kink: float) -> None:
    """A kink below the tolerance is smoothed away, above it the knot stays; either way the
    curve moves by no more than the tolerance."""
    tol = 1e-5
    chain = _c1_chain(np.zeros(3), np.array([5.0, 1.0, 0.0]), [0.3, 0.6], kink=kink)
    full = curve_to_bspline(chain)
    reduced = reduce_curve(full, tol)
    assert _max_dev(full, reduced) <= tol
    _, mults = reduced.multiplicities()
    assert mults[1] == (2 if kink < tol else 3)


def test_remove_knot_reports_a_rigorous_bound() -> None:
    curve = BSplineCurve(RNG.normal(size=(7, 3)), np.r_[[0.0] * 4, 0.25, 0.5, 0.5, [1.0] * 4], 3)
    poles, knots, bound = remove_knot(curve.poles, curve.knots, 3, 0.5)
    measured = _max_dev(curve, BSplineCurve(poles, knots, 3))
    assert 0 < measured <= bound * (1 + 1e-12)
    with pytest.raises(InputError, match="interior knot"):
        remove_knot(curve.poles, curve.knots, 3, 0.4)


def _c1_coons() -> BilinearCoons:
    c = np.array([[[0, 0, 0], [0, 3, 0.5]], [[4, 0, -0.3], [4, 3, 1.0]]], dtype=float)
    return BilinearCoons(
        _c1_chain(c[0, 0], c[1, 0], [0.3, 0.55]),
        _c1_chain(c[1, 0], c[1, 1], [0.6]),
        _c1_chain(c[0, 1], c[1, 1], [0.25, 0.7]),
        _c1_chain(c[0, 0], c[0, 1], [0.4]),
    )


def test_coons_surface_of_c1_sides_becomes_c1_for_a_kernel() -> None:
    full = coons_to_bspline(_c1_coons())
    reduced = reduce_surface(full)
    _, mu, _, mv = reduced.multiplicities()
    assert mu[1:-1].max() == 2 and mv[1:-1].max() == 2
    dev = np.linalg.norm(
        full.evaluate_grid(GRID, GRID) - reduced.evaluate_grid(GRID, GRID), axis=-1
    ).max()
    assert dev < 1e-12
    # Each edge is the same curve as before (shared edges stay shared).
    for side in ("u0", "u1", "v0", "v1"):
        assert _max_dev(full.boundary_curve(side), reduced.boundary_curve(side)) < 1e-12


def test_collapsed_side_stays_one_point_bitwise() -> None:
    c = np.array([[0.0, 0, 0], [4, 0, 0.3], [2, 3, 1.0]])
    coons = three_sided(
        _c1_chain(c[0], c[1], [0.4]), _c1_chain(c[1], c[2], [0.5]), _c1_chain(c[2], c[0], [0.3])
    )
    reduced = reduce_surface(coons_to_bspline(coons))
    top = reduced.boundary_curve("v1").poles
    assert np.all(top == top[0])


def test_surface_budget_is_shared_by_both_directions() -> None:
    full = coons_to_bspline(_c1_coons())
    bumped = BSplineSurface(
        full.poles + RNG.normal(scale=1e-6, size=full.poles.shape),
        full.knots_u, full.knots_v, 3, 3,
    )
    tol = 3e-6
    reduced = reduce_surface(bumped, tol)
    dev = np.linalg.norm(
        bumped.evaluate_grid(GRID, GRID) - reduced.evaluate_grid(GRID, GRID), axis=-1
    ).max()
    assert dev <= tol
    with pytest.raises(InputError, match="tolerance"):
        reduce_surface(full, -1.0)
