"""Cubic Bézier curves as plain arrays, in any dimension (Eq. 2.6).

A cubic is a ``(4, D)`` array of control points; a chain of ``K`` cubics is ``(K, 4, D)``.
Functions broadcast over leading axes so a whole loop is evaluated in one call.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

# Power-basis matrix: B(t) = [1, t, t^2, t^3] @ _M @ ctrl.
_M = np.array(
    [[1.0, 0.0, 0.0, 0.0], [-3.0, 3.0, 0.0, 0.0], [3.0, -6.0, 3.0, 0.0], [-1.0, 3.0, -3.0, 1.0]]
)


def bernstein(t: ArrayLike) -> NDArray[np.float64]:
    """Cubic Bernstein basis at ``t``: shape ``t.shape + (4,)``."""
    t = np.asarray(t, dtype=float)
    s = 1.0 - t
    return np.stack([s * s * s, 3.0 * t * s * s, 3.0 * t * t * s, t * t * t], axis=-1)  # pow() is 10x slower


def evaluate(ctrl: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Points on the cubic(s).

    Parameters
    ----------
    ctrl : (..., 4, D) float
    t : (n,) float in [0, 1]

    Returns
    -------
    (..., n, D) float
    """
    return bernstein(t) @ np.asarray(ctrl, dtype=float)


def derivative(ctrl: ArrayLike, t: ArrayLike, order: int = 1) -> NDArray[np.float64]:
    """``order``-th derivative (1, 2 or 3) of the cubic(s) at ``t``: shape (..., n, D)."""
    c = np.asarray(ctrl, dtype=float)
    t = np.asarray(t, dtype=float)
    if order == 1:
        d = 3.0 * np.diff(c, axis=-2)  # (..., 3, D) quadratic
        s = 1.0 - t
        basis = np.stack([s * s, 2.0 * t * s, t * t], axis=-1)
        return basis @ d
    if order == 2:
        d = 6.0 * np.diff(c, n=2, axis=-2)  # (..., 2, D) linear
        basis = np.stack([1.0 - t, t], axis=-1)
        return basis @ d
    if order == 3:
        d = 6.0 * np.diff(c, n=3, axis=-2)  # (..., 1, D) constant
        return np.broadcast_to(d, d.shape[:-2] + (t.shape[0], d.shape[-1])).copy()
    raise ValueError(f"derivative order must be 1, 2 or 3, got {order}")


def split(ctrl: ArrayLike, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """de Casteljau split of one cubic ``(4, D)`` at ``t`` into two cubics."""
    p = np.asarray(ctrl, dtype=float)
    a = (1 - t) * p[:-1] + t * p[1:]
    b = (1 - t) * a[:-1] + t * a[1:]
    c = (1 - t) * b[:-1] + t * b[1:]
    left = np.stack([p[0], a[0], b[0], c[0]])
    right = np.stack([c[0], b[1], a[2], p[3]])
    return left, right


def power_coefficients(ctrl: ArrayLike) -> NDArray[np.float64]:
    """Power-basis coefficients ``(..., 4, D)``: B(t) = sum_k coef[k] t^k."""
    return _M @ np.asarray(ctrl, dtype=float)


def sample_chain(curves: ArrayLike, per_curve: int) -> NDArray[np.float64]:
    """Sample a chain ``(K, 4, D)`` with ``per_curve`` points per curve (end point excluded).

    Returns ``(K * per_curve, D)``; for a closed chain this is the closed polyline's vertices.
    """
    t = np.arange(per_curve) / per_curve
    pts = evaluate(curves, t)
    return pts.reshape(-1, pts.shape[-1])


def transform(curves: ArrayLike, matrix: ArrayLike, offset: ArrayLike) -> NDArray[np.float64]:
    """Apply the affine map x -> matrix @ x + offset to control points (Béziers are affine
    invariant, which is what makes symmetric fitting exact)."""
    c = np.asarray(curves, dtype=float)
    return c @ np.asarray(matrix, dtype=float).T + np.asarray(offset, dtype=float)
