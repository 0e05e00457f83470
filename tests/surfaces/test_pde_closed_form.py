"""Tests of the closed-form PDE patches of thesis Chapter 4 (Eqs. 4.16-4.28)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad.errors import InputError
from pde2cad.surfaces.pde_closed_form import (
    DEFAULT_Q,
    Q_BOUNDS,
    SOLUTIONS,
    basis_functions,
    fit_pde_surface,
    pde_basis,
    plane_parameterization,
)

NOSE16 = Path(__file__).resolve().parents[2] / "examples" / "data" / "nose16.csv"

# Table 4.3 (mean errors of X1..X4 on the 16 nose points) and Table 4.2 (X4: max 5.52e-5).
THESIS_MEAN_16 = {"X1": 4.9378e-4, "X2": 4.1927e-5, "X3": 1.2499e-4, "X4": 2.31e-5}
THESIS_MAX_16 = 5.52e-5  # the only maximum the thesis gives; held against all four here


def _nose16() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points and their uniform 4x4 (u, v) grid: row = v index, col = u index."""
    if not NOSE16.exists():
        pytest.skip(f"{NOSE16} is not available")
    rows = [
        line.split(",")
        for line in NOSE16.read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ][1:]
    data = np.array(rows, dtype=float)
    params = np.stack([data[:, 1] / 3.0, data[:, 0] / 3.0], axis=1)
    return data[:, 2:], params


def _grid(n: int) -> NDArray[np.float64]:
    g = np.linspace(0.0, 1.0, n)
    u, v = np.meshgrid(g, g)
    return np.stack([u.ravel(), v.ravel()], axis=1)


def _sphere_part(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """A 92 x 92 degree part of the unit sphere."""
    th, ph = (u - 0.5) * 1.6, (v - 0.5) * 1.6
    return np.stack([np.sin(th) * np.cos(ph), np.sin(ph), np.cos(th) * np.cos(ph)], axis=-1)


def _sine_bump(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.stack([u, v, 0.3 * np.sin(np.pi * u) * np.sin(np.pi * v)], axis=-1)


# ---------------------------------------------------------------------------- basis (Eq. 4.20)


def test_x4_basis_follows_eq_4_20_order() -> None:
    rng = np.random.default_rng(0)
    u, v = rng.random(50), rng.random(50)
    q2, q4 = 0.1, 0.1
    eu, ev = np.exp(q2 * u), np.exp(q4 * v)
    cu, su, cv, sv = np.cos(q2 * u), np.sin(q2 * u), np.cos(q4 * v), np.sin(q4 * v)
    expected = np.stack(
        [
            eu * ev * cu * cv, eu * ev * cu * sv, eu * ev * su * cv, eu * ev * su * sv,
            eu / ev * cu * cv, eu / ev * cu * sv, eu / ev * su * cv, eu / ev * su * sv,
            ev / eu * cu * cv, ev / eu * cu * sv, ev / eu * su * cv, ev / eu * su * sv,
            cu * cv / (eu * ev), cu * sv / (eu * ev), su * cv / (eu * ev), su * sv / (eu * ev),
        ],
        axis=1,
    )  # fmt: skip
    np.testing.assert_allclose(basis_functions(u, v), expected, rtol=1e-14, atol=1e-15)


def test_x4_64_basis_tail_follows_eq_4_27() -> None:
    rng = np.random.default_rng(1)
    u, v = rng.random(20), rng.random(20)
    q = {"q2": 0.3, "q4": 0.4, "q5": 1.7, "q6": 2.3}
    f = basis_functions(u, v, "X4", 64, q)
    q4, q5, q6 = q["q4"], q["q5"], q["q6"]
    em5 = np.exp(-q5 * u)
    # f49..f56: e^{-q5 u} cos(q5 u) times the first half of Eq. 4.26's v factor, then q6 half.
    v_factor = [
        np.exp(q4 * v) * np.cos(q4 * v), np.exp(q4 * v) * np.sin(q4 * v),
        np.exp(-q4 * v) * np.cos(q4 * v), np.exp(-q4 * v) * np.sin(q4 * v),
        np.exp(q6 * v) * np.cos(q6 * v), np.exp(q6 * v) * np.sin(q6 * v),
        np.exp(-q6 * v) * np.cos(q6 * v), np.exp(-q6 * v) * np.sin(q6 * v),
    ]  # fmt: skip
    for k, g in enumerate(v_factor):
        np.testing.assert_allclose(f[:, 48 + k], em5 * np.cos(q5 * u) * g, rtol=1e-13)
        np.testing.assert_allclose(f[:, 56 + k], em5 * np.sin(q5 * u) * g, rtol=1e-13)


def test_x1_basis_is_product_of_eq_4_11_and_4_14() -> None:
    u, v = np.array([0.2, 0.9]), np.array([0.7, 0.1])
    q1, q3 = 0.5, 0.8
    fu = [np.exp(q1 * u), np.exp(-q1 * u), np.cos(q1 * u), np.sin(q1 * u)]
    gv = [np.exp(q3 * v), np.exp(-q3 * v), np.cos(q3 * v), np.sin(q3 * v)]
    expected = np.stack([a * b for a in fu for b in gv], axis=1)
    np.testing.assert_allclose(basis_functions(u, v, "X1", 16, {"q1": q1, "q3": q3}), expected)


@pytest.mark.parametrize("solution", SOLUTIONS)
def test_basis_solves_the_pde_eq_4_1(solution: str) -> None:
    """Each f_j has f_uuuu = k_u f and f_vvvv = k_v f with constants shared by all 16 terms,
    so a1 X_uuuu + a2 X_vvvv = 0 holds with a1 = k_v, a2 = -k_u (Eqs. 4.1, 4.6, 4.13)."""
    basis = pde_basis(solution, 16, {"q1": 0.7, "q2": 0.9, "q3": 1.1, "q4": 1.3})
    rng = np.random.default_rng(2)
    u, v = rng.random(30), rng.random(30)
    f = basis.values(u, v)
    f_uuuu = basis.values(u, v, du=4)
    f_vvvv = basis.values(u, v, dv=4)
    k_u = np.median(f_uuuu / f)
    k_v = np.median(f_vvvv / f)
    np.testing.assert_allclose(f_uuuu, k_u * f, atol=1e-12)
    np.testing.assert_allclose(f_vvvv, k_v * f, atol=1e-12)
    np.testing.assert_allclose(k_v * f_uuuu - k_u * f_vvvv, 0.0, atol=1e-12)


def test_derivatives_match_finite_differences() -> None:
    uv = _grid(12)
    surf = fit_pde_surface(_sphere_part(uv[:, 0], uv[:, 1]), uv, terms=64)
    # h = 1e-5 balances truncation (~h^2) against round-off of the evaluation (~1e-13 / h).
    u, v, h = np.array([0.13, 0.5, 0.91]), np.array([0.77, 0.02, 0.4]), 1e-5
    su, sv = surf.derivatives(u, v)
    np.testing.assert_allclose(
        su, (surf.evaluate(u + h, v) - surf.evaluate(u - h, v)) / (2 * h), atol=1e-6
    )
    np.testing.assert_allclose(
        sv, (surf.evaluate(u, v + h) - surf.evaluate(u, v - h)) / (2 * h), atol=1e-6
    )
    suu, suv, svv = surf.second_derivatives(u, v)
    np.testing.assert_allclose(
        suv, (surf.derivatives(u, v + h)[0] - surf.derivatives(u, v - h)[0]) / (2 * h), atol=1e-5
    )
    np.testing.assert_allclose(
        suu, (surf.derivatives(u + h, v)[0] - surf.derivatives(u - h, v)[0]) / (2 * h), atol=1e-5
    )
    np.testing.assert_allclose(
        svv, (surf.derivatives(u, v + h)[1] - surf.derivatives(u, v - h)[1]) / (2 * h), atol=1e-5
    )


def test_evaluate_broadcasts() -> None:
    points, params = _nose16()
    surf = fit_pde_surface(points, params)
    u = np.linspace(0, 1, 5)[:, None]
    v = np.linspace(0, 1, 7)[None, :]
    assert surf.evaluate(u, v).shape == (5, 7, 3)
    su, sv = surf.derivatives(u, v)
    assert su.shape == sv.shape == (5, 7, 3)
    assert surf.evaluate(0.5, 0.5).shape == (3,)
    np.testing.assert_allclose(surf.evaluate(params[:, 0], params[:, 1]), points, atol=1e-8)


# ------------------------------------------------------------- nose16 (Tables 4.1-4.3)


@pytest.mark.parametrize("solution", SOLUTIONS)
def test_nose16_beats_thesis_tables(
    solution: str, record_property: pytest.RecordProperty
) -> None:
    points, params = _nose16()
    surf = fit_pde_surface(points, params, solution=solution)
    err = surf.errors
    record_property("errors", err)
    record_property("condition", surf.condition)
    print(f"{solution}: max {err['max']:.3e} mean {err['mean']:.3e} cond {surf.condition:.2e}")
    assert surf.solution == solution and surf.terms == 16
    assert surf.coefficients.shape == (16, 3) and surf.params.shape == (16, 2)
    assert not surf.underdetermined and surf.rank == 16
    assert err["mean"] <= THESIS_MEAN_16[solution]
    assert err["max"] <= THESIS_MAX_16
    # A stable solve interpolates the 16 points (measured 8e-11 .. 2e-9).
    assert err["max"] < 1e-8
    assert err["max_orthogonal"] <= err["max"] + 1e-15
    assert err["mean_orthogonal"] <= err["mean"] + 1e-15


def test_stable_solve_beats_normal_equations_on_nose16() -> None:
    """Eq. 4.24 solved as written squares a condition number of ~7e9 (NOTES.md)."""
    points, params = _nose16()
    design = basis_functions(params[:, 0], params[:, 1])
    assert np.linalg.cond(design) > 1e9
    normal = np.linalg.solve(design.T @ design, design.T @ points)
    normal_max = np.linalg.norm(design @ normal - points, axis=1).max()
    surf = fit_pde_surface(points, params)
    print(f"normal equations max {normal_max:.3e}, stable max {surf.errors['max']:.3e}")
    assert surf.errors["max"] * 1000.0 <= normal_max


# ------------------------------------------------------------------- 64 terms (Eq. 4.28)


@pytest.mark.parametrize("shape", [_sphere_part, _sine_bump])
def test_64_terms_beat_16_on_dense_surface(shape) -> None:  # noqa: ANN001
    uv = _grid(20)
    points = shape(uv[:, 0], uv[:, 1])
    s16 = fit_pde_surface(points, uv)
    s64 = fit_pde_surface(points, uv, terms=64)
    assert s64.coefficients.shape == (64, 3)
    assert s64.q == {"q2": 0.1, "q4": 0.1, "q5": DEFAULT_Q["q5"], "q6": DEFAULT_Q["q6"]}
    # Measured: sphere 2.0e-3 -> 3.3e-7, sine bump 5.9e-3 -> 2.3e-6.
    assert s64.errors["rms"] * 1000.0 < s16.errors["rms"]
    # Between the samples too (no wiggles): compare with the true surface on a finer grid.
    fine = _grid(41)
    true = shape(fine[:, 0], fine[:, 1])
    e16 = np.linalg.norm(s16.evaluate(fine[:, 0], fine[:, 1]) - true, axis=1).max()
    e64 = np.linalg.norm(s64.evaluate(fine[:, 0], fine[:, 1]) - true, axis=1).max()
    assert e64 * 500.0 < e16


def test_extra_terms_with_thesis_q_add_nothing() -> None:
    """q5 = q6 = 0.1 repeats the q2/q4 family: why the defaults differ from it."""
    uv = _grid(20)
    points = _sphere_part(uv[:, 0], uv[:, 1])
    s16 = fit_pde_surface(points, uv)
    same = fit_pde_surface(points, uv, terms=64, q={"q5": 0.1, "q6": 0.1})
    assert same.rank <= 16
    assert same.errors["rms"] > 0.9 * s16.errors["rms"]


@pytest.mark.parametrize(("solution", "terms"), [("X4", 16), ("X2", 16), ("X4", 64)])
def test_recovers_surface_sampled_from_the_model(solution: str, terms: int) -> None:
    rng = np.random.default_rng(3)
    q = {"q1": 0.6, "q2": 0.5, "q3": 0.7, "q4": 0.8, "q5": 2.5, "q6": 1.5}
    coef = rng.uniform(-1.0, 1.0, (terms, 3))
    uv = rng.random((300, 2))
    points = basis_functions(uv[:, 0], uv[:, 1], solution, terms, q) @ coef
    # center=False: the pure Eq. 4.21 / 4.28, which contains the sampled surface exactly.
    surf = fit_pde_surface(points, uv, solution=solution, terms=terms, q=q, center=False)
    assert np.all(surf.origin == 0.0)
    fine = _grid(31)
    true = basis_functions(fine[:, 0], fine[:, 1], solution, terms, q) @ coef
    got = surf.evaluate(fine[:, 0], fine[:, 1])
    scale = np.abs(true).max()
    assert np.abs(got - true).max() < 1e-8 * scale
    assert surf.errors["max"] < 1e-9 * scale


# ------------------------------------------------------------- parameterization (Fig. 4.10)


def test_pca_parameterization_of_tilted_plane() -> None:
    rng = np.random.default_rng(4)
    local = np.column_stack([rng.uniform(0, 3, 200), rng.uniform(0, 1, 200), np.zeros(200)])
    angle_a, angle_b = 0.7, -0.4
    rot_x = np.array(
        [[1, 0, 0], [0, np.cos(angle_a), -np.sin(angle_a)], [0, np.sin(angle_a), np.cos(angle_a)]]
    )
    rot_z = np.array(
        [[np.cos(angle_b), -np.sin(angle_b), 0], [np.sin(angle_b), np.cos(angle_b), 0], [0, 0, 1]]
    )
    points = local @ (rot_z @ rot_x).T + np.array([5.0, -2.0, 1.0])
    surf = fit_pde_surface(points)
    uv = surf.params
    np.testing.assert_allclose(uv.min(axis=0), 0.0, atol=1e-15)
    np.testing.assert_allclose(uv.max(axis=0), 1.0, atol=1e-15)
    # The projection is affine: (u, v) is an affine function of the in-plane coordinates,
    # with u along the long side (up to the sample's slight PCA tilt and orientation).
    affine = np.column_stack([local[:, :2], np.ones(200)])
    coef = np.linalg.lstsq(affine, uv, rcond=None)[0]
    np.testing.assert_allclose(affine @ coef, uv, atol=1e-12)
    assert abs(coef[0, 0]) > 10 * abs(coef[1, 0])
    # 16 terms: the f_j reproduce linear functions only to ~1e-7 of the size (q = 0.1 is
    # close to, not equal to, the cubic limit); measured max 2.2e-7 on this 3 x 1 plane.
    assert surf.errors["max"] < 1e-6
    assert surf.errors["max_orthogonal"] <= surf.errors["max"]
    s64 = fit_pde_surface(points, terms=64)
    assert s64.errors["max"] < 1e-9  # measured 1.9e-11
    # The fitted patch lies in the plane: its normal offset is ~0 everywhere.
    normal = np.cross(*(rot_z @ rot_x)[:, :2].T)
    fine = _grid(11)
    offsets = (surf.evaluate(fine[:, 0], fine[:, 1]) - points[0]) @ normal
    assert np.abs(offsets).max() < 1e-6
    offsets64 = (s64.evaluate(fine[:, 0], fine[:, 1]) - points[0]) @ normal
    assert np.abs(offsets64).max() < 1e-9


def test_fit_does_not_depend_on_placement() -> None:
    uv = _grid(10)
    points = _sphere_part(uv[:, 0], uv[:, 1])
    shift = np.array([500.0, -200.0, 100.0])
    near = fit_pde_surface(points, uv)
    far = fit_pde_surface(points + shift, uv)
    np.testing.assert_allclose(far.origin - near.origin, shift)
    np.testing.assert_allclose(far.coefficients, near.coefficients, rtol=1e-6, atol=1e-9)
    assert far.errors["max"] == pytest.approx(near.errors["max"], rel=1e-4)
    # The pure Eq. 4.21 (center=False) moves with the shift: the f_j hold constants only
    # approximately. Measured on a plane: 2.2e-7 near the origin, 2e-4 at this shift.
    plane = np.column_stack([uv, np.zeros(len(uv))])
    pure_far = fit_pde_surface(plane + shift, uv, center=False)
    centred_far = fit_pde_surface(plane + shift, uv)
    assert centred_far.errors["max"] * 100.0 < pure_far.errors["max"]


def test_plane_parameterization_is_deterministic_under_point_order() -> None:
    rng = np.random.default_rng(5)
    points = np.column_stack([rng.random(50), 2 * rng.random(50), 0.1 * rng.random(50)])
    perm = rng.permutation(50)
    np.testing.assert_allclose(
        plane_parameterization(points)[perm], plane_parameterization(points[perm]), atol=1e-12
    )


# ----------------------------------------------------------------- solve options


def test_fewer_points_than_terms_gives_min_norm_interpolant_without_warnings() -> None:
    points, params = _nose16()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        surf = fit_pde_surface(points[:10], params[:10])
        surf64 = fit_pde_surface(points, params, terms=64)
    assert surf.underdetermined and surf.rank <= 10
    assert surf64.underdetermined and surf64.rank == 16
    assert surf.errors["max"] < 1e-9
    assert surf64.errors["max"] < 1e-9


def test_ridge_trades_accuracy_for_smaller_coefficients() -> None:
    uv = _grid(10)
    points = _sphere_part(uv[:, 0], uv[:, 1])
    plain = fit_pde_surface(points, uv, terms=64)
    ridged = fit_pde_surface(points, uv, terms=64, ridge=1e-6)
    assert ridged.ridge == 1e-6
    assert np.linalg.norm(ridged.coefficients) < np.linalg.norm(plain.coefficients)
    assert plain.errors["rms"] < ridged.errors["rms"] < 1e-2


def test_fit_q_improves_64_term_fit_within_bounds() -> None:
    uv = _grid(12)
    points = _sphere_part(uv[:, 0], uv[:, 1])
    default = fit_pde_surface(points, uv, terms=64)
    tuned = fit_pde_surface(points, uv, terms=64, fit_q=True)
    assert tuned.q_fitted and not default.q_fitted
    assert tuned.q["q2"] == DEFAULT_Q["q2"] and tuned.q["q4"] == DEFAULT_Q["q4"]
    for name in ("q5", "q6"):
        assert Q_BOUNDS[0] <= tuned.q[name] <= Q_BOUNDS[1]
    assert tuned.errors["rms"] < 0.5 * default.errors["rms"]


def test_fit_q_is_skipped_when_the_patch_interpolates() -> None:
    points, params = _nose16()
    surf = fit_pde_surface(points, params, fit_q=True)
    assert not surf.q_fitted and surf.q == {"q2": 0.1, "q4": 0.1}


# ----------------------------------------------------------------- closest points


def test_orthogonal_distance_of_offset_points() -> None:
    uv = _grid(15)
    surf = fit_pde_surface(_sphere_part(uv[:, 0], uv[:, 1]), uv, terms=64)
    rng = np.random.default_rng(6)
    true_uv = rng.uniform(0.1, 0.9, (400, 2))
    su, sv = surf.derivatives(true_uv[:, 0], true_uv[:, 1])
    normal = np.cross(su, sv)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    delta = 0.02
    query = surf.evaluate(true_uv[:, 0], true_uv[:, 1]) + delta * normal
    start = np.clip(true_uv + rng.normal(0.0, 0.03, true_uv.shape), 0.0, 1.0)
    found, dist = surf.closest_points(query, start)
    np.testing.assert_allclose(dist, delta, atol=1e-9)
    np.testing.assert_allclose(found, true_uv, atol=1e-7)


def test_orthogonal_errors_with_poor_params() -> None:
    uv = _grid(20)
    points = _sphere_part(uv[:, 0], uv[:, 1])
    rng = np.random.default_rng(7)
    noisy_uv = np.clip(uv + rng.normal(0.0, 0.02, uv.shape), 0.0, 1.0)
    surf = fit_pde_surface(points, noisy_uv)
    err = surf.errors
    # Parameter noise shows in the parametric error, much less in the distance to the patch.
    assert err["mean_orthogonal"] * 5.0 < err["mean"]
    assert err["max_orthogonal"] <= err["max"]


# ------------------------------------------------------------------- bad inputs


def _some_points() -> NDArray[np.float64]:
    return _sine_bump(*_grid(5).T)


@pytest.mark.parametrize(
    ("points", "kwargs", "match"),
    [
        (np.zeros((5, 2)), {}, r"shape \(5, 2\); pass an \(N, 3\)"),
        ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], {}, "2 point"),
        (np.ones((6, 3)), {}, "all points coincide"),
        (np.outer(np.arange(6.0), [1, 2, 3]), {}, "points are collinear; a surface needs a 2D"),
        ("abc", {}, "cannot be read"),
        (None, {"solution": "X5"}, "solution 'X5' is unknown"),
        (None, {"terms": 32}, "terms = 32 is not supported"),
        (None, {"q": {"q7": 1.0}}, "unknown q constant"),
        (None, {"q": {"q2": -1.0}}, "q2 = -1.0 is not a positive"),
        (None, {"ridge": -1.0}, "ridge = -1.0"),
        (None, {"params": np.zeros((24, 2))}, r"params has shape \(24, 2\); pass \(25, 2\)"),
        (None, {"params": np.full((25, 2), 1.5)}, r"params span .* rescale"),
    ],
)  # fmt: skip
def test_bad_inputs_raise_input_error(points, kwargs, match: str) -> None:  # noqa: ANN001
    pts = _some_points() if points is None else points
    with pytest.raises(InputError, match=match):
        fit_pde_surface(pts, **kwargs)


def test_nan_rows_are_counted() -> None:
    points = _some_points()
    points[[1, 4, 7]] = np.nan
    points[9, 2] = np.inf
    with pytest.raises(InputError, match="points has 4 row"):
        fit_pde_surface(points)
    with pytest.raises(ValueError, match="NaN or inf"):
        fit_pde_surface(_some_points(), np.full((25, 2), np.nan))
