"""Plain-array B-spline curves and surfaces: the exchange form for STEP / IGES export.

Both classes hold clamped (open) knot vectors in full, the form the NURBS book uses;
:meth:`BSplineCurve.multiplicities` and :meth:`BSplineSurface.multiplicities` give the
"distinct knots + multiplicities" form that OpenCASCADE (``Geom_BSplineSurface``) wants.

Evaluation is the local Cox-de Boor recursion (NURBS book A2.2), vectorized over the
parameters, with derivatives by the derivative recursion of the basis. It is self-contained
rather than ``scipy.interpolate.BSpline.design_matrix`` so it runs on scipy 1.10, which has no
derivative design matrices, and so surfaces never form a dense (points, poles) matrix.

Knot insertion is Boehm's algorithm, written with elementwise array operations only: the
same poles give bitwise the same result whether they are a curve's (n, D) array or a
surface's (n, m, D) net. That is what keeps the edge of a converted surface identical to the
curve converted on its own, so adjacent faces share their edges exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import InputError

Side = Literal["u0", "u1", "v0", "v1"]
#: The four edges of a surface: ``u0`` is ``S(0, v)``, ``u1`` is ``S(1, v)``, ``v0`` is
#: ``S(u, 0)``, ``v1`` is ``S(u, 1)`` (bottom, right, top, left of a Coons patch are
#: ``v0, u1, v1, u0``).
SIDES = ("u0", "u1", "v0", "v1")


# --------------------------------------------------------------------------- knot helpers
def check_knots(knots: ArrayLike, degree: int, n_poles: int, name: str = "knots") -> None:
    """Raise InputError unless ``knots`` is a clamped vector of ``n_poles + degree + 1``
    non-decreasing values with interior multiplicities <= ``degree``."""
    k = np.asarray(knots, dtype=float)
    if degree < 1:
        raise InputError(f"degree must be >= 1, got {degree}")
    if k.ndim != 1 or k.size != n_poles + degree + 1:
        raise InputError(
            f"{name} must have n_poles + degree + 1 = {n_poles + degree + 1} values, "
            f"got shape {k.shape}"
        )
    if n_poles < degree + 1:
        raise InputError(f"degree {degree} needs at least {degree + 1} poles, got {n_poles}")
    if not np.all(np.isfinite(k)) or np.any(np.diff(k) < 0):
        raise InputError(f"{name} must be finite and non-decreasing")
    if np.any(k[: degree + 1] != k[0]) or np.any(k[-degree - 1 :] != k[-1]) or k[0] == k[-1]:
        raise InputError(
            f"{name} must be clamped: the first and the last {degree + 1} values equal, "
            f"and a non-empty domain; got {k.tolist()}"
        )
    _, mult = unique_knots(k[degree + 1 : -degree - 1])
    if mult.size and mult.max() > degree:
        raise InputError(f"{name} has an interior knot of multiplicity > degree {degree}")


def unique_knots(knots: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Distinct values (k,) and their multiplicities (k,) of a full knot vector (exact
    equality: knots are compared as stored)."""
    values, mults = np.unique(np.asarray(knots, dtype=float), return_counts=True)
    return values, mults.astype(np.int64)


def full_knots(values: ArrayLike, mults: ArrayLike) -> NDArray[np.float64]:
    """Inverse of :func:`unique_knots`: the full vector ``repeat(values, mults)``."""
    return np.repeat(np.asarray(values, dtype=float), np.asarray(mults, dtype=np.int64))


def merged_knots(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Smallest knot vector containing both ``a`` and ``b``: union of the values, each with
    the larger of its two multiplicities."""
    va, ma = unique_knots(a)
    vb, mb = unique_knots(b)
    values = np.union1d(va, vb)
    mult = np.zeros(values.size, dtype=np.int64)
    mult[np.searchsorted(values, va)] = ma
    mult[np.searchsorted(values, vb)] = np.maximum(mult[np.searchsorted(values, vb)], mb)
    return full_knots(values, mult)


def missing_knots(have: ArrayLike, want: ArrayLike) -> NDArray[np.float64]:
    """Knots to insert into ``have`` to reach ``want`` (``want`` must contain ``have``),
    each value repeated by the missing multiplicity."""
    vh, mh = unique_knots(have)
    vw, mw = unique_knots(want)
    extra = mw.copy()
    pos = np.searchsorted(vw, vh)
    if np.any(pos >= vw.size) or np.any(vw[np.minimum(pos, vw.size - 1)] != vh):
        raise InputError("the target knot vector does not contain the knots already present")
    extra[pos] -= mh
    if np.any(extra < 0):
        raise InputError("the target knot vector has a knot with lower multiplicity")
    return full_knots(vw, extra)


def greville(knots: NDArray[np.float64], degree: int) -> NDArray[np.float64]:
    """Greville abscissae (n,): ``(t_{i+1} + ... + t_{i+p}) / p``, the parameters whose
    linear function ``sum xi_i N_i(t) = t`` the B-spline basis reproduces."""
    n = knots.size - degree - 1
    idx = np.arange(n)[:, None] + np.arange(1, degree + 1)[None, :]
    return knots[idx].mean(axis=1)


# --------------------------------------------------------------------------- basis
def find_span(
    knots: NDArray[np.float64], degree: int, t: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Index ``s`` of the non-empty knot span ``[t_s, t_{s+1})`` holding each ``t`` (n,).

    The end of the domain belongs to the last span, and parameters outside the domain to the
    first or last span, so they extrapolate its polynomial.
    """
    n = knots.size - degree - 1
    return np.clip(np.searchsorted(knots, t, side="right") - 1, degree, n - 1).astype(np.int64)


def basis_local(
    knots: NDArray[np.float64], degree: int, t: ArrayLike, order: int = 0
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The ``degree + 1`` basis functions (or their ``order``-th derivatives) that are
    nonzero at each parameter.

    Parameters
    ----------
    knots : (n + degree + 1,) float
    degree : int
    t : array_like (n_t,)
    order : int
        Derivative order, >= 0 (above ``degree`` the result is zero).

    Returns
    -------
    span : (n_t,) int
        Basis function ``span - degree + l`` has the value ``values[:, l]``.
    values : (n_t, degree + 1) float
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    span = find_span(knots, degree, t)
    low = max(degree - order, 0)
    # Degree-`low` basis by the triangular recursion (A2.2): entry r is N_{span-low+r, low}.
    vals = np.ones((t.size, 1))
    for j in range(1, low + 1):
        # left[r] = t - t_{s+1-j+r}, right[r] = t_{s+1+r} - t for r = 0..j-1.
        left = t[:, None] - knots[span[:, None] + 1 - np.arange(j, 0, -1)[None, :]]
        right = knots[span[:, None] + 1 + np.arange(j)[None, :]] - t[:, None]
        # Denominator t_{s+1+r} - t_{s+1-j+r} > 0 as the span [t_s, t_{s+1}) is not empty.
        temp = vals / (right + left)
        new = np.zeros((t.size, j + 1))
        new[:, :j] = right * temp
        new[:, 1:] += left * temp
        vals = new
    # Raise to `degree` by the derivative recursion: each step differentiates once,
    # N'_{i,k} = k (N_{i,k-1} / (t_{i+k} - t_i) - N_{i+1,k-1} / (t_{i+k+1} - t_{i+1})).
    for k in range(low + 1, degree + 1):
        i = span[:, None] - k + np.arange(k + 1)[None, :]  # functions s-k .. s
        padded = np.zeros((t.size, k + 2))
        padded[:, 1:-1] = vals  # padded[:, r] is N_{s-k+r, k-1}, zero outside the support
        d1 = knots[i + k] - knots[i]
        d2 = knots[i + k + 1] - knots[i + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(d1 > 0, padded[:, :-1] / d1, 0.0)
            b = np.where(d2 > 0, padded[:, 1:] / d2, 0.0)
        vals = k * (a - b)
    if order > degree:
        vals = np.zeros((t.size, degree + 1))
    return span, vals


def basis_matrix(
    knots: NDArray[np.float64], degree: int, t: ArrayLike, order: int = 0
) -> NDArray[np.float64]:
    """Dense collocation matrix (n_t, n) of the basis (or its ``order``-th derivative)."""
    span, vals = basis_local(knots, degree, t, order)
    n = knots.size - degree - 1
    out = np.zeros((span.size, n))
    cols = span[:, None] - degree + np.arange(degree + 1)[None, :]
    np.put_along_axis(out, cols, vals, axis=1)
    return out


# --------------------------------------------------------------------------- operators
def insert_knot(
    poles: NDArray[np.float64], knots: NDArray[np.float64], degree: int, x: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Boehm insertion of one knot ``x`` along axis 0 of ``poles`` (n, ...): the same curve
    (or surface, column by column) with ``n + 1`` poles and ``x`` added to ``knots``.

    Only elementwise operations: the result for a pole row does not depend on which other
    rows are processed with it.
    """
    a, b = knots[degree], knots[-degree - 1]
    if not a < x < b:
        raise InputError(f"a knot can only be inserted inside the domain ({a}, {b}), got {x}")
    if np.count_nonzero(knots == x) >= degree:
        raise InputError(f"knot {x} already has multiplicity {degree} (the degree)")
    k = int(np.searchsorted(knots, x, side="right") - 1)
    n = poles.shape[0]
    i = np.arange(k - degree + 1, k + 1)
    alpha = (x - knots[i]) / (knots[i + degree] - knots[i])
    alpha = alpha.reshape((-1,) + (1,) * (poles.ndim - 1))
    new = np.empty((n + 1, *poles.shape[1:]))
    new[: k - degree + 1] = poles[: k - degree + 1]
    new[k - degree + 1 : k + 1] = alpha * poles[i] + (1.0 - alpha) * poles[i - 1]
    new[k + 1 :] = poles[k:]
    return new, np.insert(knots, k + 1, x)


def insert_knots(
    poles: NDArray[np.float64], knots: NDArray[np.float64], degree: int, xs: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Insert every value of ``xs`` (repeat a value to raise its multiplicity), axis 0."""
    for x in np.sort(np.asarray(xs, dtype=float).reshape(-1)):
        poles, knots = insert_knot(poles, knots, degree, float(x))
    return poles, knots


def elevation_matrix(
    knots: NDArray[np.float64], degree: int, new_degree: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear map raising the degree of a B-spline from ``degree`` to ``new_degree``.

    Every distinct knot gains ``new_degree - degree`` in multiplicity, which keeps the
    continuity at each knot. The new poles are found by collocation at the Greville
    abscissae of the new basis (a square system, nonsingular by Schoenberg-Whitney); the
    elevated spline is the same polynomial on each span, so this is exact to rounding.

    Returns
    -------
    matrix : (n_new, n) float
        ``new_poles = matrix @ poles``; its first and last rows are exactly unit vectors (the
        end poles of a clamped spline are its end points and stay bitwise unchanged).
    new_knots : (n_new + new_degree + 1,) float
    """
    if new_degree < degree:
        raise InputError(f"cannot lower the degree from {degree} to {new_degree}")
    values, mults = unique_knots(knots)
    new_knots = full_knots(values, mults + (new_degree - degree))
    n = knots.size - degree - 1
    if new_degree == degree:
        return np.eye(n), knots.copy()
    xi = greville(new_knots, new_degree)
    matrix: NDArray[np.float64] = np.asarray(
        np.linalg.solve(basis_matrix(new_knots, new_degree, xi), basis_matrix(knots, degree, xi)),
        dtype=np.float64,
    )
    matrix[0], matrix[-1] = 0.0, 0.0
    matrix[0, 0], matrix[-1, -1] = 1.0, 1.0
    return matrix, new_knots


def _apply(
    matrix: NDArray[np.float64], poles: NDArray[np.float64], axis: int
) -> NDArray[np.float64]:
    """``matrix`` applied along ``axis`` of ``poles``."""
    moved = np.moveaxis(poles, axis, 0)
    out = np.tensordot(matrix, moved, axes=(1, 0))
    return np.moveaxis(out, 0, axis)


def _freeze(a: NDArray[np.float64]) -> NDArray[np.float64]:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------- classes
@dataclass(frozen=True, eq=False)
class BSplineCurve:
    """Clamped polynomial B-spline curve.

    Attributes
    ----------
    poles : (n, D) float
    knots : (n + degree + 1,) float
        Full clamped knot vector (first and last values repeated ``degree + 1`` times).
    degree : int
    """

    poles: NDArray[np.float64]
    knots: NDArray[np.float64]
    degree: int

    def __post_init__(self) -> None:
        poles = _freeze(self.poles)
        if poles.ndim != 2:
            raise InputError(f"poles must have shape (n, D), got {poles.shape}")
        if not np.all(np.isfinite(poles)):
            raise InputError("poles contain NaN or inf")
        check_knots(self.knots, int(self.degree), poles.shape[0])
        object.__setattr__(self, "poles", poles)
        object.__setattr__(self, "knots", _freeze(self.knots))
        object.__setattr__(self, "degree", int(self.degree))

    @property
    def domain(self) -> tuple[float, float]:
        """Parameter interval ``(t_p, t_n)``."""
        return float(self.knots[self.degree]), float(self.knots[-self.degree - 1])

    def multiplicities(self) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """OpenCASCADE form: distinct knots (k,) and multiplicities (k,)."""
        return unique_knots(self.knots)

    def derivative(self, t: ArrayLike, order: int = 1) -> NDArray[np.float64]:
        """``order``-th derivative at ``t`` (any shape): ``t.shape + (D,)``.

        At a knot, the span to its right is used (the left one at the domain end).
        """
        t = np.asarray(t, dtype=float)
        span, vals = basis_local(self.knots, self.degree, t, order)
        idx = span[:, None] - self.degree + np.arange(self.degree + 1)[None, :]
        out = np.einsum("nl,nld->nd", vals, self.poles[idx])
        return out.reshape((*t.shape, self.poles.shape[1]))

    def evaluate(self, t: ArrayLike) -> NDArray[np.float64]:
        """Points ``C(t)``: ``t.shape + (D,)``."""
        return self.derivative(t, 0)

    def with_knots_inserted(self, knots: ArrayLike) -> BSplineCurve:
        """The same curve with the knots ``knots`` added (Boehm; exact)."""
        poles, new = insert_knots(self.poles, self.knots, self.degree, knots)
        return BSplineCurve(poles, new, self.degree)

    def degree_elevated(self, degree: int) -> BSplineCurve:
        """The same curve at degree ``degree`` (>= the current one), same continuity."""
        matrix, new = elevation_matrix(self.knots, self.degree, degree)
        return BSplineCurve(matrix @ self.poles, new, degree)


@dataclass(frozen=True, eq=False)
class BSplineSurface:
    """Clamped polynomial tensor-product B-spline surface.

    Attributes
    ----------
    poles : (nu, nv, D) float
        ``S(u, v) = sum_ij N_i(u) M_j(v) poles[i, j]``.
    knots_u : (nu + degree_u + 1,) float
    knots_v : (nv + degree_v + 1,) float
        Full clamped knot vectors.
    degree_u, degree_v : int
    """

    poles: NDArray[np.float64]
    knots_u: NDArray[np.float64]
    knots_v: NDArray[np.float64]
    degree_u: int
    degree_v: int

    def __post_init__(self) -> None:
        poles = _freeze(self.poles)
        if poles.ndim != 3:
            raise InputError(f"poles must have shape (nu, nv, D), got {poles.shape}")
        if not np.all(np.isfinite(poles)):
            raise InputError("poles contain NaN or inf")
        check_knots(self.knots_u, int(self.degree_u), poles.shape[0], "knots_u")
        check_knots(self.knots_v, int(self.degree_v), poles.shape[1], "knots_v")
        object.__setattr__(self, "poles", poles)
        object.__setattr__(self, "knots_u", _freeze(self.knots_u))
        object.__setattr__(self, "knots_v", _freeze(self.knots_v))
        object.__setattr__(self, "degree_u", int(self.degree_u))
        object.__setattr__(self, "degree_v", int(self.degree_v))

    @property
    def pole_count(self) -> tuple[int, int]:
        """``(nu, nv)``."""
        return int(self.poles.shape[0]), int(self.poles.shape[1])

    def multiplicities(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.int64]]:
        """OpenCASCADE form ``(u_knots, u_mults, v_knots, v_mults)``."""
        return (*unique_knots(self.knots_u), *unique_knots(self.knots_v))

    def partial(
        self, u: ArrayLike, v: ArrayLike, du: int = 0, dv: int = 0
    ) -> NDArray[np.float64]:
        """``d^(du+dv) S / du^du dv^dv`` at ``u``, ``v`` (broadcast): ``shape + (D,)``.

        Only the ``(p + 1)(q + 1)`` poles that act on each point are gathered.
        """
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        shape = u.shape
        p, q = self.degree_u, self.degree_v
        su, bu = basis_local(self.knots_u, p, u.reshape(-1), du)
        sv, bv = basis_local(self.knots_v, q, v.reshape(-1), dv)
        iu = su[:, None] - p + np.arange(p + 1)[None, :]
        iv = sv[:, None] - q + np.arange(q + 1)[None, :]
        local = self.poles[iu[:, :, None], iv[:, None, :]]  # (n, p+1, q+1, D)
        out = np.einsum("na,nb,nabd->nd", bu, bv, local)
        return out.reshape((*shape, self.poles.shape[2]))

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Points ``S(u, v)``; ``u``, ``v`` broadcast, result ``shape + (D,)``."""
        return self.partial(u, v)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(S_u, S_v)``, each ``shape + (D,)``."""
        return self.partial(u, v, 1, 0), self.partial(u, v, 0, 1)

    def evaluate_grid(
        self, u: ArrayLike, v: ArrayLike, du: int = 0, dv: int = 0
    ) -> NDArray[np.float64]:
        """``S`` (or a partial) on the grid ``u (a,) x v (b,)``: shape (a, b, D), by two
        dense basis products (cheap for grids, where :meth:`partial` would gather)."""
        bu = basis_matrix(self.knots_u, self.degree_u, u, du)
        bv = basis_matrix(self.knots_v, self.degree_v, v, dv)
        return np.einsum("ai,ijd,bj->abd", bu, self.poles, bv, optimize=True)

    def boundary_curve(self, side: Side) -> BSplineCurve:
        """The edge ``side`` as a curve: its row of poles, which is exact for a clamped
        surface. ``u0``: ``S(u_min, v)``, ``u1``: ``S(u_max, v)`` (parameter v);
        ``v0``: ``S(u, v_min)``, ``v1``: ``S(u, v_max)`` (parameter u)."""
        if side == "u0":
            return BSplineCurve(self.poles[0], self.knots_v, self.degree_v)
        if side == "u1":
            return BSplineCurve(self.poles[-1], self.knots_v, self.degree_v)
        if side == "v0":
            return BSplineCurve(self.poles[:, 0], self.knots_u, self.degree_u)
        if side == "v1":
            return BSplineCurve(self.poles[:, -1], self.knots_u, self.degree_u)
        raise InputError(f"side must be one of {SIDES}, got {side!r}")

    def with_knots_inserted(
        self, knots_u: ArrayLike = (), knots_v: ArrayLike = ()
    ) -> BSplineSurface:
        """The same surface with knots added in u and in v (Boehm; exact)."""
        poles, ku = insert_knots(self.poles, self.knots_u, self.degree_u, knots_u)
        moved, kv = insert_knots(
            np.swapaxes(poles, 0, 1), self.knots_v, self.degree_v, knots_v
        )
        return BSplineSurface(np.swapaxes(moved, 0, 1), ku, kv, self.degree_u, self.degree_v)

    def degree_elevated(self, degree_u: int, degree_v: int) -> BSplineSurface:
        """The same surface at degrees ``(degree_u, degree_v)`` (>= the current ones)."""
        poles = self.poles
        ku, kv = self.knots_u, self.knots_v
        if degree_u != self.degree_u:
            mu, ku = elevation_matrix(self.knots_u, self.degree_u, degree_u)
            poles = _apply(mu, poles, 0)
        if degree_v != self.degree_v:
            mv, kv = elevation_matrix(self.knots_v, self.degree_v, degree_v)
            poles = _apply(mv, poles, 1)
        return BSplineSurface(poles, ku, kv, degree_u, degree_v)
