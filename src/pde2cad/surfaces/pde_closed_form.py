"""Closed-form solutions of a fourth-order PDE as surface patches (thesis Chapter 4).

Separating variables in ``a1 X_uuuu + a2 X_vvvv = 0`` (Eq. 4.1) gives, per parametric
direction, one of two families of four functions:

* ``"hyp"`` (Eq. 4.11 / 4.14):   ``e^{qt}, e^{-qt}, cos(qt), sin(qt)``
* ``"damped"`` (Eq. 4.12 / 4.15): ``e^{qt}cos(qt), e^{qt}sin(qt), e^{-qt}cos(qt), e^{-qt}sin(qt)``

Their products are the four solutions X1..X4 (Eqs. 4.16-4.19); the 16 products of X4 are the
basis ``f_j`` of Eq. 4.20 and the patch is ``X(u, v) = sum_j d_j f_j(u, v)`` (Eq. 4.21). The
64-term extension (Eqs. 4.26-4.28) adds a second family with its own constants ``q5`` (u) and
``q6`` (v) on each side; here it is offered for every solution, X4 being the thesis's case.

Every basis function is the real or imaginary part of ``exp(lambda t)`` for a complex
``lambda``, so its k-th derivative is the same part of ``lambda^k exp(lambda t)``: values and
analytic derivatives of any order come from one formula.

Why not the normal equations of Eq. 4.24: with the thesis's ``q2 = q4 = 0.1`` the damped
functions are almost the cubic polynomials (``f'''' = -4 q^4 f`` tends to ``f'''' = 0``), so the
collocation matrix of the 16 nose points (Table 4.1) has a condition number near 7e9, and
forming ``A^T A`` squares it to ~5e19, beyond double precision. The fit here scales the
columns and solves the least-squares problem through an SVD, which works with ``A`` itself.

The fitted patch is ``o + X(u, v)`` with ``o`` the centroid of the points (a constant also
solves Eq. 4.1): the ``f_j`` contain constants only approximately, and fitting relative to the
centroid keeps the result independent of where the part sits (``center=False`` fits the pure
Eq. 4.21). Defaults of the extra constants: ``q5 = q6 = 2`` (see :data:`DEFAULT_Q`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import FitError, InputError

SOLUTIONS: tuple[str, ...] = ("X1", "X2", "X3", "X4")
"""The four closed-form solutions (Eqs. 4.16-4.19); X4 is the thesis's choice."""

TERMS: tuple[int, ...] = (16, 64)
"""Supported numbers of vector unknowns d_j: Eq. 4.21 (16) and Eq. 4.28 (64)."""

DEFAULT_Q: dict[str, float] = {
    "q1": 0.1,
    "q2": 0.1,
    "q3": 0.1,
    "q4": 0.1,
    "q5": 2.0,
    "q6": 2.0,
}
"""Default constants of the exponents.

``q2 = q4 = 0.1`` is the thesis's choice (Section 4.3.3); ``q1`` and ``q3`` (X1..X3) are not
given there and take the same value. ``q5``/``q6`` of Eq. 4.26 are never given. At 0.1 the
extra family would repeat the first one (the 64-term fit is then no better than the 16-term
one), and values up to 0.5 keep it within 1.3e-4 of the cubics. At 2 the functions
``e^{+-2t}cos(2t)``, ``e^{+-2t}sin(2t)`` are 3.4 % (relative, max norm) away from every cubic on
[0, 1] (0.1: ~2e-7), so the 8 functions per direction span a genuinely richer space. Measured
(max error against the true surface on a 41x41 grid, fits to 15x15..30x30 grids and 300
random samples of 9 test surfaces: sphere and torus parts, half cylinder, sine waves,
Gaussian bump, saddle, bowl, tanh ridge): the 64-term fit with ``q5 = q6 = 2`` is 2.6
(grids) and 1.9 (random) decades better than the 16-term fit on average; 0.5..2 are within
0.2 decades of each other on average, and 2 has the (joint) smallest worst case (e.g. on a
20x20 grid of a sphere part 7.6e-7 against 4.3e-3 for 16 terms, half cylinder 1.5e-5 against
3.6e-2). Above 2.5 the average degrades again (3: 0.3 decades worse than 2).
"""

Q_BOUNDS: tuple[float, float] = (0.05, 8.0)
"""Search interval of each q when ``fit_q=True``. Below 0.05 the family is a cubic to within
round-off (nothing left to tune); above 8 the exponentials span e^{+-8} over [0, 1] and the
oscillation period (2 pi / q < 0.8) is shorter than typical point spacings of a patch."""

_FAMILIES: dict[str, tuple[str, str, str, str]] = {
    # solution: (u family, u constant, v family, v constant), Eqs. 4.16-4.19
    "X1": ("hyp", "q1", "hyp", "q3"),
    "X2": ("hyp", "q1", "damped", "q4"),
    "X3": ("damped", "q2", "hyp", "q3"),
    "X4": ("damped", "q2", "damped", "q4"),
}

# Relative singular-value cut-off of the solve (LAPACK's default for gelsd is eps * max(N, T)).
_RCOND_FACTOR = float(np.finfo(float).eps)

# Newton iterations for the closest-point projection; quadratic convergence from the
# parametric start needs far fewer, the cap only bounds the cost on pathological points.
_NEWTON_ITERATIONS = 30
_BACKTRACK_STEPS = 8


def _family_exponents(kind: str, q: float) -> tuple[NDArray[np.complex128], NDArray[np.bool_]]:
    """Complex exponents ``lambda`` and real/imaginary flags of one four-function family.

    Each function is ``Re exp(lambda t)`` (flag False) or ``Im exp(lambda t)`` (flag True), in
    the order of the constants c1..c4 of Eq. 4.11 (``"hyp"``) or Eq. 4.12 (``"damped"``).
    """
    if kind == "hyp":
        lam = np.array([q, -q, 1j * q, 1j * q], dtype=complex)
        imag = np.array([False, False, False, True])
    else:
        lam = np.array([q * (1 + 1j), q * (1 + 1j), q * (-1 + 1j), q * (-1 + 1j)], dtype=complex)
        imag = np.array([False, True, False, True])
    return lam, imag


def _factor_values(
    t: NDArray[np.float64], lam: NDArray[np.complex128], imag: NDArray[np.bool_], order: int
) -> NDArray[np.float64]:
    """``order``-th derivative of the 1D factor functions at ``t``: shape ``t.shape + (n,)``."""
    z = (lam**order) * np.exp(t[..., None] * lam)
    return np.where(imag, z.imag, z.real)


@dataclass(frozen=True, eq=False)  # arrays inside: no elementwise ==
class PDEBasis:
    """The basis ``f_j(u, v)`` of one closed-form solution (Eqs. 4.20 and 4.27).

    ``f_j(u, v) = F_a(u) G_b(v)`` with ``F`` (u factor, Eq. 4.11/4.12) and ``G`` (v factor,
    Eq. 4.14/4.15). Column ``j`` of :meth:`values` is the product with internal index
    ``order[j] = a * len(G) + b``: for X4 with 16 terms ``j`` follows Eq. 4.20 exactly; otherwise
    ``j = a * len(G) + b`` (row-major over the factors of Eq. 4.26, the order of Eq. 4.27).

    Attributes
    ----------
    solution : str
        One of :data:`SOLUTIONS`.
    terms : int
        16 or 64.
    q : dict of str to float
        The constants in use, e.g. ``{"q2": 0.1, "q4": 0.1}`` for X4 with 16 terms.
    """

    solution: str
    terms: int
    q: dict[str, float]
    _lam_u: NDArray[np.complex128] = field(repr=False)
    _imag_u: NDArray[np.bool_] = field(repr=False)
    _lam_v: NDArray[np.complex128] = field(repr=False)
    _imag_v: NDArray[np.bool_] = field(repr=False)
    order: NDArray[np.intp] = field(repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        """Number of u and v factor functions (4, 4) or (8, 8)."""
        return len(self._lam_u), len(self._lam_v)

    def factors(
        self, u: NDArray[np.float64], v: NDArray[np.float64], du: int = 0, dv: int = 0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``du``-th derivative of the u factors and ``dv``-th of the v factors."""
        return (
            _factor_values(u, self._lam_u, self._imag_u, du),
            _factor_values(v, self._lam_v, self._imag_v, dv),
        )

    def values(
        self, u: ArrayLike, v: ArrayLike, du: int = 0, dv: int = 0
    ) -> NDArray[np.float64]:
        """``d^(du+dv) f_j / du^du dv^dv`` at broadcast ``(u, v)``: shape ``(..., terms)``."""
        uu, vv = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        fu, gv = self.factors(uu, vv, du, dv)
        prod = (fu[..., :, None] * gv[..., None, :]).reshape(uu.shape + (self.terms,))
        return prod[..., self.order]


def _resolve_q(solution: str, terms: int, q: Mapping[str, float] | None) -> dict[str, float]:
    """The constants a solution uses, defaults overridden by ``q`` (validated)."""
    fam = _FAMILIES[solution]
    names = [fam[1], fam[3]] + (["q5", "q6"] if terms == 64 else [])
    given = dict(q or {})
    unknown = sorted(set(given) - set(DEFAULT_Q))
    if unknown:
        raise InputError(
            f"unknown q constant(s) {unknown}; use keys among {sorted(DEFAULT_Q)}"
        )
    resolved: dict[str, float] = {}
    for name in names:
        value = float(given.get(name, DEFAULT_Q[name]))
        if not np.isfinite(value) or value <= 0.0:
            raise InputError(f"{name} = {value} is not a positive finite number; pass e.g. 0.1")
        resolved[name] = value
    return resolved


def pde_basis(
    solution: str = "X4", terms: int = 16, q: Mapping[str, float] | None = None
) -> PDEBasis:
    """Build the basis of a closed-form solution (Eqs. 4.16-4.20, 4.26-4.27).

    Parameters
    ----------
    solution : {"X1", "X2", "X3", "X4"}
        X1 = hyp(u; q1) hyp(v; q3) (Eq. 4.16), X2 = hyp(u; q1) damped(v; q4) (Eq. 4.17),
        X3 = damped(u; q2) hyp(v; q3) (Eq. 4.18), X4 = damped(u; q2) damped(v; q4) (Eq. 4.19).
        Eq. 4.17 as printed writes its second factor in ``u``; by the derivation (Eq. 4.11
        times Eq. 4.15) it is in ``v``.
    terms : {16, 64}
        64 adds the family with ``q5`` to the u factor and the one with ``q6`` to the v factor
        (Eq. 4.26 for X4, the same construction for X1..X3).
    q : mapping, optional
        Overrides of :data:`DEFAULT_Q`; keys a solution does not use are ignored.

    Returns
    -------
    PDEBasis
    """
    solution, terms = _check_solution_terms(solution, terms)
    qs = _resolve_q(solution, terms, q)
    kind_u, name_u, kind_v, name_v = _FAMILIES[solution]
    lam_u, imag_u = _family_exponents(kind_u, qs[name_u])
    lam_v, imag_v = _family_exponents(kind_v, qs[name_v])
    if terms == 64:
        # Eq. 4.26: the second family keeps the form of the first with its own constant.
        lu2, iu2 = _family_exponents(kind_u, qs["q5"])
        lv2, iv2 = _family_exponents(kind_v, qs["q6"])
        lam_u, imag_u = np.concatenate([lam_u, lu2]), np.concatenate([imag_u, iu2])
        lam_v, imag_v = np.concatenate([lam_v, lv2]), np.concatenate([imag_v, iv2])
    nv = len(lam_v)
    if solution == "X4" and terms == 16:
        # Eq. 4.20 orders by (sign of u exponent, sign of v exponent, u trig, v trig); the
        # factor index is a = 2 * sign_u + trig_u, b = 2 * sign_v + trig_v.
        j = np.arange(16)
        su, sv, tu, tv = j // 8, (j // 4) % 2, (j // 2) % 2, j % 2
        order = (2 * su + tu) * nv + (2 * sv + tv)
    else:
        order = np.arange(len(lam_u) * nv)
    return PDEBasis(solution, terms, qs, lam_u, imag_u, lam_v, imag_v, order.astype(np.intp))


def basis_functions(
    u: ArrayLike,
    v: ArrayLike,
    solution: str = "X4",
    terms: int = 16,
    q: Mapping[str, float] | None = None,
) -> NDArray[np.float64]:
    """Values ``f_j(u, v)`` of Eq. 4.20 (16 terms) or Eq. 4.27 (64 terms).

    Parameters
    ----------
    u, v : array_like
        Broadcastable parameter arrays.
    solution, terms, q
        As in :func:`pde_basis`.

    Returns
    -------
    (..., terms) float
    """
    return pde_basis(solution, terms, q).values(u, v)


@dataclass(frozen=True)
class _Solve:
    coefficients: NDArray[np.float64]
    residual_ss: float
    rank: int
    condition: float


def _solve(
    design: NDArray[np.float64], points: NDArray[np.float64], ridge: float
) -> _Solve:
    """Least squares ``min |A D - P|^2 + ridge |S D|^2`` by SVD of the column-scaled ``A``.

    ``S`` is the diagonal of column norms, so ``ridge`` penalizes the coefficients of the
    unit-norm columns and is free of the data's units. Scaling first makes the singular values
    measure near-dependence of the functions rather than their sizes. Singular values below
    ``eps * max(N, T) * s_max`` are dropped, which makes an underdetermined or rank-deficient
    system return the minimum-norm solution (in the scaled coefficients).
    """
    norms = np.linalg.norm(design, axis=0)
    # A column that vanishes at every sample (e.g. sin(q u) with all u = 0) carries no
    # information; scale 1 keeps it at a zero coefficient.
    norms = np.where(norms > 0.0, norms, 1.0)
    scaled = design / norms
    try:
        U, s, Vt = np.linalg.svd(scaled, full_matrices=False)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - LAPACK non-convergence
        raise FitError(
            f"the SVD of the {design.shape[0]}x{design.shape[1]} design matrix did not "
            "converge; check the parameters for duplicates or pass ridge > 0"
        ) from exc
    cut = _RCOND_FACTOR * max(design.shape) * (s[0] if s.size else 0.0)
    keep = s > cut
    filt = np.zeros_like(s)
    filt[keep] = s[keep] / (s[keep] ** 2 + ridge)
    coef_scaled = Vt.T @ (filt[:, None] * (U.T @ points))
    coefficients = coef_scaled / norms[:, None]
    if not np.all(np.isfinite(coefficients)):
        raise FitError("the fit produced non-finite coefficients; pass ridge > 0")
    resid = scaled @ coef_scaled - points
    rank = int(np.count_nonzero(keep))
    cond = float(s[0] / s[rank - 1]) if rank else float("inf")
    return _Solve(coefficients, float(np.sum(resid * resid)), rank, cond)


@dataclass(frozen=True, eq=False)  # arrays inside: no elementwise ==
class PDESurface:
    """A fitted closed-form PDE patch ``X(u, v) = o + sum_j d_j f_j(u, v)`` (Eq. 4.21 / 4.28).

    The constant ``o`` (:attr:`origin`: the centroid of the fitted points, or 0 with
    ``center=False``) is not in the thesis. A constant solves Eq. 4.1 exactly, so ``X`` is
    still a closed-form solution; the ``f_j`` only approximate constants (to ~2e-7 with
    q = 0.1), so without ``o`` a part placed far from the coordinate origin fits worse
    (16-term fit of a 3 x 1 plane 500 units away: max error 2e-4 instead of 2.2e-7).

    Attributes
    ----------
    basis : PDEBasis
        The functions ``f_j``.
    coefficients : (terms, 3) float
        The vector unknowns ``d_j``, in the order of :class:`PDEBasis`.
    origin : (3,) float
        The constant offset ``o`` (zeros for the pure Eq. 4.21).
    params : (N, 2) float
        The (u, v) of the fitted points.
    errors : dict of str to float
        ``mean``/``max``: parametric distances ``|P_i - X(u_i, v_i)|`` (Eq. 4.25);
        ``mean_orthogonal``/``max_orthogonal``: distance from each point to the closest point
        of the patch over [0, 1]^2; ``rms``: root mean square of the parametric distances.
    underdetermined : bool
        True when there are fewer points than terms: the coefficients are then the
        minimum-norm solution (of the column-scaled system), and the patch interpolates the
        points when their (u, v) are distinct.
    rank : int
        Numerical rank of the column-scaled design matrix.
    condition : float
        Its condition number (over the kept singular values).
    ridge : float
        The Tikhonov weight used.
    q_fitted : bool
        True when the q constants came from the nonlinear search of ``fit_q=True``.
    """

    basis: PDEBasis
    coefficients: NDArray[np.float64]
    origin: NDArray[np.float64]
    params: NDArray[np.float64]
    errors: dict[str, float]
    underdetermined: bool
    rank: int
    condition: float
    ridge: float
    q_fitted: bool

    @property
    def solution(self) -> str:
        """Which closed-form solution, "X1".."X4"."""
        return self.basis.solution

    @property
    def terms(self) -> int:
        """Number of vector unknowns, 16 or 64."""
        return self.basis.terms

    @property
    def q(self) -> dict[str, float]:
        """The q constants in use."""
        return dict(self.basis.q)

    def _grid(self) -> NDArray[np.float64]:
        """Coefficients as the (nu, nv, 3) array of products F_a(u) G_b(v)."""
        nu, nv = self.basis.shape
        flat = np.empty((nu * nv, 3))
        flat[self.basis.order] = self.coefficients
        return flat.reshape(nu, nv, 3)

    def _partial(
        self, u: NDArray[np.float64], v: NDArray[np.float64], du: int, dv: int
    ) -> NDArray[np.float64]:
        fu, gv = self.basis.factors(u, v, du, dv)
        out = np.einsum("...a,...b,abk->...k", fu, gv, self._grid())
        return out + self.origin if du == dv == 0 else out

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Points ``origin + X(u, v)`` (Eq. 4.21) at broadcast ``u``, ``v``: ``(..., 3)``."""
        uu, vv = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        return self._partial(uu, vv, 0, 0)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Analytic first derivatives ``(X_u, X_v)``, each ``(..., 3)``."""
        uu, vv = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        return self._partial(uu, vv, 1, 0), self._partial(uu, vv, 0, 1)

    def second_derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Analytic second derivatives ``(X_uu, X_uv, X_vv)``, each ``(..., 3)``."""
        uu, vv = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        return (
            self._partial(uu, vv, 2, 0),
            self._partial(uu, vv, 1, 1),
            self._partial(uu, vv, 0, 2),
        )

    def closest_points(
        self, points: ArrayLike, start: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Closest points of the patch over [0, 1]^2 by a vectorized, safeguarded Newton method.

        Minimizes ``|X(u, v) - P|^2 / 2`` from ``start``. The Newton matrix uses the analytic
        second derivatives; where it is not positive definite the Gauss-Newton matrix
        ``J^T J`` takes over. Steps are clamped to the unit square and halved until the distance
        decreases, so the result is never farther than the start.

        Parameters
        ----------
        points : (M, 3) float
        start : (M, 2) float
            Initial (u, v), clipped to [0, 1]^2.

        Returns
        -------
        params : (M, 2) float
        distances : (M,) float
        """
        P = np.asarray(points, dtype=float)
        uv = np.clip(np.asarray(start, dtype=float), 0.0, 1.0).copy()
        r = self.evaluate(uv[:, 0], uv[:, 1]) - P
        d2 = np.einsum("ij,ij->i", r, r)
        active = np.ones(len(P), dtype=bool)
        for _ in range(_NEWTON_ITERATIONS):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            u, v, ri = uv[idx, 0], uv[idx, 1], r[idx]
            Su, Sv = self.derivatives(u, v)
            Suu, Suv, Svv = self.second_derivatives(u, v)
            gu = np.einsum("ij,ij->i", Su, ri)
            gv = np.einsum("ij,ij->i", Sv, ri)
            a = np.einsum("ij,ij->i", Su, Su)
            b = np.einsum("ij,ij->i", Su, Sv)
            c = np.einsum("ij,ij->i", Sv, Sv)
            ha = a + np.einsum("ij,ij->i", Suu, ri)
            hb = b + np.einsum("ij,ij->i", Suv, ri)
            hc = c + np.einsum("ij,ij->i", Svv, ri)
            det = ha * hc - hb * hb
            newton_ok = (ha > 0.0) & (det > 1e-14 * (ha * hc + 1e-300))
            ha = np.where(newton_ok, ha, a)
            hb = np.where(newton_ok, hb, b)
            hc = np.where(newton_ok, hc, c)
            # A tiny Levenberg term keeps the Gauss-Newton fallback solvable at degenerate
            # points of the patch (X_u parallel to X_v).
            damp = 1e-12 * (a + c) + 1e-300
            ha, hc = ha + damp, hc + damp
            det = ha * hc - hb * hb
            step_u = -(hc * gu - hb * gv) / det
            step_v = -(ha * gv - hb * gu) / det
            step = np.stack([step_u, step_v], axis=1)
            base = uv[idx]
            accepted = np.zeros(idx.size, dtype=bool)
            for _ in range(_BACKTRACK_STEPS):
                todo = ~accepted
                if not np.any(todo):
                    break
                trial = np.clip(base[todo] + step[todo], 0.0, 1.0)
                rt = self.evaluate(trial[:, 0], trial[:, 1]) - P[idx[todo]]
                dt = np.einsum("ij,ij->i", rt, rt)
                better = dt < d2[idx[todo]]
                sel = idx[todo][better]
                uv[sel], r[sel], d2[sel] = trial[better], rt[better], dt[better]
                accepted[np.flatnonzero(todo)[better]] = True
                step[todo] *= 0.5
            moved = np.abs(uv[idx] - base).max(axis=1)
            # Stop a point once no step lowers its distance or the step is at round-off.
            active[idx] = accepted & (moved > 1e-13)
        return uv, np.sqrt(d2)


def _check_solution_terms(solution: str, terms: int) -> tuple[str, int]:
    if not isinstance(solution, str) or solution.upper() not in SOLUTIONS:
        raise InputError(f"solution {solution!r} is unknown; use one of {', '.join(SOLUTIONS)}")
    if isinstance(terms, bool) or terms not in TERMS:
        raise InputError(f"terms = {terms!r} is not supported; use 16 (Eq. 4.21) or 64 (Eq. 4.28)")
    return solution.upper(), int(terms)


def _check_points(points: ArrayLike) -> NDArray[np.float64]:
    try:
        P = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"points cannot be read as a float array ({exc}); pass an (N, 3) array"
        ) from exc
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"points has shape {P.shape}; pass an (N, 3) array of x, y, z")
    bad = int(np.count_nonzero(~np.all(np.isfinite(P), axis=1)))
    if bad:
        raise InputError(f"points has {bad} row(s) with NaN or inf; remove or repair them")
    if len(P) < 3:
        raise InputError(f"{len(P)} point(s) given; a surface patch needs at least 3")
    extent = float(np.ptp(P, axis=0).max())
    scale = float(np.abs(P).max())
    if extent <= 1e-12 * max(scale, 1.0):
        raise InputError("all points coincide; a surface needs points spread in 2D")
    return P


def _check_params(params: ArrayLike, n: int) -> NDArray[np.float64]:
    try:
        uv = np.asarray(params, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"params cannot be read as a float array ({exc}); pass an (N, 2) array"
        ) from exc
    if uv.shape != (n, 2):
        raise InputError(f"params has shape {uv.shape}; pass ({n}, 2), one (u, v) per point")
    bad = int(np.count_nonzero(~np.all(np.isfinite(uv), axis=1)))
    if bad:
        raise InputError(f"params has {bad} row(s) with NaN or inf; pass finite (u, v)")
    tol = 1e-9
    if uv.min() < -tol or uv.max() > 1.0 + tol:
        raise InputError(
            f"params span [{uv.min():.6g}, {uv.max():.6g}]; the patch lives on [0, 1]^2, "
            "rescale them (e.g. per-axis min/max) or pass params=None"
        )
    return np.clip(uv, 0.0, 1.0)


def plane_parameterization(points: ArrayLike) -> NDArray[np.float64]:
    """Parameters by projection onto the PCA plane (thesis Section 4.3.2, Fig. 4.10).

    The points are centred and projected onto the plane of their two main principal axes;
    those axes are the PCA axes of the projected points too, so the projection is already
    aligned with u and v (Fig. 4.10(c)). Each coordinate is then scaled by its min/max into
    [0, 1]. Axis signs are fixed (largest component positive) so the result is reproducible.

    Parameters
    ----------
    points : (N, 3) float

    Returns
    -------
    (N, 2) float in [0, 1]^2
    """
    P = _check_points(points)
    centred = P - P.mean(axis=0)
    _, s, Vt = np.linalg.svd(centred, full_matrices=False)
    if s[1] <= 1e-9 * s[0]:
        raise InputError("points are collinear; a surface needs a 2D spread")
    axes = Vt[:2] * np.sign(Vt[:2][np.arange(2), np.argmax(np.abs(Vt[:2]), axis=1)])[:, None]
    uv = centred @ axes.T
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return (uv - lo) / (hi - lo)


def _with_errors(surface: PDESurface, points: NDArray[np.float64]) -> PDESurface:
    """``surface`` with its parametric (Eq. 4.25) and orthogonal errors filled in."""
    params = surface.params
    resid = np.linalg.norm(surface.evaluate(params[:, 0], params[:, 1]) - points, axis=1)
    _, ortho = surface.closest_points(points, params)
    errors = {
        "mean": float(resid.mean()),
        "max": float(resid.max()),
        "rms": float(np.sqrt(np.mean(resid**2))),
        "mean_orthogonal": float(ortho.mean()),
        "max_orthogonal": float(ortho.max()),
    }
    return replace(surface, errors=errors)


def _search_q(
    points: NDArray[np.float64],
    params: NDArray[np.float64],
    solution: str,
    terms: int,
    q: dict[str, float],
    ridge: float,
) -> dict[str, float]:
    """Bounded search of the q constants minimizing the least-squares error (Eq. 4.22).

    With 16 terms the two constants in use are searched; with 64 terms the base pair stays
    at its value (it supplies the near-cubic part) and ``(q5, q6)`` are searched. A coarse
    log-spaced grid picks the start, bounded Nelder-Mead (derivative-free, because the
    rank cut-off makes the objective only piecewise smooth) refines it in log q.
    """
    from scipy.optimize import minimize

    names = ["q5", "q6"] if terms == 64 else list(q)[:2]
    lo, hi = np.log(Q_BOUNDS[0]), np.log(Q_BOUNDS[1])
    # Relative objective: independent of the units and placement of the points.
    denom = float(np.sum((points - points.mean(axis=0)) ** 2)) or 1.0

    def objective(logq: NDArray[np.float64]) -> float:
        trial = dict(q)
        trial.update({n: float(np.exp(x)) for n, x in zip(names, np.clip(logq, lo, hi))})
        design = pde_basis(solution, terms, trial).values(params[:, 0], params[:, 1])
        return _solve(design, points, ridge).residual_ss / denom

    grid = np.linspace(lo, hi, 5)
    starts = [np.log([q[n] for n in names])] + [np.array([a, b]) for a in grid for b in grid]
    values = [objective(s) for s in starts]
    x0 = starts[int(np.argmin(values))]
    res = minimize(
        objective,
        x0,
        method="Nelder-Mead",
        bounds=[(lo, hi)] * len(names),
        options={"xatol": 1e-2, "fatol": 1e-14, "maxiter": 100},
    )
    best = res.x if res.fun <= min(values) else x0
    out = dict(q)
    out.update({n: float(np.exp(x)) for n, x in zip(names, best)})
    return out


def fit_pde_surface(
    points: ArrayLike,
    params: ArrayLike | None = None,
    *,
    solution: str = "X4",
    terms: int = 16,
    q: Mapping[str, float] | None = None,
    fit_q: bool = False,
    ridge: float = 0.0,
    center: bool = True,
) -> PDESurface:
    """Fit a closed-form PDE patch to points (thesis Sections 4.3.2-4.3.3, 4.4).

    Minimizes Eq. 4.22, ``sum_n |X(u_n, v_n) - P_n|^2``, over the vector unknowns ``d_j``,
    by an SVD of the column-scaled design matrix instead of the normal equations of Eq. 4.24
    (they square a condition number of ~1e10, see the module docstring).

    Parameters
    ----------
    points : (N, 3) float
        Finite points, N >= 3, not all coincident.
    params : (N, 2) float in [0, 1]^2, optional
        Their (u, v). Default: :func:`plane_parameterization` (PCA plane, Fig. 4.10), which
        needs the points not to be collinear.
    solution : {"X1", "X2", "X3", "X4"}
        Closed-form solution (Eqs. 4.16-4.19); X4 (basis Eq. 4.20) is the thesis's choice.
    terms : {16, 64}
        16 unknowns (Eq. 4.21) or the extended 64 (Eq. 4.28).
    q : mapping, optional
        Overrides of :data:`DEFAULT_Q` (``q2 = q4 = 0.1`` as the thesis, ``q5 = q6 = 2``).
    fit_q : bool
        Search the q constants in :data:`Q_BOUNDS` for the least error (the nonlinear option the
        thesis mentions after Eq. 4.24 and leaves out). Skipped when ``N <= terms``: the patch
        then interpolates for any q and there is nothing to minimize.
    ridge : float
        Tikhonov weight ``lambda >= 0``: minimizes ``|A d - P|^2 + lambda |S d|^2`` with ``S`` the
        column norms of the design matrix ``A``. 0 (default) is plain least squares; 1e-10 to
        1e-6 damps oscillation between sparse or unevenly spread points at a small cost in
        accuracy.
    center : bool
        Fit the points relative to their centroid, kept as :attr:`PDESurface.origin`, so the
        result does not depend on where the points sit in space (default). False fits the pure
        Eq. 4.21 / 4.28, as the thesis does; only then is a surface sampled from the model
        itself reproduced exactly.

    Returns
    -------
    PDESurface

    Raises
    ------
    InputError
        Bad points, params, solution, terms, q or ridge.
    FitError
        The linear algebra failed.
    """
    P = _check_points(points)
    solution, terms = _check_solution_terms(solution, terms)
    if not np.isfinite(ridge) or ridge < 0.0:
        raise InputError(f"ridge = {ridge} must be a finite number >= 0; pass 0 for none")
    qs = _resolve_q(solution, terms, q)
    uv = plane_parameterization(P) if params is None else _check_params(params, len(P))
    origin = P.mean(axis=0) if center else np.zeros(3)
    centred = P - origin
    q_fitted = False
    if fit_q and len(P) > terms:
        qs = _search_q(centred, uv, solution, terms, qs, float(ridge))
        q_fitted = True
    basis = pde_basis(solution, terms, qs)
    sol = _solve(basis.values(uv[:, 0], uv[:, 1]), centred, float(ridge))
    surface = PDESurface(
        basis=basis,
        coefficients=sol.coefficients,
        origin=origin,
        params=uv,
        errors={},
        underdetermined=len(P) < terms,
        rank=sol.rank,
        condition=sol.condition,
        ridge=float(ridge),
        q_fitted=q_fitted,
    )
    return _with_errors(surface, P)
