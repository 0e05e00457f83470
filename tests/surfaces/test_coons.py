"""Tests of the boundary chains and Coons patches of thesis Chapter 5 (Eqs. 5.1-5.7)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from pde2cad.curves import bezier
from pde2cad.errors import FitError, InputError
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import (
    BicubicCoons,
    BilinearCoons,
    estimate_cross_derivatives,
    three_sided,
)

RNG = np.random.default_rng(20240611)
JET = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))


def _tensor_patch() -> NDArray[np.float64]:
    """Control net (4, 4, 3) of a curved bicubic Bézier patch over roughly [0, 3]^2."""
    i, j = np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij")
    net = np.stack([i, j, np.zeros_like(i)], axis=-1)
    net += RNG.normal(scale=0.3, size=net.shape)
    return net


def _tensor_eval(
    net: NDArray[np.float64], u: NDArray[np.float64], v: NDArray[np.float64]
) -> NDArray[np.float64]:
    return np.einsum("...i,...j,ijd->...d", bezier.bernstein(u), bezier.bernstein(v), net)


def _tensor_data(net: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    """Sides and ribbons of a tensor patch, each a cubic (4, 3) in the module convention."""
    return {
        "bottom": net[:, 0],
        "right": net[3, :],
        "top": net[:, 3],
        "left": net[0, :],
        "d_bottom": 3.0 * (net[:, 1] - net[:, 0]),
        "d_right": 3.0 * (net[3, :] - net[2, :]),
        "d_top": 3.0 * (net[:, 3] - net[:, 2]),
        "d_left": 3.0 * (net[1, :] - net[0, :]),
    }


def _chain_sides() -> tuple[PiecewiseBezier, PiecewiseBezier, PiecewiseBezier, PiecewiseBezier]:
    """Four sides, two of them 2-piece chains with different breaks, meeting at the corners."""
    p00, p10, p11, p01 = (
        np.array(p, dtype=float) for p in ([0, 0, 0], [3, 0, 0.5], [3, 3, 0], [0, 3, 1])
    )
    bottom = PiecewiseBezier.from_chain(
        np.stack(
            [
                [p00, [0.5, -0.4, 0.3], [1.0, 0.3, 0.6], [1.6, 0.1, 0.4]],
                [[1.6, 0.1, 0.4], [2.2, -0.1, 0.2], [2.6, -0.3, 0.6], p10],
            ]
        )
    )
    right = PiecewiseBezier.from_cubic([p10, [3.4, 1.0, 0.0], [2.8, 2.0, 0.9], p11])
    top = PiecewiseBezier.from_chain(
        np.stack(
            [
                [p01, [0.7, 3.4, 1.2], [1.2, 3.1, 0.3], [1.5, 3.0, 0.5]],
                [[1.5, 3.0, 0.5], [1.9, 2.9, 0.7], [2.5, 3.3, -0.2], p11],
            ]
        ),
        spacing="uniform",
    )
    left = PiecewiseBezier.from_cubic([p00, [-0.4, 1.0, 0.5], [0.3, 2.0, 1.4], p01])
    return bottom, right, top, left


# ------------------------------------------------------------------------- PiecewiseBezier
def test_chain_evaluates_each_cubic_on_its_interval() -> None:
    bottom, *_ = _chain_sides()
    k0, k1 = bottom.ctrl
    b = bottom.breaks[1]
    s = np.linspace(0.0, 1.0, 101)
    local0, local1 = s[s < b] / b, (s[s >= b] - b) / (1.0 - b)
    expected = np.concatenate([bezier.evaluate(k0, local0), bezier.evaluate(k1, local1)])
    np.testing.assert_allclose(bottom.evaluate(s), expected, atol=1e-13)
    d2 = np.concatenate(
        [bezier.derivative(k0, local0, 2) / b**2, bezier.derivative(k1, local1, 2) / (1 - b) ** 2]
    )
    np.testing.assert_allclose(bottom.derivative(s, 2), d2, atol=1e-11)


def test_reversed_runs_backwards() -> None:
    bottom, *_ = _chain_sides()
    s = RNG.random(50)
    rev = bottom.reversed()
    np.testing.assert_allclose(rev.evaluate(s), bottom.evaluate(1.0 - s), atol=1e-13)
    np.testing.assert_allclose(rev.derivative(s), -bottom.derivative(1.0 - s), atol=1e-12)


def test_to_bspline_is_exact() -> None:
    bottom, *_ = _chain_sides()
    poles, knots, degree = bottom.to_bspline()
    assert poles.shape == (7, 3) and knots.shape == (11,) and degree == 3
    s = np.linspace(0.0, 1.0, 201)
    np.testing.assert_allclose(BSpline(knots, poles, degree)(s), bottom.evaluate(s), atol=1e-13)


def test_point_curve_is_constant() -> None:
    p = PiecewiseBezier.from_point([1.0, 2.0, 3.0])
    np.testing.assert_array_equal(p.evaluate(RNG.random(5)), np.tile([1.0, 2.0, 3.0], (5, 1)))
    np.testing.assert_array_equal(p.derivative(RNG.random(5)), np.zeros((5, 3)))


@pytest.mark.parametrize(
    ("ctrl", "breaks", "match"),
    [
        (np.zeros((2, 4, 3)), [0.0, 0.7, 0.6], "increase strictly"),
        (np.zeros((1, 4, 3)), [0.0, 0.5], "increase strictly"),
        (np.full((1, 4, 3), np.nan), [0.0, 1.0], "NaN"),
        (np.zeros((2, 3, 3)), [0.0, 0.5, 1.0], r"\(K, 4, D\)"),
    ],
)
def test_chain_rejects_bad_input(
    ctrl: NDArray[np.float64], breaks: list[float], match: str
) -> None:
    with pytest.raises(InputError, match=match):
        PiecewiseBezier(ctrl, np.asarray(breaks))


def test_chain_rejects_a_gap() -> None:
    ctrl = np.zeros((2, 4, 3))
    ctrl[1] += 1.0
    with pytest.raises(InputError, match="cubic 0 ends"):
        PiecewiseBezier(ctrl, np.array([0.0, 0.5, 1.0]))


# ------------------------------------------------------------------------- bilinear (Eq. 5.1)
def test_bilinear_reproduces_its_four_sides() -> None:
    bottom, right, top, left = _chain_sides()
    patch = BilinearCoons(bottom, right, top, left)
    t = np.linspace(0.0, 1.0, 257)
    np.testing.assert_allclose(patch.evaluate(t, 0.0), bottom.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.evaluate(t, 1.0), top.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.evaluate(0.0, t), left.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.evaluate(1.0, t), right.evaluate(t), rtol=0, atol=1e-12)


def test_bilinear_matches_eq_5_1() -> None:
    bottom, right, top, left = _chain_sides()
    patch = BilinearCoons(bottom, right, top, left)
    u, v = RNG.random(100), RNG.random(100)
    p = patch.corners
    uu, vv = u[:, None], v[:, None]
    expected = (
        (1 - vv) * bottom.evaluate(u)
        + vv * top.evaluate(u)
        + (1 - uu) * left.evaluate(v)
        + uu * right.evaluate(v)
        - (
            (1 - uu) * (1 - vv) * p[0, 0]
            + uu * (1 - vv) * p[1, 0]
            + (1 - uu) * vv * p[0, 1]
            + uu * vv * p[1, 1]
        )
    )
    np.testing.assert_allclose(patch.evaluate(u, v), expected, atol=1e-13)


def test_evaluate_broadcasts_over_a_grid() -> None:
    patch = BilinearCoons(*_chain_sides())
    u, v = np.linspace(0, 1, 5), np.linspace(0, 1, 7)
    grid = patch.evaluate(u[:, None], v[None, :])
    assert grid.shape == (5, 7, 3)
    np.testing.assert_allclose(grid[3, 4], patch.evaluate(u[3], v[4]), atol=1e-14)


def test_from_loop_reverses_top_and_left() -> None:
    bottom, right, top, left = _chain_sides()
    direct = BilinearCoons(bottom, right, top, left)
    loop = BilinearCoons.from_loop(bottom, right, top.reversed(), left.reversed())
    u, v = RNG.random(50), RNG.random(50)
    np.testing.assert_allclose(loop.evaluate(u, v), direct.evaluate(u, v), atol=1e-13)


def test_corner_mismatch_names_the_corner() -> None:
    bottom, right, top, left = _chain_sides()
    moved = left.ctrl[0].copy()
    moved[3] += [0.0, 0.0, 0.1]
    with pytest.raises(InputError, match=r"corner S\(0,1\).*top\(0\).*left\(1\)"):
        BilinearCoons(bottom, right, top, moved)
    with pytest.raises(InputError, match="reversed"):
        BilinearCoons(bottom, right, top.reversed(), left)


def test_three_sided_collapses_the_top() -> None:
    a, b, apex = np.array([0.0, 0, 0]), np.array([2.0, 0, 0]), np.array([1.0, 2.0, 0.5])
    c0 = np.array([a, [0.7, -0.3, 0.2], [1.4, 0.2, -0.2], b])
    c1 = np.array([b, [2.2, 0.8, 0.0], [1.6, 1.6, 0.6], apex])
    c2 = np.array([apex, [0.5, 1.5, 0.7], [-0.2, 0.8, 0.0], a])
    patch = three_sided(c0, c1, c2)
    t = np.linspace(0, 1, 101)
    np.testing.assert_allclose(patch.evaluate(t, 1.0), np.tile(apex, (101, 1)), atol=1e-13)
    np.testing.assert_allclose(patch.evaluate(t, 0.0), bezier.evaluate(c0, t), atol=1e-13)
    np.testing.assert_allclose(patch.evaluate(1.0, t), bezier.evaluate(c1, t), atol=1e-13)
    np.testing.assert_allclose(patch.evaluate(0.0, t), bezier.evaluate(c2, 1 - t), atol=1e-13)
    su, _ = patch.derivatives(t, 1.0)
    np.testing.assert_allclose(su, 0.0, atol=1e-13)  # the documented singularity


@pytest.mark.parametrize("kind", ["bilinear", "bicubic"])
def test_derivatives_match_finite_differences(kind: str) -> None:
    bottom, right, top, left = _chain_sides()
    if kind == "bilinear":
        patch: BilinearCoons | BicubicCoons = BilinearCoons(bottom, right, top, left)
    else:
        rib = RNG.normal(size=(4, 4, 3))
        patch = BicubicCoons(bottom, right, top, left, *rib)
    # Stay off the breaks, where the chains are only C0.
    u = RNG.uniform(0.05, 0.4, 60)
    v = RNG.uniform(0.05, 0.95, 60)
    h = 1e-6
    su, sv = patch.derivatives(u, v)
    suu, suv, svv = patch.second_derivatives(u, v)
    np.testing.assert_allclose(
        su, (patch.evaluate(u + h, v) - patch.evaluate(u - h, v)) / (2 * h), atol=1e-7
    )
    np.testing.assert_allclose(
        sv, (patch.evaluate(u, v + h) - patch.evaluate(u, v - h)) / (2 * h), atol=1e-7
    )
    d_u = [
        (a - b) / (2 * h)
        for a, b in zip(patch.derivatives(u + h, v), patch.derivatives(u - h, v), strict=True)
    ]
    d_v = [
        (a - b) / (2 * h)
        for a, b in zip(patch.derivatives(u, v + h), patch.derivatives(u, v - h), strict=True)
    ]
    np.testing.assert_allclose(suu, d_u[0], atol=1e-6)
    np.testing.assert_allclose(suv, d_u[1], atol=1e-6)
    np.testing.assert_allclose(suv, d_v[0], atol=1e-6)
    np.testing.assert_allclose(svv, d_v[1], atol=1e-6)


@pytest.mark.parametrize("kind", ["bilinear", "bicubic"])
def test_jet_on_polynomial_cells_equals_the_boolean_sum(kind: str) -> None:
    bottom, right, top, left = _chain_sides()
    if kind == "bilinear":
        patch: BilinearCoons | BicubicCoons = BilinearCoons(bottom, right, top, left)
    else:
        patch = BicubicCoons(bottom, right, top, left, *RNG.normal(size=(4, 4, 3)))
    ub, vb, coef = patch.power_cells()
    np.testing.assert_array_equal(ub, np.union1d(bottom.breaks, top.breaks))  # 0, b1, b2, 1
    assert vb.tolist() == [0.0, 1.0] and coef.shape == (3, 1, 4, 4, 3)
    u, v = RNG.random(500), RNG.random(500)
    u[:4] = ub
    jet = patch.jet(u, v)
    reference = (patch.evaluate(u, v), *patch.derivatives(u, v), *patch.second_derivatives(u, v))
    for fast, slow in zip(jet, reference, strict=True):
        np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-11)


def test_jet_of_many_points_equals_the_jets_of_their_parts() -> None:
    """Large calls run in blocks (bounding the per-point cell coefficients): the values
    must be those of small calls, bit for bit, on ruled (bilinear) and full (bicubic) cells."""
    bottom, right, top, left = _chain_sides()
    for patch in (
        BilinearCoons(bottom, right, top, left),
        BicubicCoons(bottom, right, top, left, *RNG.normal(size=(4, 4, 3))),
    ):
        u, v = RNG.random(140_000), RNG.random(140_000)
        whole = patch.jet(u, v)
        parts = [patch.jet(a, b) for a, b in zip(np.array_split(u, 7), np.array_split(v, 7))]
        for k, fast in enumerate(whole):
            np.testing.assert_array_equal(fast, np.concatenate([p[k] for p in parts]))


# ------------------------------------------------------------------------- bicubic (Eqs. 5.2-5.7)
def test_bicubic_reproduces_a_bicubic_tensor_patch() -> None:
    net = _tensor_patch()
    data = _tensor_data(net)
    patch = BicubicCoons(**data)
    u, v = RNG.random(2000), RNG.random(2000)
    np.testing.assert_allclose(patch.evaluate(u, v), _tensor_eval(net, u, v), rtol=0, atol=1e-10)
    assert max(max(r.values()) for r in patch.compatibility_residuals().values()) < 1e-12


def test_bicubic_interpolates_sides_even_with_incompatible_ribbons() -> None:
    bottom, right, top, left = _chain_sides()
    patch = BicubicCoons(bottom, right, top, left, *RNG.normal(size=(4, 4, 3)))
    t = np.linspace(0.0, 1.0, 257)
    np.testing.assert_allclose(patch.evaluate(t, 0.0), bottom.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.evaluate(t, 1.0), top.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.evaluate(0.0, t), left.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.evaluate(1.0, t), right.evaluate(t), rtol=0, atol=1e-12)
    residuals = patch.compatibility_residuals()
    assert set(residuals) == {(0, 0), (1, 0), (0, 1), (1, 1)}
    assert min(r["S_v"] for r in residuals.values()) > 1e-3  # random ribbons do not agree


def _compatible_ribbons(
    bottom: PiecewiseBezier, right: PiecewiseBezier, top: PiecewiseBezier, left: PiecewiseBezier
) -> tuple[list[PiecewiseBezier], NDArray[np.float64]]:
    """Random 2-piece C1 ribbons meeting the corner conditions, and the twists."""
    twists = RNG.normal(size=(2, 2, 3))
    ends = np.array([0.0, 1.0])
    breaks = np.array([0.0, 0.4, 1.0])

    def ribbon(
        v0: NDArray[np.float64],
        v1: NDArray[np.float64],
        t0: NDArray[np.float64],
        t1: NDArray[np.float64],
    ) -> PiecewiseBezier:
        values = np.stack([v0, RNG.normal(size=3), v1])
        slopes = np.stack([t0, RNG.normal(size=3), t1])
        return PiecewiseBezier.from_hermite(values, slopes, breaks)

    dl, dr = left.derivative(ends), right.derivative(ends)
    db, dt = bottom.derivative(ends), top.derivative(ends)
    d_bottom = ribbon(dl[0], dr[0], twists[0, 0], twists[1, 0])
    d_top = ribbon(dl[1], dr[1], twists[0, 1], twists[1, 1])
    d_left = ribbon(db[0], dt[0], twists[0, 0], twists[0, 1])
    d_right = ribbon(db[1], dt[1], twists[1, 0], twists[1, 1])
    return [d_bottom, d_right, d_top, d_left], twists


def test_bicubic_interpolates_compatible_ribbons() -> None:
    sides = _chain_sides()
    ribbons, twists = _compatible_ribbons(*sides)
    patch = BicubicCoons(*sides, *ribbons)
    np.testing.assert_allclose(patch.twists, twists, atol=1e-13)  # default = ribbon average
    for residual in patch.compatibility_residuals().values():
        assert max(residual.values()) < 1e-12
    d_bottom, d_right, d_top, d_left = ribbons
    t = np.linspace(0.0, 1.0, 257)
    np.testing.assert_allclose(
        patch.derivatives(t, 0.0)[1], d_bottom.evaluate(t), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(patch.derivatives(t, 1.0)[1], d_top.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(patch.derivatives(0.0, t)[0], d_left.evaluate(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        patch.derivatives(1.0, t)[0], d_right.evaluate(t), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(patch.evaluate(t, 0.0), sides[0].evaluate(t), rtol=0, atol=1e-12)


def test_bicubic_rejects_bad_twists() -> None:
    data = _tensor_data(_tensor_patch())
    with pytest.raises(InputError, match=r"twists must have shape \(2, 2, 3\)"):
        BicubicCoons(**data, twists=np.zeros((4, 3)))
    with pytest.raises(InputError, match="NaN"):
        BicubicCoons(**data, twists=np.full((2, 2, 3), np.nan))


# ------------------------------------------------------------------------- ribbons from points
def test_estimated_ribbons_recover_a_bicubic_patch() -> None:
    net = _tensor_patch()
    data = _tensor_data(net)
    params = RNG.random((20000, 2))
    points = _tensor_eval(net, params[:, 0], params[:, 1])
    sides = [data[k] for k in ("bottom", "right", "top", "left")]
    ribbons = estimate_cross_derivatives(points, params, *sides, order=3)
    t = np.linspace(0.0, 1.0, 101)
    for name in ("d_bottom", "d_right", "d_top", "d_left"):
        np.testing.assert_allclose(
            getattr(ribbons, name).evaluate(t), bezier.evaluate(data[name], t), atol=1e-9
        )
    patch = BicubicCoons(
        *sides, ribbons.d_bottom, ribbons.d_right, ribbons.d_top, ribbons.d_left, ribbons.twists
    )
    np.testing.assert_allclose(patch.evaluate(params[:, 0], params[:, 1]), points, atol=1e-9)
    for residual in patch.compatibility_residuals().values():
        assert max(residual.values()) < 1e-12  # compatible by construction


def test_estimated_ribbons_without_matching_need_not_be_compatible() -> None:
    net = _tensor_patch()
    data = _tensor_data(net)
    params = RNG.random((5000, 2))
    points = _tensor_eval(net, params[:, 0], params[:, 1]) + RNG.normal(scale=1e-3, size=(5000, 3))
    sides = [data[k] for k in ("bottom", "right", "top", "left")]
    free = estimate_cross_derivatives(points, params, *sides, pieces=2, match_corners=False)
    matched = estimate_cross_derivatives(points, params, *sides, pieces=2)
    patch_free = BicubicCoons(
        *sides, free.d_bottom, free.d_right, free.d_top, free.d_left, free.twists
    )
    patch_matched = BicubicCoons(
        *sides, matched.d_bottom, matched.d_right, matched.d_top, matched.d_left, matched.twists
    )
    worst_free = max(r["S_v"] for r in patch_free.compatibility_residuals().values())
    worst_matched = max(max(r.values()) for r in patch_matched.compatibility_residuals().values())
    assert worst_free > 1e-6 and worst_matched < 1e-12


def test_estimate_needs_points_near_every_side() -> None:
    data = _tensor_data(_tensor_patch())
    sides = [data[k] for k in ("bottom", "right", "top", "left")]
    params = RNG.uniform(0.0, 0.8, (3000, 2))  # nothing near u = 1 or v = 1
    points = RNG.random((3000, 3))
    with pytest.raises(FitError, match=r"band=0\.15 of the top side"):
        estimate_cross_derivatives(points, params, *sides)
    with pytest.raises(InputError, match="NaN"):
        estimate_cross_derivatives(np.full((10, 3), np.nan), RNG.random((10, 2)), *sides)
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        estimate_cross_derivatives(points, params + 0.5, *sides)


# ------------------------------------------------------------------------- fast paths
def test_chain_jet_for_many_points_equals_the_per_piece_sum() -> None:
    """Many points on a chain of many cubics take the gathered-coefficient path: same values
    and derivatives as evaluating every piece and picking each point's own."""
    ctrl = RNG.normal(size=(9, 4, 3))
    ctrl[1:, 0] = ctrl[:-1, 3]
    curve = PiecewiseBezier.from_chain(ctrl)
    s = RNG.random(5000)
    s[:10] = curve.breaks
    fast = curve.jet(s, 3)
    small = np.concatenate([curve.jet(part, 3) for part in np.array_split(s, 200)], axis=1)
    np.testing.assert_allclose(fast, small, rtol=0, atol=1e-11)


@pytest.mark.parametrize("kind", ["bilinear", "bicubic"])
def test_evaluate_of_many_points_equals_the_boolean_sum(kind: str) -> None:
    """Scattered evaluations of many points run on the polynomial cells."""
    bottom, right, top, left = _chain_sides()
    if kind == "bilinear":
        patch: BilinearCoons | BicubicCoons = BilinearCoons(bottom, right, top, left)
    else:
        patch = BicubicCoons(bottom, right, top, left, *RNG.normal(size=(4, 4, 3)))
    u, v = RNG.random(6000), RNG.random(6000)
    fast = patch.evaluate(u, v)
    slow = patch._partials(u, v, ((0, 0),))[0]
    assert fast.shape == (6000, 3)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-11)
    grid = patch.evaluate(u[:, None], v[None, :50])  # a grid keeps the Boolean sum
    column = patch._partials(u, np.full(u.size, v[7]), ((0, 0),))[0]
    np.testing.assert_allclose(grid[:, 7], column, rtol=0, atol=1e-11)


def test_apex_ribbon_three_sided_bicubic_is_compatible_with_one_tangent_plane() -> None:
    """3-sided bicubic Coons (Fig. 5.11, Eqs. 5.2-5.7): top = apex, d_top = apex_ribbon;
    left/right ribbons vanish at the apex with slopes = the apex twists. The corner data are
    compatible and the limit normal at the apex is the same from every direction."""
    from pde2cad.surfaces.boundary import PiecewiseBezier
    from pde2cad.surfaces.coons import BicubicCoons, apex_ribbon

    apex = np.array([0.0, 0.0, 0.0])
    p0, p1 = np.array([1.0, 0.0, 0.1]), np.array([0.0, 1.0, 0.1])
    bottom = PiecewiseBezier(np.array([[p0, [1.0, 0.5, 0.1], [0.5, 1.0, 0.1], p1]]), np.array([0.0, 1.0]))
    right = PiecewiseBezier(np.array([[p1, [0.0, 0.6, 0.02], [0.0, 0.3, 0.0], apex]]), np.array([0.0, 1.0]))
    left = PiecewiseBezier(np.array([[p0, [0.6, 0.0, 0.02], [0.3, 0.0, 0.0], apex]]), np.array([0.0, 1.0]))
    top = PiecewiseBezier.from_point(apex)
    e = np.array([0.0, 1.0])
    lv, rv = left.derivative(e)[1], right.derivative(e)[1]
    tau0, tau1 = np.array([0.0, -1.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    d_top = apex_ribbon(left, right, tau0, tau1, normal=np.array([0.0, 0.0, 1.0]))
    assert np.allclose(d_top.evaluate(e), [lv, rv])
    assert np.allclose(d_top.derivative(e), [tau0, tau1])
    zero = np.zeros(3)
    d_left = PiecewiseBezier.from_hermite([bottom.derivative(e)[0], zero], [zero, tau0], e)
    d_right = PiecewiseBezier.from_hermite([bottom.derivative(e)[1], zero], [zero, tau1], e)
    d_bottom = PiecewiseBezier.from_hermite([left.derivative(e)[0], right.derivative(e)[0]], [zero, zero], e)
    patch = BicubicCoons(bottom, right, top, left, d_bottom, d_right, d_top, d_left)
    for residual in patch.compatibility_residuals().values():
        assert max(residual.values()) < 1e-12
    u = np.linspace(0.0, 1.0, 7)
    su, sv = patch.derivatives(u, np.full_like(u, 1.0 - 1e-6))
    nrm = np.cross(su, sv)
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    assert np.allclose(np.abs(nrm[:, 2]), 1.0, atol=1e-5)
