"""Coons patches: the base surfaces of Chapter 5 (bilinear Eq. 5.1, bicubic Eqs. 5.2-5.7).

Convention (both patches)
-------------------------
The four sides are given in the order ``bottom, right, top, left`` and each runs in the
direction of its own parameter, not around the loop::

    S(u, 0) = bottom(u)     from S(0, 0) to S(1, 0)
    S(1, v) = right(v)      from S(1, 0) to S(1, 1)
    S(u, 1) = top(u)        from S(0, 1) to S(1, 1)
    S(0, v) = left(v)       from S(0, 0) to S(0, 1)

          top(u) ->
    S(0,1) -------- S(1,1)
      ^               ^
    left(v)        right(v)
      |               |
    S(0,0) -------- S(1,0)
         bottom(u) ->

A boundary extractor that returns a closed loop of four head-to-tail curves uses
:meth:`BilinearCoons.from_loop`, which reverses ``top`` and ``left``.

Both patches are Boolean sums ``S = L_u + L_v - T`` (Eq. 5.2): a loft between ``bottom`` and
``top`` blended in ``v``, a loft between ``left`` and ``right`` blended in ``u``, minus the
tensor-product interpolant of the corner data. The bilinear patch blends with ``1 - t, t``
(Eq. 5.1), the bicubic one with the cubic Hermite functions of the matrix H (Eq. 5.4). Every
partial derivative is the same sum with differentiated blends and curves, so evaluation,
derivatives and second derivatives share one code path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import FitError, InputError
from pde2cad.surfaces.boundary import (
    JOIN_TOLERANCE,
    PiecewiseBezier,
    as_curve,
    bbox_diagonal,
)

CurveLike = PiecewiseBezier | ArrayLike

# The (du, dv) orders of a jet: value, first, then second derivatives.
_JET_ORDERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))


def _linear_blend(t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
    """Blends ``(1 - t, t)`` of Eq. 5.1 and their derivatives: ``t.shape + (2,)``."""
    if order == 0:
        return np.stack([1.0 - t, t], axis=-1)
    if order == 1:
        return np.broadcast_to(np.array([-1.0, 1.0]), (*t.shape, 2))
    if order in (2, 3):
        return np.zeros((*t.shape, 2))
    raise InputError(f"derivative order must be 0..3, got {order}")


def _hermite_blend(t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
    """Cubic Hermite functions, the rows of H (Eq. 5.4) applied to ``(t^3, t^2, t, 1)``:
    ``H0 = 2t^3 - 3t^2 + 1, H1 = -2t^3 + 3t^2, H2 = t^3 - 2t^2 + t, H3 = t^3 - t^2``,
    so H0, H1 carry the values at t = 0, 1 and H2, H3 the derivatives there."""
    t2 = t * t
    if order == 0:
        h0 = 2.0 * t2 * t - 3.0 * t2 + 1.0
        h2 = t2 * t - 2.0 * t2 + t
        h3 = t2 * t - t2
        return np.stack([h0, 1.0 - h0, h2, h3], axis=-1)
    if order == 1:
        d0 = 6.0 * t2 - 6.0 * t
        return np.stack([d0, -d0, 3.0 * t2 - 4.0 * t + 1.0, 3.0 * t2 - 2.0 * t], axis=-1)
    if order == 2:
        e0 = 12.0 * t - 6.0
        return np.stack([e0, -e0, 6.0 * t - 4.0, 6.0 * t - 2.0], axis=-1)
    if order == 3:
        return np.broadcast_to(np.array([12.0, -12.0, 6.0, 6.0]), (*t.shape, 4))
    raise InputError(f"derivative order must be 0..3, got {order}")


def _check_corners(
    bottom: PiecewiseBezier, right: PiecewiseBezier, top: PiecewiseBezier, left: PiecewiseBezier
) -> NDArray[np.float64]:
    """Corner points ``(2, 2, D)`` indexed ``[i, j] = S(i, j)``; InputError if sides miss."""
    dims = {c.dim for c in (bottom, right, top, left)}
    if len(dims) != 1:
        raise InputError(f"the four boundary curves must share one dimension, got {sorted(dims)}")
    tol = JOIN_TOLERANCE * bbox_diagonal(
        np.concatenate([c.ctrl for c in (bottom, right, top, left)])
    )
    pairs = {
        (0, 0): ("bottom(0)", bottom.start, "left(0)", left.start),
        (1, 0): ("bottom(1)", bottom.end, "right(0)", right.start),
        (0, 1): ("top(0)", top.start, "left(1)", left.end),
        (1, 1): ("top(1)", top.end, "right(1)", right.end),
    }
    corners = np.empty((2, 2, bottom.dim))
    for (i, j), (name_a, a, name_b, b) in pairs.items():
        gap = float(np.linalg.norm(a - b))
        if gap > tol:
            raise InputError(
                f"corner S({i},{j}) does not close: {name_a} = {a.tolist()} but {name_b} = "
                f"{b.tolist()} (gap {gap:.3g}). Sides are bottom(u), right(v), top(u), left(v), "
                "each running with its own parameter (bottom/top left to right, left/right bottom "
                "to top); reverse a side with .reversed() or pass a head-to-tail loop to from_loop"
            )
        corners[i, j] = 0.5 * (a + b)
    return corners


def _broadcast_params(
    u: ArrayLike, v: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    np.broadcast_shapes(u.shape, v.shape)  # fail early with numpy's own message
    return u, v


def _horner(
    poly: list[NDArray[np.float64]], t: NDArray[np.float64], order: int, out: NDArray[np.float64]
) -> None:
    """``out <- d^order/dt^order sum_k poly[k] t^k`` for a cubic, in place (no temporaries
    the size of ``out`` beyond one)."""
    if order == 0:
        np.multiply(poly[3], t, out=out)
        out += poly[2]
        out *= t
        out += poly[1]
        out *= t
        out += poly[0]
    elif order == 1:
        np.multiply(poly[3], 3.0 * t, out=out)
        out += 2.0 * poly[2]
        out *= t
        out += poly[1]
    else:
        np.multiply(poly[3], 6.0 * t, out=out)
        out += 2.0 * poly[2]


def _cell_jet(
    coef: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Jet of the bicubic ``sum_ij coef[i, j] x^i y^j`` at ``x, y`` (n,): (6, D, n), for one
    cell ``coef`` (4, 4, D) or every point's own cell, (4, 4, D, n).

    Horner in y then in x, coordinate-major: with the n points on the fast axis every array
    operation runs over long contiguous rows (several times faster than (n, 3) arrays).
    """
    dim = coef.shape[2]
    c = coef[..., None] if coef.ndim == 3 else coef  # (4, 4, D, 1 or n) against (n,)
    q = np.empty((3, 4, dim, x.size))  # q[b, i] = d^b/dy^b sum_j c[i, j] y^j
    rows = [c[:, j] for j in range(4)]  # (4, D, 1): all four i at once
    for b in range(3):
        _horner(rows, y, b, q[b])
    out = np.empty((len(_JET_ORDERS), dim, x.size))
    for k, (a, b) in enumerate(_JET_ORDERS):
        _horner(list(q[b]), x, a, out[k])
    return out


def _ruled_cell_jet(
    coef: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """:func:`_cell_jet` of cells without ``x^i y^j`` terms for ``i, j >= 2``, which is
    every cell of a bilinear Coons patch (Eq. 5.1: each term is linear in u or in v).

    ``coef`` (12, D, 1 or n) holds ``c_0j, c_1j`` for j = 0..3 (rows ``2j``, ``2j + 1``),
    then ``c_20, c_30, c_21, c_31``: 12 of the 16 coefficients, and the rows ``i = 2, 3``
    are lines in y, so the scheme does about a third less work. The values are those of
    the full scheme bit for bit (the vanishing terms contribute exact zeros there).
    """
    dim = coef.shape[1]
    q = np.empty((3, 4, dim, x.size))  # q[b, i] = d^b/dy^b sum_j c[i, j] y^j
    rows = [coef[2 * j : 2 * j + 2] for j in range(4)]  # (2, D, .): i = 0 and 1
    for b in range(3):
        _horner(rows, y, b, q[b, :2])
    np.multiply(coef[10:12], y, out=q[0, 2:])
    q[0, 2:] += coef[8:10]
    q[1, 2:] = coef[10:12]
    out = np.empty((len(_JET_ORDERS), dim, x.size))
    for k, (a, b) in enumerate(_JET_ORDERS[:-1]):
        _horner(list(q[b]), x, a, out[k])
    # S_vv: only i = 0, 1 have a second y-derivative.
    np.multiply(q[2, 1], x, out=out[-1])
    out[-1] += q[2, 0]
    return out


#: Where the ruled coefficients sit in a cell's (4, 4) block (see _ruled_cell_jet).
_RULED_TERMS = (
    [(i, j) for j in range(4) for i in (0, 1)] + [(2, 0), (3, 0), (2, 1), (3, 1)]
)


#: Largest block of points a jet evaluates at once (bounds its per-point coefficients).
_JET_BLOCK = 65_536
#: Scattered evaluations of at least this many points use the polynomial cells.
_CELL_MIN = 4096


def _horner_values(
    coef: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``sum_ij coef[i, j] x^i y^j`` for one bicubic cell ``coef`` (4, 4, D) at ``x, y``
    (n,): (D, n), coordinate-major so the points run along contiguous rows."""
    c = coef[..., None]  # (4, 4, D, 1) broadcasts against (n,)
    acc = np.empty((coef.shape[-1], x.size))
    row = np.empty_like(acc)
    for i in range(3, -1, -1):
        # Horner in y for row i, then in x, in place: no temporaries of n values.
        np.multiply(c[i, 3], y, out=row)
        row += c[i, 2]
        row *= y
        row += c[i, 1]
        row *= y
        row += c[i, 0]
        if i == 3:
            acc[:] = row
        else:
            acc *= x
            acc += row
    return acc


def cell_values(
    cells: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    u: NDArray[np.float64],
    v: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Values of a patch given as polynomial cells (see :meth:`_BooleanSumPatch.power_cells`)
    at ``u, v`` (n,): (n, D).

    The points are sorted by cell once, so every cell is one contiguous Horner scheme.
    """
    ub, vb, coef = cells
    nu, nv, dim = coef.shape[0], coef.shape[1], coef.shape[-1]
    u = np.asarray(u, dtype=float).reshape(-1)
    v = np.asarray(v, dtype=float).reshape(-1)
    iu = np.clip(np.searchsorted(ub, u, side="right") - 1, 0, nu - 1)
    iv = np.clip(np.searchsorted(vb, v, side="right") - 1, 0, nv - 1)
    x, y = u - ub[iu], v - vb[iv]
    if nu * nv == 1:
        return _horner_values(coef[0, 0], x, y).T
    cell = iu * nv + iv
    # A stable sort of small integers is a radix sort: O(n).
    order = np.argsort(cell.astype(np.int16 if nu * nv < 2**15 else np.int64), kind="stable")
    starts = np.searchsorted(cell[order], np.arange(nu * nv + 1))
    xs, ys = x[order], y[order]
    res = np.empty((dim, u.size))
    for c in np.flatnonzero(np.diff(starts)):
        part = slice(starts[c], starts[c + 1])
        res[:, part] = _horner_values(coef[c // nv, c % nv], xs[part], ys[part])
    out = np.empty((u.size, dim))
    out[order] = res.T
    return out


def _cell_breaks(curves: tuple[PiecewiseBezier, ...]) -> NDArray[np.float64]:
    """The union of the curves' breaks, near-duplicates inside (0, 1) as one: a reversed
    side's ``1 - 0.8 = 0.19999999999999996`` and ``0.2`` would make a cell of width 3e-17,
    and every extra cell costs each evaluation a sort. A cluster keeps its largest value,
    so the cell starting there takes the pieces valid from it on (the sliver before it is
    the previous cell's, extrapolated by rounding)."""
    b = np.unique(np.concatenate([c.breaks for c in curves]))
    last = np.r_[np.diff(b) > _BREAK_MERGE, True]
    return b[last | (b < _BREAK_MERGE) | (b > 1.0 - _BREAK_MERGE)]


#: Breaks closer than this are one in the polynomial cells (see _cell_breaks).
_BREAK_MERGE = 1e-12


class _BooleanSumPatch:
    """``S = sum_k b_k(v) F_k(u) + sum_k b_k(u) G_k(v) - sum_ij b_i(u) b_j(v) C_ij`` (Eq. 5.2).

    Subclasses set ``_u_curves`` (the F_k: functions of u blended in v), ``_v_curves`` (the
    G_k), ``_corner_data`` ``C`` (k, k, D) and ``_blend``.
    """

    _u_curves: tuple[PiecewiseBezier, ...]
    _v_curves: tuple[PiecewiseBezier, ...]
    _corner_data: NDArray[np.float64]

    @staticmethod
    def _blend(t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        raise NotImplementedError

    @property
    def dim(self) -> int:
        """Dimension ``D`` of the points."""
        return int(self._corner_data.shape[-1])

    def _partials(
        self, u: ArrayLike, v: ArrayLike, orders: tuple[tuple[int, int], ...]
    ) -> list[NDArray[np.float64]]:
        u, v = _broadcast_params(u, v)
        top_u = max(a for a, _ in orders)
        top_v = max(b for _, b in orders)
        # Curves are evaluated on u's and v's own shapes, so a grid u[:, None], v[None, :]
        # costs one curve evaluation per row and column, not per grid point.
        fu = np.stack([c.jet(u, top_u) for c in self._u_curves], axis=1)  # (r, k, *u, D)
        gv = np.stack([c.jet(v, top_v) for c in self._v_curves], axis=1)  # (r, k, *v, D)
        k = self._corner_data.shape[0]
        flat_corner = self._corner_data.reshape(k, k * self.dim)
        out = []
        for a, b in orders:
            bu = self._blend(u, a)[..., None]  # (*u, k, 1)
            bv = self._blend(v, b)[..., None]
            # einsum, not @: a threaded BLAS costs more than this thin product itself.
            corner = np.einsum("...i,ik->...k", bu[..., 0], flat_corner).reshape(
                (*u.shape, k, self.dim)
            )
            # Blend index k is 2 or 4: summing it explicitly beats einsum on 1e6 points.
            total = bv[..., 0, :] * (fu[a][0] - corner[..., 0, :]) + bu[..., 0, :] * gv[b][0]
            for i in range(1, k):
                total += bv[..., i, :] * (fu[a][i] - corner[..., i, :]) + bu[..., i, :] * gv[b][i]
            out.append(total)
        return out

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Points ``S(u, v)``; ``u``, ``v`` broadcast, result ``shape + (D,)``.

        Many scattered points (``u`` and ``v`` both of at least ``_CELL_MIN`` values) are
        evaluated on :meth:`power_cells`, the same polynomial (equal to rounding) at a
        fraction of the cost; grids and small inputs by the Boolean sum itself.
        """
        u, v = _broadcast_params(u, v)
        if u.size >= _CELL_MIN and v.size >= _CELL_MIN:
            shape = np.broadcast_shapes(u.shape, v.shape)
            flat_u = np.broadcast_to(u, shape).reshape(-1)
            flat_v = np.broadcast_to(v, shape).reshape(-1)
            return cell_values(self.power_cells(), flat_u, flat_v).reshape((*shape, self.dim))
        return self._partials(u, v, ((0, 0),))[0]

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """First partial derivatives ``(S_u, S_v)``, each ``shape + (D,)``."""
        su, sv = self._partials(u, v, ((1, 0), (0, 1)))
        return su, sv

    def second_derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Second partial derivatives ``(S_uu, S_uv, S_vv)``, each ``shape + (D,)``.

        One-sided at the breaks of a boundary chain, which is only C0 there.
        """
        suu, suv, svv = self._partials(u, v, ((2, 0), (1, 1), (0, 2)))
        return suu, suv, svv

    def power_cells(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The patch as a grid of polynomial cells (exact).

        Every side, ribbon and blend is a cubic between breaks, so on each cell of the grid
        ``u_breaks x v_breaks`` (the unions of the breaks of the curves in u and in v) the
        Boolean sum is a bicubic polynomial: ``S(u0 + x, v0 + y) = sum_ij A[i, j] x^i y^j``.
        Its coefficients are the Taylor coefficients at the cell's lower corner. This is the
        form :meth:`jet` evaluates, and the exact polynomial data a B-spline export needs.

        Returns
        -------
        u_breaks : (Nu + 1,) float
        v_breaks : (Nv + 1,) float
        coefficients : (Nu, Nv, 4, 4, D) float
            ``coefficients[cu, cv, i, j]`` multiplies ``x^i y^j`` on cell ``(cu, cv)``.
        """
        cached = getattr(self, "_cells", None)
        if cached is not None:
            return cached
        ub, vb = _cell_breaks(self._u_curves), _cell_breaks(self._v_curves)
        orders = tuple((i, j) for i in range(4) for j in range(4))
        parts = self._partials(ub[:-1, None], vb[None, :-1], orders)
        fact = np.array([1.0, 1.0, 2.0, 6.0])
        coef = np.stack(parts, axis=2).reshape(ub.size - 1, vb.size - 1, 4, 4, self.dim)
        coef /= (fact[:, None] * fact[None, :])[..., None]
        cells = (ub, vb, coef)
        self._cells = cells
        return cells

    def jet(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """``(S, S_u, S_v, S_uu, S_uv, S_vv)`` in one pass (what a Newton projection needs).

        Evaluated on :meth:`power_cells`, the same polynomial as the Boolean sum (equal to
        rounding) at a fraction of the cost. The arrays returned are transposed views of
        coordinate-major (D, n) arrays, which is what the projection computes with.
        """
        u, v = _broadcast_params(u, v)
        shape = np.broadcast_shapes(u.shape, v.shape)
        u = np.broadcast_to(u, shape).reshape(-1)
        v = np.broadcast_to(v, shape).reshape(-1)
        if u.size <= _JET_BLOCK:
            out = self._flat_jet(u, v)
        else:
            # Blocks bound the per-point cell coefficients (12-16 D values a point).
            out = np.empty((len(_JET_ORDERS), self.dim, u.size))
            for start in range(0, u.size, _JET_BLOCK):
                part = slice(start, start + _JET_BLOCK)
                out[:, :, part] = self._flat_jet(u[part], v[part])
        return tuple(o.T.reshape((*shape, self.dim)) for o in out)

    def _flat_jet(self, u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`jet` at flat ``u, v`` (n,), coordinate-major: (6, D, n)."""
        ub, vb, coef = self.power_cells()
        nu, nv = coef.shape[:2]
        iu = np.clip(np.searchsorted(ub, u, side="right") - 1, 0, nu - 1)
        iv = np.clip(np.searchsorted(vb, v, side="right") - 1, 0, nv - 1)
        x, y = u - ub[iu], v - vb[iv]
        ruled = not coef[:, :, 2:, 2:].any()
        if ruled:
            terms = np.array(_RULED_TERMS)
            coef = coef[:, :, terms[:, 0], terms[:, 1]]  # (nu, nv, 12, D)
        if nu * nv == 1:
            mine = coef[0, 0][..., None]
        else:
            # Every point's own cell coefficients, gathered from the small table: one
            # Horner scheme over all points. (Sorting the points by cell and running one
            # scheme per cell cost 5-8x more: ~60 numpy calls per cell on short runs.)
            table = coef.reshape(nu * nv, -1).T  # (terms D, cells)
            mine = np.take(table, iu * nv + iv, axis=1).reshape(*coef.shape[2:], -1)
        return _ruled_cell_jet(mine, x, y) if ruled else _cell_jet(mine, x, y)


class BilinearCoons(_BooleanSumPatch):
    """Bilinearly blended Coons patch (Eq. 5.1).

    ``S(u,v) = (1-v) bottom(u) + v top(u) + (1-u) left(v) + u right(v)
    - [(1-u)(1-v) P00 + u(1-v) P10 + (1-u) v P01 + u v P11]``, with ``Pij = S(i, j)``.
    It interpolates the four sides exactly (positional continuity with any neighbour that uses
    the same curve for the shared side).

    Parameters
    ----------
    bottom, right, top, left : PiecewiseBezier or array
        Sides in the module's convention (see the module docstring); arrays are coerced with
        :func:`pde2cad.surfaces.boundary.as_curve`. A side may be a single point (3-sided
        patch, see :func:`three_sided`).

    Raises
    ------
    InputError
        If two sides that should meet at a corner miss by more than 1e-9 of the bounding box.
    """

    _blend = staticmethod(_linear_blend)

    def __init__(
        self, bottom: CurveLike, right: CurveLike, top: CurveLike, left: CurveLike
    ) -> None:
        self.bottom, self.right, self.top, self.left = (
            as_curve(c) for c in (bottom, right, top, left)
        )
        self.corners = _check_corners(self.bottom, self.right, self.top, self.left)
        self._u_curves = (self.bottom, self.top)
        self._v_curves = (self.left, self.right)
        self._corner_data = self.corners

    @classmethod
    def from_loop(cls, c0: CurveLike, c1: CurveLike, c2: CurveLike, c3: CurveLike) -> BilinearCoons:
        """Patch from a closed loop of four head-to-tail sides starting at ``S(0, 0)``:
        ``c0 = bottom``, ``c1 = right``, ``c2 = top`` reversed, ``c3 = left`` reversed."""
        return cls(c0, c1, as_curve(c2).reversed(), as_curve(c3).reversed())


def three_sided(c0: CurveLike, c1: CurveLike, c2: CurveLike) -> BilinearCoons:
    """3-sided bilinear Coons patch (Fig. 5.11) from a head-to-tail loop ``c0, c1, c2``.

    The top side collapses to the point where ``c1`` ends and ``c2`` starts:
    ``bottom = c0`` (S(0,0) -> S(1,0)), ``right = c1`` (S(1,0) -> apex),
    ``left = c2`` reversed (S(0,0) -> apex) and ``top(u) = apex``. The patch is singular at
    ``v = 1`` (``S_u = 0`` there); Eq. 5.1 needs no change.
    """
    c1 = as_curve(c1)
    return BilinearCoons(c0, c1, PiecewiseBezier.from_point(c1.end), as_curve(c2).reversed())


def apex_ribbon(
    left: CurveLike,
    right: CurveLike,
    twist_left: ArrayLike,
    twist_right: ArrayLike,
    normal: ArrayLike | None = None,
) -> PiecewiseBezier:
    """Cross-boundary derivative ``d_top(u) = S_v(u, 1)`` of a 3-sided bicubic Coons patch.

    The top side of the 3-sided patch (Fig. 5.11) is the apex, a point, so ``top'(u) = 0``
    and the corner data of Eqs. 5.6-5.7 at ``(0, 1)`` and ``(1, 1)`` read: ``S_u = 0`` (the
    left and right ribbons vanish at the apex), ``S_v(0, 1) = left'(1)``,
    ``S_v(1, 1) = right'(1)`` (the sides' derivatives pointing into the apex) and
    ``S_uv(i, 1)`` = the twists, which are also the slopes of ``d_left`` and ``d_right`` at
    the apex. The single cubic Hermite through these data,
    ``d_top = H0(u) left'(1) + H1(u) right'(1) + H2(u) twist_left + H3(u) twist_right``
    (Eq. 5.4's blends), satisfies all of them. Near the apex
    ``S(u, 1 - e) ~ apex - e d_top(u)`` and ``S_u ~ -e d_top'(u)``, so the limit normal is
    ``d_top x d_top'``: with the four vectors in one plane the apex has ONE tangent plane.
    (``d_top = (1 - u) left'(1) + u right'(1)`` is the case ``twist = right'(1) - left'(1)``.)

    Parameters
    ----------
    left, right : PiecewiseBezier or array
        The sides ``S(0, v)`` and ``S(1, v)``, both ending at the apex (module convention).
    twist_left, twist_right : (D,) float
        ``S_uv(0, 1)`` and ``S_uv(1, 1)``.
    normal : (D,) float, optional
        Normal of the apex's tangent plane: the twists are projected into that plane (the
        side derivatives are the edges' own and are kept).

    Returns
    -------
    PiecewiseBezier
        One cubic piece on [0, 1].
    """
    end = np.array([1.0])
    values = np.vstack([as_curve(left).derivative(end)[0], as_curve(right).derivative(end)[0]])
    slopes = np.vstack([np.asarray(twist_left, dtype=float), np.asarray(twist_right, dtype=float)])
    if normal is not None:
        nrm = np.asarray(normal, dtype=float)
        nrm = nrm / max(float(np.linalg.norm(nrm)), 1e-300)
        slopes = slopes - np.outer(slopes @ nrm, nrm)
    return PiecewiseBezier.from_hermite(values, slopes, np.array([0.0, 1.0]))


class BicubicCoons(_BooleanSumPatch):
    """Bicubically blended Coons patch (Eqs. 5.2-5.7), the base patch for C1 continuity.

    ``S = S_1 + S_2 - S_3`` with Hermite blends (Eq. 5.4):
    ``S_1 = H0(v) bottom(u) + H1(v) top(u) + H2(v) d_bottom(u) + H3(v) d_top(u)`` (Eq. 5.3),
    ``S_2 = H0(u) left(v) + H1(u) right(v) + H2(u) d_left(v) + H3(u) d_right(v)`` (Eq. 5.5),
    ``S_3`` the bicubic Hermite interpolant of corners, corner tangents and twists (Eqs. 5.6,
    5.7).

    Parameters
    ----------
    bottom, right, top, left : PiecewiseBezier or array
        The sides, in the convention of the module docstring.
    d_bottom, d_right, d_top, d_left : PiecewiseBezier or array
        Cross-boundary derivatives (ribbons), each on its side's parameter:
        ``d_bottom(u) = S_v(u, 0)``, ``d_top(u) = S_v(u, 1)``, ``d_left(v) = S_u(0, v)``,
        ``d_right(v) = S_u(1, v)``. Curves, not callables: the projection needs their
        derivatives, and a shared edge must hand its neighbours the very same data.
    twists : (2, 2, D) float, optional
        Corner twists ``twists[i, j] = S_uv(i, j)`` (the S_uv matrix of Eq. 5.7). Default: at
        each corner the average of the two ribbon derivatives there, ``d_left'(j)`` or
        ``d_right'(j)`` and ``d_bottom'(i)`` or ``d_top'(i)``.

    Notes
    -----
    The corner tangents of Eq. 5.7 are read from the ribbons (``S_u(i, j)`` from ``d_left`` /
    ``d_right``, ``S_v(i, j)`` from ``d_bottom`` / ``d_top``), which makes the patch
    interpolate its four sides whatever the ribbons. It interpolates its ribbons only when the
    corner data agree (see :meth:`compatibility_residuals`): at each corner a ribbon's value
    must equal the derivative of the side that leaves the corner the other way (e.g.
    ``d_bottom(0) = left'(0)``), and the twist must equal the derivative of both ribbons there
    (``d_left'(0) = d_bottom'(0) = S_uv(0, 0)``). Where four patches meet, this asks the sides
    passing straight through the corner, and the ribbons along a chain, to be C1; where three
    or five meet, it cannot all hold with bicubic patches, so measure what remains.
    """

    _blend = staticmethod(_hermite_blend)

    def __init__(
        self,
        bottom: CurveLike,
        right: CurveLike,
        top: CurveLike,
        left: CurveLike,
        d_bottom: CurveLike,
        d_right: CurveLike,
        d_top: CurveLike,
        d_left: CurveLike,
        twists: ArrayLike | None = None,
    ) -> None:
        self.bottom, self.right, self.top, self.left = (
            as_curve(c) for c in (bottom, right, top, left)
        )
        self.d_bottom, self.d_right, self.d_top, self.d_left = (
            as_curve(c) for c in (d_bottom, d_right, d_top, d_left)
        )
        self.corners = _check_corners(self.bottom, self.right, self.top, self.left)
        dim = self.bottom.dim
        for name in ("d_bottom", "d_right", "d_top", "d_left"):
            if getattr(self, name).dim != dim:
                raise InputError(
                    f"{name} has dimension {getattr(self, name).dim} but the sides have {dim}"
                )
        ends = np.array([0.0, 1.0])
        # u_rib[i] = S_u(i, v) at v = 0, 1 with derivatives; v_rib[j] = S_v(u, j) at u = 0, 1.
        u_rib = np.stack([self.d_left.jet(ends, 1), self.d_right.jet(ends, 1)])  # (i, r, j, D)
        v_rib = np.stack([self.d_bottom.jet(ends, 1), self.d_top.jet(ends, 1)])  # (j, r, i, D)
        if twists is None:
            twists = 0.5 * (u_rib[:, 1] + v_rib[:, 1].transpose(1, 0, 2))
        else:
            twists = np.asarray(twists, dtype=float)
            if twists.shape != (2, 2, dim):
                raise InputError(
                    f"twists must have shape (2, 2, {dim}) with twists[i, j] = S_uv(i, j), "
                    f"got {twists.shape}"
                )
            if not np.all(np.isfinite(twists)):
                raise InputError("twists contain NaN or inf; pass finite values or None")
        self.twists = twists
        # Corner data C[i, j] of Eq. 5.6 in the Hermite index order (value at 0, value at 1,
        # derivative at 0, derivative at 1) along u (i) and v (j).
        c = np.empty((4, 4, dim))
        c[:2, :2] = self.corners
        c[:2, 2:] = v_rib[:, 0].transpose(1, 0, 2)  # S_v(i, j) = v ribbon j at u = i
        c[2:, :2] = u_rib[:, 0]  # S_u(i, j) = u ribbon i at v = j
        c[2:, 2:] = twists
        self._corner_data = c
        self._u_curves = (self.bottom, self.top, self.d_bottom, self.d_top)
        self._v_curves = (self.left, self.right, self.d_left, self.d_right)

    def compatibility_residuals(self) -> dict[tuple[int, int], dict[str, float]]:
        """Mismatch of the corner data, per corner ``(i, j)`` = ``(u, v)`` in {0, 1}^2.

        Returns
        -------
        dict
            ``{(i, j): {"S_u": ..., "S_v": ..., "S_uv_from_u": ..., "S_uv_from_v": ...}}``:
            ``S_u`` = |derivative of the bottom/top side at u = i - u ribbon (d_left or
            d_right) at v = j|, ``S_v`` likewise with the left/right side against d_bottom or
            d_top, ``S_uv_from_u`` = |derivative of the u ribbon at the corner - twist|,
            ``S_uv_from_v`` the same for the v ribbon. All zero means the patch interpolates
            its four ribbons exactly (Eqs. 5.3-5.6); the residuals bound how far it misses.
        """
        ends = np.array([0.0, 1.0])
        side_u = [c.jet(ends, 1)[1] for c in (self.bottom, self.top)]  # [j][i] = dS/du
        side_v = [c.jet(ends, 1)[1] for c in (self.left, self.right)]  # [i][j] = dS/dv
        rib_u = [c.jet(ends, 1) for c in (self.d_left, self.d_right)]  # [i][r][j]
        rib_v = [c.jet(ends, 1) for c in (self.d_bottom, self.d_top)]  # [j][r][i]
        out: dict[tuple[int, int], dict[str, float]] = {}
        for i in (0, 1):
            for j in (0, 1):
                t = self.twists[i, j]
                out[(i, j)] = {
                    "S_u": float(np.linalg.norm(side_u[j][i] - rib_u[i][0][j])),
                    "S_v": float(np.linalg.norm(side_v[i][j] - rib_v[j][0][i])),
                    "S_uv_from_u": float(np.linalg.norm(rib_u[i][1][j] - t)),
                    "S_uv_from_v": float(np.linalg.norm(rib_v[j][1][i] - t)),
                }
        return out


# --------------------------------------------------------------------------- ribbons from points
@dataclass(frozen=True, eq=False)
class Ribbons:
    """Cross-boundary derivative curves and corner twists for :class:`BicubicCoons`.

    ``d_bottom(u) = S_v(u, 0)``, ``d_right(v) = S_u(1, v)``, ``d_top(u) = S_v(u, 1)``,
    ``d_left(v) = S_u(0, v)``; ``twists[i, j] = S_uv(i, j)``, shape (2, 2, D).
    """

    d_bottom: PiecewiseBezier
    d_right: PiecewiseBezier
    d_top: PiecewiseBezier
    d_left: PiecewiseBezier
    twists: NDArray[np.float64]


def _hermite_design(s: NDArray[np.float64], breaks: NDArray[np.float64]) -> NDArray[np.float64]:
    """Basis of a C1 piecewise cubic Hermite curve at ``s`` (n,): columns are the node values
    V_0..V_K then the node slopes T_0..T_K (derivatives d/ds). Shape (n, 2(K+1))."""
    k_max = breaks.size - 2
    k = np.clip(np.searchsorted(breaks, s, side="right") - 1, 0, k_max)
    h = breaks[k + 1] - breaks[k]
    basis = _hermite_blend((s - breaks[k]) / h, 0)  # H0 value at node k, H1 at k+1, H2/H3 slopes
    n_nodes = breaks.size
    out = np.zeros((s.size, 2 * n_nodes))
    rows = np.arange(s.size)
    out[rows, k] = basis[:, 0]
    out[rows, k + 1] = basis[:, 1]
    out[rows, n_nodes + k] = basis[:, 2] * h
    out[rows, n_nodes + k + 1] = basis[:, 3] * h
    return out


def estimate_cross_derivatives(
    points: ArrayLike,
    params: ArrayLike,
    bottom: CurveLike,
    right: CurveLike,
    top: CurveLike,
    left: CurveLike,
    band: float = 0.15,
    pieces: int = 1,
    order: int = 2,
    match_corners: bool = True,
) -> Ribbons:
    """Estimate the four ribbons of a bicubic Coons patch from the points near each side.

    The thesis takes the ribbons as given (Section 5.3.1); this fills the gap. Near a side,
    with ``s`` the parameter along it and ``w`` the signed parametric distance from it
    (``w = v`` at the bottom, ``v - 1`` at the top, ``u`` at the left, ``u - 1`` at the right),
    a Taylor expansion gives ``S(s, w) = C(s) + w D(s) + w^2 E_2(s) + ... + w^order E_order(s)``
    with ``C`` the known side and ``D`` the ribbon. The points with ``|w| < band`` fit
    ``D, E_2, ...`` by one linear least-squares problem. Each unknown curve is a C1 piecewise
    cubic Hermite with ``pieces`` uniform pieces (unknowns: node values and slopes).

    With ``match_corners`` (default) the result satisfies the corner compatibility conditions
    of :class:`BicubicCoons` by construction: each ribbon's end values are pinned to the
    derivatives of the sides leaving its corners (``d_bottom(0) = left'(0)`` ...), and the
    end slopes of the two ribbons meeting at a corner are one shared unknown, the twist. The
    four sides are then solved jointly. Without it, each side is fitted freely and the twists
    are the averages of the two ribbon slopes.

    Parameters
    ----------
    points : (N, D) float
        The patch's points.
    params : (N, 2) float
        Their ``(u, v)`` in [0, 1]^2, e.g. from :func:`pde2cad.surfaces.projection.project_points`
        onto the bilinear Coons patch of the same sides.
    bottom, right, top, left : PiecewiseBezier or array
        The sides (module convention).
    band : float
        Width of the band of points used per side, in parameter units (0 < band <= 0.5).
    pieces : int
        Number of Hermite pieces per ribbon.
    order : int
        Highest power of ``w`` in the model (>= 1); 2 absorbs the curvature across the side,
        3 is exact for bicubic patches.
    match_corners : bool
        Pin ribbon ends to the side derivatives and share the twists (see above).

    Returns
    -------
    Ribbons

    Raises
    ------
    InputError
        NaN, wrong shapes, params outside [0, 1], band or pieces out of range.
    FitError
        A band holds too few points to determine its unknowns.
    """
    pts = np.asarray(points, dtype=float)
    prm = np.asarray(params, dtype=float)
    if pts.ndim != 2 or prm.shape != (pts.shape[0], 2):
        raise InputError(
            f"points must be (N, D) and params (N, 2) with the same N; got {pts.shape} and "
            f"{prm.shape}"
        )
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(prm))):
        raise InputError("points or params contain NaN or inf; drop those rows first")
    if np.any(prm < 0.0) or np.any(prm > 1.0):
        raise InputError(
            "params must lie in [0, 1]^2; drop the points project_points flags as outside"
        )
    if not 0.0 < band <= 0.5:
        raise InputError(f"band must be in (0, 0.5], got {band}")
    if pieces < 1 or order < 1:
        raise InputError(f"pieces and order must be >= 1, got pieces={pieces}, order={order}")
    sides = {
        "bottom": as_curve(bottom),
        "right": as_curve(right),
        "top": as_curve(top),
        "left": as_curve(left),
    }
    _check_corners(*sides.values())
    dim = pts.shape[1]
    if sides["bottom"].dim != dim:
        raise InputError(f"points have dimension {dim} but the sides have {sides['bottom'].dim}")

    breaks = np.linspace(0.0, 1.0, pieces + 1)
    n_nodes = pieces + 1
    n_basis = 2 * n_nodes
    ends = np.array([0.0, 1.0])
    # side -> (along index, depth offset, corner (i, j) at s = 0 and s = 1, pinned end values)
    spec = {
        "bottom": (
            0,
            0.0,
            ((0, 0), (1, 0)),
            sides["left"].derivative(ends[:1])[0],
            sides["right"].derivative(ends[:1])[0],
        ),
        "top": (
            0,
            1.0,
            ((0, 1), (1, 1)),
            sides["left"].derivative(ends[1:])[0],
            sides["right"].derivative(ends[1:])[0],
        ),
        "left": (
            1,
            0.0,
            ((0, 0), (0, 1)),
            sides["bottom"].derivative(ends[:1])[0],
            sides["top"].derivative(ends[:1])[0],
        ),
        "right": (
            1,
            1.0,
            ((1, 0), (1, 1)),
            sides["bottom"].derivative(ends[1:])[0],
            sides["top"].derivative(ends[1:])[0],
        ),
    }

    # Global unknowns: [4 twists if shared] + per side [ribbon columns] + [higher terms].
    n_twist = 4 if match_corners else 0
    rib_cols = n_basis - 4 if match_corners else n_basis  # pinned ends and twists leave
    side_cols = rib_cols + (order - 1) * n_basis
    n_cols = n_twist + 4 * side_cols
    # Thin QR factorizations and a tiny least squares: a threaded BLAS only adds barriers.
    from pde2cad.surfaces.deformation import _single_threaded_blas

    with _single_threaded_blas():
        blocks: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
        for idx, (name, (along, offset, corner_ij, pin0, pin1)) in enumerate(spec.items()):
            s_all = prm[:, along]
            w_all = prm[:, 1 - along] - offset
            sel = np.abs(w_all) < band
            s, w = s_all[sel], w_all[sel][:, None]
            if s.size < side_cols + (2 if match_corners else 0):
                raise FitError(
                    f"only {s.size} points lie within band={band} of the {name} side, too few "
                    f"for {side_cols} unknowns; widen band, or lower pieces / order"
                )
            rhs = pts[sel] - sides[name].evaluate(s)
            basis = _hermite_design(s, breaks)
            # Only this side's columns (and its two corner twists) are non-zero in its band:
            # factor those alone and place the triangle's columns back (same normal equations,
            # a fraction of the work).
            base = n_twist + idx * side_cols
            used = list(range(base, base + side_cols))
            if match_corners:
                used = [2 * i + j for i, j in corner_ij] + used
            cols = np.zeros((s.size, len(used)))
            first = 2 if match_corners else 0  # local column of the side's first unknown
            if match_corners:
                # Ribbon node layout: values V_0..V_K, slopes T_0..T_K; V_0, V_K are pinned
                # (moved to the right-hand side), T_0, T_K are the shared corner twists.
                rhs = rhs - w * (basis[:, :1] * pin0 + basis[:, n_nodes - 1 : n_nodes] * pin1)
                cols[:, 0] = w[:, 0] * basis[:, n_nodes]
                cols[:, 1] = w[:, 0] * basis[:, -1]
                free = np.r_[1 : n_nodes - 1, n_nodes + 1 : 2 * n_nodes - 1]
                cols[:, first : first + rib_cols] = w * basis[:, free]
            else:
                cols[:, first : first + rib_cols] = w * basis
            for p in range(2, order + 1):
                start = first + rib_cols + (p - 2) * n_basis
                cols[:, start : start + n_basis] = w**p * basis
            # Reduce each band to its small triangular factor: the joint problem is then tiny.
            # mode="r" returns the bare R array; numpy's stubs type every mode as QRResult.
            r = cast(NDArray[np.float64], np.linalg.qr(np.hstack([cols, rhs]), mode="r"))
            r_full = np.zeros((r.shape[0], n_cols))
            r_full[:, used] = r[:, : len(used)]
            blocks.append((r_full, r[:, len(used) :]))
        a = np.vstack([b[0] for b in blocks])
        b = np.vstack([b[1] for b in blocks])
        sol, _, rank, sv = np.linalg.lstsq(a, b, rcond=None)
    if rank < n_cols or sv[-1] < 1e-12 * sv[0]:
        raise FitError(
            "the points near the sides do not determine the ribbons (rank-deficient fit); "
            "check that points cover every side's band, widen band, or lower pieces / order"
        )

    ribbons: dict[str, PiecewiseBezier] = {}
    twist_sum = np.zeros((2, 2, dim))
    for idx, (name, (_, _, corner_ij, pin0, pin1)) in enumerate(spec.items()):
        base = n_twist + idx * side_cols
        x = sol[base : base + rib_cols]
        if match_corners:
            values = np.vstack([pin0, x[: n_nodes - 2], pin1])
            (i0, j0), (i1, j1) = corner_ij
            slopes = np.vstack([sol[2 * i0 + j0], x[n_nodes - 2 :], sol[2 * i1 + j1]])
        else:
            values, slopes = x[:n_nodes], x[n_nodes:]
            for (i, j), slope in zip(corner_ij, (slopes[0], slopes[-1]), strict=True):
                twist_sum[i, j] += 0.5 * slope
        ribbons[name] = PiecewiseBezier.from_hermite(values, slopes, breaks)
    twists = np.asarray(sol[:4].reshape(2, 2, dim) if match_corners else twist_sum, dtype=float)
    return Ribbons(
        d_bottom=ribbons["bottom"],
        d_right=ribbons["right"],
        d_top=ribbons["top"],
        d_left=ribbons["left"],
        twists=twists,
    )
