"""Tests of the B-spline data classes and of the patch-to-B-spline conversion."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from pde2cad.bspline import (
    BSplineCurve,
    BSplineSurface,
    add_surfaces,
    coons_to_bspline,
    curve_to_bspline,
    deformation_to_bspline,
    patch_to_bspline,
)
from pde2cad.errors import FitError, InputError
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import BicubicCoons, BilinearCoons, three_sided
from pde2cad.surfaces.deformation import Deformation

RNG = np.random.default_rng(20261122)
GRID = np.linspace(0.0, 1.0, 50)


def _chain(
    start: NDArray[np.float64], end: NDArray[np.float64], breaks: list[float]
) -> PiecewiseBezier:
    """Wiggly C0 chain of cubics from ``start`` to ``end`` with the given interior breaks."""
    b = np.array([0.0, *breaks, 1.0])
    k = b.size - 1
    lift = np.r_[0.0, RNG.normal(scale=0.2, size=k - 1), 0.0][:, None] * [0.0, 0.0, 1.0]
    knots = start + b[:, None] * (end - start) + lift
    inner = RNG.normal(scale=0.3, size=(k, 2, 3))
    ctrl = np.empty((k, 4, 3))
    ctrl[:, 0], ctrl[:, 3] = knots[:-1], knots[1:]
    ctrl[:, 1] = (2 * knots[:-1] + knots[1:]) / 3 + inner[:, 0]
    ctrl[:, 2] = (knots[:-1] + 2 * knots[1:]) / 3 + inner[:, 1]
    return PiecewiseBezier(ctrl, b)


def _corners() -> NDArray[np.float64]:
    return np.array([[[0, 0, 0], [0, 3, 0.5]], [[4, 0, -0.3], [4, 3, 1.0]]], dtype=float)


def _bilinear() -> BilinearCoons:
    c = _corners()
    return BilinearCoons(
        _chain(c[0, 0], c[1, 0], [0.3, 0.55]),  # bottom
        _chain(c[1, 0], c[1, 1], [0.6]),  # right
        _chain(c[0, 1], c[1, 1], [0.25, 0.7, 0.8]),  # top: other breaks than bottom
        _chain(c[0, 0], c[0, 1], [0.4, 0.45]),  # left
    )


def _ribbon(breaks: list[float]) -> PiecewiseBezier:
    """A random cross-derivative curve with the given interior breaks."""
    return _chain(RNG.normal(size=3), RNG.normal(size=3), breaks)


def _bicubic() -> BicubicCoons:
    b = _bilinear()
    return BicubicCoons(
        b.bottom,
        b.right,
        b.top,
        b.left,
        _ribbon([0.5]),
        _ribbon([0.2, 0.9]),
        _ribbon([]),
        _ribbon([0.33]),
    )


# --------------------------------------------------------------------------- data classes
def test_curve_evaluation_matches_scipy_with_derivatives() -> None:
    knots = np.array([0, 0, 0, 0, 0.2, 0.5, 0.5, 0.7, 1, 1, 1, 1.0])
    poles = RNG.normal(size=(8, 3))
    curve = BSplineCurve(poles, knots, 3)
    t = np.linspace(-0.1, 1.1, 301)
    ref = BSpline(knots, poles, 3)
    for order in range(4):
        scale = max(1.0, float(np.abs(ref(t, nu=order)).max()))
        assert np.abs(curve.derivative(t, order) - ref(t, nu=order)).max() <= 1e-13 * scale
    values, mults = curve.multiplicities()
    np.testing.assert_array_equal(values, [0, 0.2, 0.5, 0.7, 1])
    np.testing.assert_array_equal(mults, [4, 1, 2, 1, 4])


def test_curve_knot_insertion_and_degree_elevation_are_exact() -> None:
    knots = np.array([0, 0, 0, 0, 0.2, 0.5, 0.5, 0.7, 1, 1, 1, 1.0])
    curve = BSplineCurve(RNG.normal(size=(8, 2)), knots, 3)
    t = np.linspace(0, 1, 201)
    refined = curve.with_knots_inserted([0.3, 0.3, 0.5, 0.9])
    assert refined.poles.shape == (12, 2)
    assert np.abs(refined.evaluate(t) - curve.evaluate(t)).max() < 1e-14
    raised = curve.degree_elevated(5)
    _, mults = raised.multiplicities()
    np.testing.assert_array_equal(mults, [6, 3, 4, 3, 6])  # continuity kept
    assert np.abs(raised.evaluate(t) - curve.evaluate(t)).max() < 1e-13
    np.testing.assert_array_equal(raised.poles[[0, -1]], curve.poles[[0, -1]])


def test_surface_partials_match_scipy_tensor_product() -> None:
    ku = np.array([0, 0, 0, 0, 0.4, 1, 1, 1, 1.0])
    kv = np.array([0, 0, 0, 0.3, 0.6, 0.6, 1, 1, 1.0])
    poles = RNG.normal(size=(5, 6, 3))
    s = BSplineSurface(poles, ku, kv, 3, 2)
    u, v = RNG.uniform(size=100), RNG.uniform(size=100)
    for du, dv in ((0, 0), (1, 0), (0, 1), (1, 1), (2, 1)):
        bu = BSpline(ku, np.eye(5), 3)(u, nu=du)  # (n, 5)
        bv = BSpline(kv, np.eye(6), 2)(v, nu=dv)
        ref = np.einsum("ni,ijd,nj->nd", bu, poles, bv)
        assert np.abs(s.partial(u, v, du, dv) - ref).max() < 1e-12 * max(1, np.abs(ref).max())
    grid = s.evaluate_grid(GRID, GRID)
    assert np.abs(grid - s.evaluate(GRID[:, None], GRID[None, :])).max() < 1e-13
    assert s.multiplicities()[3].tolist() == [3, 1, 2, 3]


def test_invalid_knots_raise() -> None:
    with pytest.raises(InputError):
        BSplineCurve(np.zeros((4, 3)), np.array([0, 0, 0, 0.5, 1, 1, 1, 1.0]), 3)  # unclamped
    with pytest.raises(InputError):
        BSplineCurve(np.zeros((4, 3)), np.linspace(0, 1, 8), 3)
    bezier = np.r_[[0.0] * 4, [1.0] * 4]
    surface = BSplineSurface(np.zeros((4, 4, 3)), bezier, bezier, 3, 3)
    with pytest.raises(InputError):
        surface.boundary_curve("w0")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- conversion
def test_curve_to_bspline_matches_chain() -> None:
    chain = _chain(np.zeros(3), np.array([5.0, 1, 0]), [0.1, 0.35, 0.9])
    curve = curve_to_bspline(chain)
    s = np.linspace(0, 1, 1001)
    assert np.abs(curve.evaluate(s) - chain.evaluate(s)).max() < 1e-12
    assert curve.multiplicities()[1].tolist() == [4, 3, 3, 3, 4]


def _three_sided() -> BilinearCoons:
    c = _corners()
    return three_sided(
        _chain(c[0, 0], c[1, 0], [0.3]),
        _chain(c[1, 0], c[1, 1], [0.6, 0.7]),
        _chain(c[1, 1], c[0, 0], [0.5]),
    )


@pytest.mark.parametrize("make", [_bilinear, _bicubic, _three_sided])
def test_coons_to_bspline_is_exact(make: object) -> None:
    coons = make()  # type: ignore[operator]
    surface = coons_to_bspline(coons)
    assert (surface.degree_u, surface.degree_v) == (3, 3)
    ref = coons.evaluate(GRID[:, None], GRID[None, :])
    err = np.abs(surface.evaluate_grid(GRID, GRID) - ref).max()
    assert err < 1e-10
    su, sv = coons.derivatives(GRID[:, None], GRID[None, :])
    assert np.abs(surface.evaluate_grid(GRID, GRID, 1, 0) - su).max() < 1e-9
    assert np.abs(surface.evaluate_grid(GRID, GRID, 0, 1) - sv).max() < 1e-9
    # The breaks of bottom and top (resp. left and right) all become triple knots.
    ub = np.unique(np.concatenate([c.breaks for c in coons._u_curves]))
    ku, mu, kv, mv = surface.multiplicities()
    np.testing.assert_array_equal(ku, ub)
    assert set(mu[1:-1].tolist()) <= {3}


def test_coons_boundary_curves_are_the_sides() -> None:
    coons = _bilinear()
    surface = coons_to_bspline(coons)
    s = np.linspace(0, 1, 301)
    sides = (("v0", coons.bottom), ("u1", coons.right), ("v1", coons.top), ("u0", coons.left))
    for side, curve in sides:
        edge = surface.boundary_curve(side)  # type: ignore[arg-type]
        assert np.abs(edge.evaluate(s) - curve.evaluate(s)).max() < 1e-12


def test_shared_side_gives_identical_edge_curves() -> None:
    c = _corners()
    shared = _chain(c[0, 1], c[1, 1], [0.25, 0.7])
    lower = BilinearCoons(
        _chain(c[0, 0], c[1, 0], [0.5]),
        _chain(c[1, 0], c[1, 1], [0.6]),
        shared,
        _chain(c[0, 0], c[0, 1], [0.4]),
    )
    up = c[:, 1] + [0, 2.0, 0.3]
    upper = BilinearCoons(
        shared,
        _chain(c[1, 1], up[1], [0.3]),
        _chain(up[0], up[1], [0.5]),
        _chain(c[0, 1], up[0], [0.2, 0.8]),
    )
    a = coons_to_bspline(lower).boundary_curve("v1")
    b = coons_to_bspline(upper).boundary_curve("v0")
    # Same side, same refinement (both opposite sides break at 0.5): the very same data.
    np.testing.assert_array_equal(a.poles, b.poles)
    np.testing.assert_array_equal(a.knots, b.knots)
    assert a.degree == b.degree
    # And with other breaks on the opposite side, still the same curve to rounding.
    upper2 = BilinearCoons(shared, upper.right, _chain(up[0], up[1], [0.1, 0.45]), upper.left)
    c2 = coons_to_bspline(upper2).boundary_curve("v0")
    s = np.linspace(0, 1, 301)
    assert np.abs(c2.evaluate(s) - a.evaluate(s)).max() < 1e-12


def _deformation(kind: str, size: float = 1.0) -> Deformation:
    m = n = 10
    mi, ni = np.meshgrid(np.arange(1, m + 1), np.arange(1, n + 1), indexing="ij")
    amp = size * 0.1 / (mi * ni)[..., None] * RNG.normal(size=(m, n, 3))
    return Deformation(amp, kind=kind)  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", ["c0", "c1", "c1full"])
def test_deformation_approximation_within_tolerance_and_zero_on_boundary(kind: str) -> None:
    deformation = _deformation(kind)
    tol = 1e-4
    surface = deformation_to_bspline(deformation, tol)
    dense = np.linspace(0, 1, 701)
    err = surface.evaluate_grid(dense, dense) - deformation.evaluate(dense[:, None], dense[None, :])
    assert np.sqrt((err**2).sum(-1)).max() <= tol
    t = RNG.uniform(size=200)
    zero, one = np.zeros_like(t), np.ones_like(t)
    edges = [(zero, t), (one, t), (t, zero), (t, one)]
    for u, v in edges:
        assert np.all(surface.evaluate(u, v) == 0.0)
    if kind != "c0":
        for (u, v), d in zip(edges, (1, 1, 0, 0)):
            su, sv = surface.derivatives(u, v)
            assert np.abs((su, sv)[1 - d]).max() <= 1e-14  # cross-boundary derivative
            assert np.abs((su, sv)[d]).max() <= 1e-14  # along the edge


def test_deformation_unreachable_tolerance_raises() -> None:
    with pytest.raises(FitError):
        deformation_to_bspline(_deformation("c0"), 1e-12, max_spans=40)


def test_add_surfaces_is_exact_and_keeps_the_coons_edges() -> None:
    coons = _bicubic()
    base = coons_to_bspline(coons)
    deformation = _deformation("c1")
    bump = deformation_to_bspline(deformation, 1e-5)
    total = add_surfaces(base, bump)
    ref = base.evaluate_grid(GRID, GRID) + bump.evaluate_grid(GRID, GRID)
    assert np.abs(total.evaluate_grid(GRID, GRID) - ref).max() < 1e-12
    for side in ("u0", "u1", "v0", "v1"):
        edge, own = total.boundary_curve(side), base.boundary_curve(side)  # type: ignore[arg-type]
        assert np.abs(edge.evaluate(GRID) - own.evaluate(GRID)).max() < 1e-12
        refined = own.with_knots_inserted(np.setdiff1d(edge.knots, own.knots))
        np.testing.assert_array_equal(edge.poles, refined.poles)  # bitwise, knots merged
    # C1: the cross-boundary derivatives of the sum are the Coons ones.
    zero, one = np.zeros_like(GRID), np.ones_like(GRID)
    assert np.abs(total.derivatives(GRID, zero)[1] - coons.derivatives(GRID, zero)[1]).max() < 1e-9
    assert np.abs(total.derivatives(one, GRID)[0] - coons.derivatives(one, GRID)[0]).max() < 1e-9


def test_add_surfaces_elevates_degree() -> None:
    base = coons_to_bspline(_bilinear())
    bump = deformation_to_bspline(_deformation("c0"), 1e-3, degree=5)
    total = add_surfaces(base, bump)
    assert (total.degree_u, total.degree_v) == (5, 5)
    ref = base.evaluate_grid(GRID, GRID) + bump.evaluate_grid(GRID, GRID)
    assert np.abs(total.evaluate_grid(GRID, GRID) - ref).max() < 1e-11


def test_patch_to_bspline_matches_deformed_patch() -> None:
    coons, deformation = _bilinear(), _deformation("c0")
    surface = patch_to_bspline(coons, deformation, 1e-4)
    u, v = GRID[:, None], GRID[None, :]
    ref = coons.evaluate(u, v) + deformation.evaluate(u, v)
    assert np.sqrt(((surface.evaluate_grid(GRID, GRID) - ref) ** 2).sum(-1)).max() <= 1e-4
