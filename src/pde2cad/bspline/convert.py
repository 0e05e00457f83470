"""Patches to B-spline surfaces: exact for the Coons base, to a tolerance for the deformation.

A Coons patch over piecewise-cubic sides is a piecewise bicubic polynomial (see
:meth:`pde2cad.surfaces.coons.BilinearCoons.power_cells`), so it is one B-spline surface of
degree (3, 3) once the curves blended in each direction share a knot vector. The
sine / sin^2 deformations (Eqs. 5.17, 5.21) are not polynomial: they are approximated by a
B-spline whose outer pole row (C0) or two outer rows (C1) are exactly zero, so the sum keeps
the Coons edges (and, for C1, the cross-boundary derivatives) bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from pde2cad.bspline.data import (
    BSplineCurve,
    BSplineSurface,
    basis_matrix,
    merged_knots,
    missing_knots,
)
from pde2cad.bspline.reduce import reduce_surface
from pde2cad.errors import FitError, InputError
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import BicubicCoons, BilinearCoons
from pde2cad.surfaces.deformation import Deformation, sine_basis

CoonsPatch = BilinearCoons | BicubicCoons


# --------------------------------------------------------------------------- curves
def curve_to_bspline(curve: PiecewiseBezier) -> BSplineCurve:
    """Exact clamped cubic B-spline of a chain of cubic Béziers (triple interior knots at the
    breaks, so the curve is only C0 there, as the chain is)."""
    poles, knots, degree = curve.to_bspline()
    return BSplineCurve(poles, knots, degree)


def _common_basis(
    curves: tuple[PiecewiseBezier, ...],
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]]:
    """The curves on one knot vector: the union of their breaks (multiplicity 3 each).

    Returns the knot vector (n + 4,) and each curve's poles (n, D). Refining by Boehm
    insertion is exact, and deterministic: the same side gives the same poles in every
    patch that refines it with the same knots.
    """
    splines = [curve_to_bspline(c) for c in curves]
    knots = splines[0].knots
    for s in splines[1:]:
        knots = merged_knots(knots, s.knots)
    poles = [s.with_knots_inserted(missing_knots(s.knots, knots)).poles for s in splines]
    return knots, poles


def _blend_blossoms(
    blend: Callable[[NDArray[np.float64], int], NDArray[np.float64]], knots: NDArray[np.float64]
) -> NDArray[np.float64]:
    """B-spline coefficients (n, k) of the Coons blends (cubic polynomials or lower) in the
    cubic basis on ``knots``.

    A polynomial of degree <= 3 is ``sum_j f(t_{j+1}, t_{j+2}, t_{j+3}) N_j`` with ``f`` its
    blossom (polar form): ``t^r`` has the blossom ``e_r(x1, x2, x3) / C(3, r)``, ``e_r`` the
    elementary symmetric polynomials. For the linear blends this is the Greville abscissa.
    """
    zero = np.zeros(1)
    # Taylor coefficients at 0 give the power form of every blend: coef[r, k] of t^r.
    coef = np.stack([blend(zero, r)[0] / math.factorial(r) for r in range(4)])
    n = knots.size - 4
    x = knots[np.arange(n)[:, None] + np.arange(1, 4)[None, :]]  # (n, 3)
    e = np.stack(
        [
            np.ones(n),
            x.sum(axis=1) / 3.0,
            (x[:, 0] * x[:, 1] + x[:, 0] * x[:, 2] + x[:, 1] * x[:, 2]) / 3.0,
            x.prod(axis=1),
        ],
        axis=1,
    )  # (n, 4): blossoms of 1, t, t^2, t^3
    return e @ coef


def coons_to_bspline(coons: CoonsPatch) -> BSplineSurface:
    """Exact degree-(3, 3) B-spline surface of a bilinear or bicubic Coons patch.

    The Boolean sum ``S = sum_k b_k(v) F_k(u) + sum_k b_k(u) G_k(v) - sum_kl b_k(u) b_l(v)
    C_kl`` (Eq. 5.2) is written in the tensor basis of ``U x V``: ``U`` merges the breaks of
    the curves blended in v (bottom, top and, for the bicubic patch, their ribbons), ``V``
    those of the curves blended in u. Each curve ``F_k`` is already a cubic B-spline on
    ``U``; each blend ``b_k`` (linear or cubic Hermite) is a cubic polynomial, whose
    coefficients in the basis on ``V`` are its blossoms (:func:`_blend_blossoms`).

    The four boundary rows of poles are then set to the sides' own refined poles, so
    :meth:`BSplineSurface.boundary_curve` returns exactly the side (bitwise the same poles
    as converting the side alone and inserting the same knots). At a corner, where two rows
    meet, the pole is the patch's corner ``S(i, j)`` (the mean of the two sides' ends, which
    is either side's end when they close exactly).

    Parameters
    ----------
    coons : BilinearCoons or BicubicCoons

    Returns
    -------
    BSplineSurface
        Degrees (3, 3); knots ``U`` and ``V`` with every break of multiplicity 3.
    """
    if not isinstance(coons, (BilinearCoons, BicubicCoons)):
        raise InputError(
            f"expected a BilinearCoons or BicubicCoons patch, got {type(coons).__name__}"
        )
    knots_u, f = _common_basis(coons._u_curves)
    knots_v, g = _common_basis(coons._v_curves)
    bu = _blend_blossoms(coons._blend, knots_u)  # (nu, k)
    bv = _blend_blossoms(coons._blend, knots_v)  # (nv, k)
    f_arr, g_arr = np.stack(f), np.stack(g)  # (k, nu, D), (k, nv, D)
    corner = coons._corner_data  # (k, k, D)
    poles = (
        np.einsum("jk,kid->ijd", bv, f_arr)
        + np.einsum("ik,kjd->ijd", bu, g_arr)
        - np.einsum("ik,jl,kld->ijd", bu, bv, corner)
    )
    # Sides: f[0] bottom (v = 0), f[1] top, g[0] left (u = 0), g[1] right.
    poles[:, 0], poles[:, -1] = f[0], f[1]
    poles[0, :], poles[-1, :] = g[0], g[1]
    poles[0, 0], poles[-1, 0] = coons.corners[0, 0], coons.corners[1, 0]
    poles[0, -1], poles[-1, -1] = coons.corners[0, 1], coons.corners[1, 1]
    return BSplineSurface(poles, knots_u, knots_v, 3, 3)


# --------------------------------------------------------------------------- deformation
def _uniform_knots(spans: int, degree: int) -> NDArray[np.float64]:
    inner = np.linspace(0.0, 1.0, spans + 1)
    return np.concatenate([np.zeros(degree), inner, np.ones(degree)])


def _gauss_samples(spans: int, degree: int) -> NDArray[np.float64]:
    """``degree + 1`` Gauss-Legendre nodes per span: least squares on them is the L2
    projection with the spline Gram matrix integrated exactly."""
    x, _ = np.polynomial.legendre.leggauss(degree + 1)
    edges = np.linspace(0.0, 1.0, spans + 1)
    return (edges[:-1, None] + 0.5 * (x[None, :] + 1.0) * np.diff(edges)[:, None]).reshape(-1)


def _fit_factors(
    count: int, kind: str, spans: int, degree: int, fixed: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Spline coefficients (n, count) of the 1-D factors ``f_1..f_count`` with the first and
    last ``fixed`` coefficients zero, by least squares; and the knot vector."""
    knots = _uniform_knots(spans, degree)
    n = knots.size - degree - 1
    t = _gauss_samples(spans, degree)
    design = basis_matrix(knots, degree, t)[:, fixed : n - fixed]
    coef = np.zeros((n, count))
    target = sine_basis(t, count, kind)  # type: ignore[arg-type]
    coef[fixed : n - fixed] = np.linalg.lstsq(design, target, rcond=None)[0]
    return coef, knots


def _frequency(count: int, kind: str) -> int:
    """Half-waves of the highest factor over [0, 1]: what sets the spans needed."""
    return {"c0": count, "c1": 2 * count, "c1full": count + 1}[kind]


def _approximate(
    deformation: Deformation, su: int, sv: int, degree: int, fixed: int,
    tolerance: float = np.inf,
) -> tuple[BSplineSurface, float]:
    """Fit on ``su x sv`` uniform spans; return the surface and its max error on a check grid
    8 points per span (and at least 400 points) in each direction.

    The error is first taken on every 4th row and column of that grid: where it already
    exceeds ``tolerance`` that lower bound is returned (a fit that fails does so there, at a
    16th of the cost; the doubling search fails a few times before it passes)."""
    kind = deformation.kind
    cu, ku = _fit_factors(deformation.m, kind, su, degree, fixed)
    cv, kv = _fit_factors(deformation.n, kind, sv, degree, fixed)
    a = deformation.coefficients  # (M, N, D)
    # Separable data w = sum a_mn f_m(u) g_n(v): the tensor least-squares fit is the product
    # of the 1-D fits of the factors (pinv of a Kronecker product).
    poles = np.einsum("im,mnd,jn->ijd", cu, a, cv, optimize=True)
    surface = BSplineSurface(poles, ku, kv, degree, degree)
    tu = np.linspace(0.0, 1.0, max(8 * su, 400) + 1)
    tv = np.linspace(0.0, 1.0, max(8 * sv, 400) + 1)
    # Error = spline - w, both separable: (B cu) a (B cv)^T - F a G^T on the grid.
    du = basis_matrix(ku, degree, tu) @ cu, sine_basis(tu, deformation.m, kind)
    dv = basis_matrix(kv, degree, tv) @ cv, sine_basis(tv, deformation.n, kind)
    coarse = _grid_error(a, *(f[::4] for f in du), *(f[::4] for f in dv))
    if coarse > tolerance:
        return surface, coarse
    return surface, _grid_error(a, *du, *dv)


def _grid_error(a: NDArray[np.float64], eu: NDArray[np.float64], fu: NDArray[np.float64],
                ev: NDArray[np.float64], fv: NDArray[np.float64]) -> float:
    """Max over the grid of ``|eu a ev^T - fu a fv^T|`` (factor values on the grid rows
    and columns, coefficients ``a`` (M, N, D))."""
    err = np.einsum("am,mnd,bn->abd", eu, a, ev, optimize=True) - np.einsum(
        "am,mnd,bn->abd", fu, a, fv, optimize=True
    )
    return float(np.sqrt((err * err).sum(axis=-1)).max())


def deformation_to_bspline(
    deformation: Deformation,
    tolerance: float,
    *,
    degree: int = 3,
    max_spans: int = 1024,
) -> BSplineSurface:
    """B-spline approximation of a sine (Eq. 5.17) or sine-squared (Eq. 5.21) deformation.

    Uniform knots in each direction, least squares on Gauss points, with the outer pole row
    on all four sides fixed to zero for ``kind="c0"`` (the surface is exactly 0.0 on the
    boundary) and the two outer rows for ``"c1"`` / ``"c1full"`` (value and cross-boundary
    derivative exactly zero). The spans start at about the number of half-waves of the
    highest term (``M`` in u, ``N`` in v), double until the max error on a dense check grid
    is within ``tolerance``, then a bisection between the last two levels keeps the fewest
    spans that pass.

    Parameters
    ----------
    deformation : Deformation
    tolerance : float
        Max distance ``|B(u, v) - w(u, v)|`` allowed, in the units of the points.
    degree : int
        Degree in both directions (>= 2 for C1: the second pole row must not touch the edge).
    max_spans : int
        Largest number of spans per direction tried.

    Returns
    -------
    BSplineSurface

    Raises
    ------
    FitError
        If ``max_spans`` spans do not reach the tolerance.
    """
    if not tolerance > 0:
        raise InputError(f"tolerance must be > 0, got {tolerance}")
    fixed = 1 if deformation.kind == "c0" else 2
    if degree < fixed:
        raise InputError(f"degree must be >= {fixed} for kind {deformation.kind!r}, got {degree}")
    fu = _frequency(deformation.m, deformation.kind)
    fv = _frequency(deformation.n, deformation.kind)
    # Scale s: spans = ceil(s * frequency), at least enough for one free pole.
    low_spans = max(2 * fixed + 1 - degree, 1)

    def spans(s: float) -> tuple[int, int]:
        return max(math.ceil(s * fu), low_spans), max(math.ceil(s * fv), low_spans)

    scale, prev = 1.0, 0.5
    while True:
        su, sv = spans(scale)
        if max(su, sv) > max_spans:
            raise FitError(
                f"tolerance {tolerance:.3g} not reached with {max_spans} spans per direction; "
                "loosen the tolerance, raise max_spans or the degree"
            )
        best, err = _approximate(deformation, su, sv, degree, fixed, tolerance)
        if err <= tolerance:
            break
        prev, scale = scale, 2.0 * scale
    # Bisection on the scale between the last failing and the first passing level: doubling
    # can overshoot the spans needed by up to 2x per direction.
    lo, hi = prev, scale
    if hi > 1.0:
        for _ in range(4):
            mid = 0.5 * (lo + hi)
            if spans(mid) == spans(hi) or spans(mid) == spans(lo):
                break
            trial, err = _approximate(deformation, *spans(mid), degree, fixed, tolerance)
            if err <= tolerance:
                best, hi = trial, mid
            else:
                lo = mid
    return best


# --------------------------------------------------------------------------- sums
def add_surfaces(a: BSplineSurface, b: BSplineSurface) -> BSplineSurface:
    """Exact sum ``a + b`` as one B-spline surface.

    Both are raised to the larger degree in each direction, then refined to the merged knot
    vectors (union of the knots, larger multiplicity), where their poles add.
    A row of zero poles stays exactly zero under both operations, so adding a deformation
    whose outer rows are zero leaves the other surface's boundary rows bitwise unchanged.
    """
    for name in ("knots_u", "knots_v"):
        ka, kb = getattr(a, name), getattr(b, name)
        if ka[0] != kb[0] or ka[-1] != kb[-1]:
            raise InputError(f"the surfaces have different parameter domains ({name})")
    if a.poles.shape[2] != b.poles.shape[2]:
        raise InputError("the surfaces have different dimensions")
    p, q = max(a.degree_u, b.degree_u), max(a.degree_v, b.degree_v)
    a, b = a.degree_elevated(p, q), b.degree_elevated(p, q)
    ku, kv = merged_knots(a.knots_u, b.knots_u), merged_knots(a.knots_v, b.knots_v)
    a = a.with_knots_inserted(missing_knots(a.knots_u, ku), missing_knots(a.knots_v, kv))
    b = b.with_knots_inserted(missing_knots(b.knots_u, ku), missing_knots(b.knots_v, kv))
    return BSplineSurface(a.poles + b.poles, ku, kv, p, q)


def patch_to_bspline(
    base: CoonsPatch,
    deformation: Deformation,
    tolerance: float,
    *,
    degree: int = 3,
    knot_tolerance: float | None = None,
) -> BSplineSurface:
    """One B-spline surface for ``base + deformation`` (Eq. 5.20).

    1. The exact Coons surface (:func:`coons_to_bspline`, triple knots at the side breaks)
       plus the deformation approximated to ``tolerance`` (:func:`deformation_to_bspline`).
    2. The knots the geometry does not need are removed
       (:func:`~pde2cad.bspline.reduce.reduce_surface` within ``knot_tolerance``, by default
       1e-9 of the pole bounding box): a patch over C1 side chains comes out with double
       knots, C1 as a kernel reads it, so it can be offset, shelled and thickened.
    """
    surface = add_surfaces(
        coons_to_bspline(base), deformation_to_bspline(deformation, tolerance, degree=degree)
    )
    return reduce_surface(surface, knot_tolerance)
