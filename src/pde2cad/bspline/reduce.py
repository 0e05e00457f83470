"""Knot removal: the same curve or surface with the lowest knot multiplicities it allows.

A CAD kernel reads a B-spline's continuity from its knots alone: a cubic with an interior
knot of multiplicity 3 is C0 there for OpenCASCADE (``GeomAbs_C0``), whatever its poles say,
and offsets, shells and thickening refuse C0 faces. The conversions of
:mod:`pde2cad.bspline.convert` write every Bézier break with multiplicity 3 (exact for any
chain), although the chains the layout fits are C1 at their breaks. Removing a knot is exact
where the geometry is smooth enough there (the removed-knot spline space contains it), so
the removal below finds the reduced poles by least squares and keeps only removals whose
deviation bound is within a tolerance.

The deviation bound is rigorous: inserting the knot back into the reduced spline (Boehm)
gives poles on the original knot vector, and by the convex-hull property the two curves
differ by at most the largest distance between corresponding poles.

Every operation acts on axis 0 of the pole array with the other axes carried along, so one
removal along u of a surface is the removal on each of its pole columns at once; the poles
outside the knot's support are copied bitwise, which keeps the surface's other edges as they
were.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pde2cad.bspline.data import BSplineCurve, BSplineSurface, insert_knot, unique_knots
from pde2cad.errors import InputError

#: Default removal tolerance relative to the pole bounding-box diagonal. A change of 1e-9 of
#: a part's size is far below any kernel's confusion tolerance (OCCT: 1e-7 mm on parts of mm
#: to m), and two faces' copies of a shared edge then stay within 2e-9 of each other.
REMOVAL_TOLERANCE = 1e-9


def remove_knot(
    poles: NDArray[np.float64], knots: NDArray[np.float64], degree: int, x: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Remove one copy of the interior knot ``x`` along axis 0 of ``poles``.

    1. The reduced knot vector drops one ``x``; inserting ``x`` back into it is a linear map
       ``A`` (n, n - 1) from reduced poles to original ones (Boehm on the identity).
    2. Rows of ``A`` that copy one reduced pole fix it exactly (the poles away from ``x``).
    3. The remaining reduced poles solve the overdetermined rows by least squares, for every
       trailing column at once; a column whose affected poles are all equal (a collapsed side)
       keeps that value bitwise.
    4. The deviation is the largest distance between ``A @ Q`` and ``poles``.

    Parameters
    ----------
    poles : (n, ..., D) float
    knots : (n + degree + 1,) float
        Full clamped knot vector containing ``x`` strictly inside the domain.
    degree : int
    x : float

    Returns
    -------
    poles : (n - 1, ..., D) float
    knots : (n + degree,) float
    deviation : float
        Upper bound of the distance between the original and the reduced spline.
    """
    hits = np.flatnonzero(knots == x)
    if hits.size == 0 or not knots[degree] < x < knots[-degree - 1]:
        raise InputError(f"{x} is not an interior knot of the knot vector")
    n = poles.shape[0]
    reduced = np.delete(knots, hits[-1])
    a, _ = insert_knot(np.eye(n - 1), reduced, degree, float(x))
    copies = (np.count_nonzero(a, axis=1) == 1) & (a.max(axis=1) == 1.0)
    fixed_cols = a[copies].argmax(axis=1)
    free = np.setdiff1d(np.arange(n - 1), fixed_cols)
    flat = poles.reshape(n, -1)
    q = np.empty((n - 1, flat.shape[1]))
    q[fixed_cols] = flat[copies]
    rows = ~copies
    rhs = flat[rows] - a[rows][:, fixed_cols] @ q[fixed_cols]
    if free.size:  # none when lowering a multiplicity-p knot: a pure collinearity test
        q[free] = np.linalg.lstsq(a[rows][:, free], rhs, rcond=None)[0]
        # A collapsed side (all its poles one point) must stay one point bitwise.
        span = flat[max(free.min() - 1, 0) : free.max() + 2]
        const = np.all(span == span[0], axis=0)
        q[free] = np.where(const, span[0], q[free])
    # The copied rows match exactly; only the solved ones can deviate.
    diff = (a[rows] @ q - flat[rows]).reshape((-1, *poles.shape[1:]))
    deviation = float(np.sqrt((diff * diff).sum(axis=-1)).max())
    return q.reshape((n - 1, *poles.shape[1:])), reduced, deviation


def _reduce_axis(
    poles: NDArray[np.float64], knots: NDArray[np.float64], degree: int, budget: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Lower every interior knot of multiplicity above 1 along axis 0 while the deviations
    (which add up) fit in ``budget``, lowest knot first; returns poles, knots and the budget
    used. One copy of each knot stays: dropping it would not raise the continuity a kernel
    reads, only try (and fail) on every span of a fitted spline."""
    used = 0.0
    values, _ = unique_knots(knots[degree + 1 : -degree - 1])
    for x in values:
        while np.count_nonzero(knots == x) > 1:
            trial, reduced, dev = remove_knot(poles, knots, degree, float(x))
            if used + dev > budget:
                break
            poles, knots, used = trial, reduced, used + dev
    return poles, knots, used


def _size(poles: NDArray[np.float64]) -> float:
    flat = poles.reshape(-1, poles.shape[-1])
    return float(np.linalg.norm(flat.max(axis=0) - flat.min(axis=0)))


def reduce_curve(curve: BSplineCurve, tolerance: float | None = None) -> BSplineCurve:
    """``curve`` with every interior knot copy removed that moves it by at most
    ``tolerance`` in total (default :data:`REMOVAL_TOLERANCE` x its pole bounding-box
    diagonal); exact (to rounding) where the curve is smoother than its knots say."""
    tol = REMOVAL_TOLERANCE * _size(curve.poles) if tolerance is None else float(tolerance)
    if not tol >= 0:
        raise InputError(f"tolerance must be >= 0, got {tolerance}")
    poles, knots, _ = _reduce_axis(curve.poles, curve.knots, curve.degree, tol)
    return BSplineCurve(poles, knots, curve.degree)


def reduce_surface(surface: BSplineSurface, tolerance: float | None = None) -> BSplineSurface:
    """``surface`` with the lowest knot multiplicities within ``tolerance``.

    1. The budget is ``tolerance`` (default :data:`REMOVAL_TOLERANCE` x the pole
       bounding-box diagonal), shared by both directions: the deviations add up.
    2. Knots are removed along u (every pole column at once), then along v with what is left.

    A C1 bicubic patch written with triple knots comes back with double ones (``GeomAbs_C1``
    for a kernel), a C2 one with single knots; where the surface really has a crease or a
    curvature jump the knot stays. The boundary rows along the reduced direction change by
    at most the tolerance; the two rows across it are copied bitwise.

    Parameters
    ----------
    surface : BSplineSurface
    tolerance : float, optional
        Largest total distance the surface may move (units of the poles).

    Returns
    -------
    BSplineSurface
    """
    tol = REMOVAL_TOLERANCE * _size(surface.poles) if tolerance is None else float(tolerance)
    if not tol >= 0:
        raise InputError(f"tolerance must be >= 0, got {tolerance}")
    poles, ku, used = _reduce_axis(surface.poles, surface.knots_u, surface.degree_u, tol)
    moved, kv, _ = _reduce_axis(
        np.swapaxes(poles, 0, 1), surface.knots_v, surface.degree_v, tol - used
    )
    return BSplineSurface(
        np.swapaxes(moved, 0, 1), ku, kv, surface.degree_u, surface.degree_v
    )
