"""Least-squares cubic Bézier fitting with fixed end points (thesis Section 3.2).

Works in any dimension D (2D outlines, 3D boundary curves). The corrected normal equations
of Eqs. 3.6-3.9 (see NOTES.md) are solved through :func:`numpy.linalg.lstsq` around a
straight-line prior, so 2-3 points or repeated parameters give the minimum-norm answer instead
of a singular matrix. Optional end tangents make joins G1: ``p1 = p0 + alpha * tan0`` and
``p2 = p3 - beta * tan3`` with ``alpha, beta > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.curves import bezier
from pde2cad.curves.parameterize import METHODS

# Joint Levenberg-Marquardt rounds per fit (see fit_with_parameters): 5 reach the orthogonal
# optimum to a few percent on pixel boundaries; smooth samples converge to ~1e-15 in ~10.
NEWTON_ROUNDS = 5


@dataclass(frozen=True)
class CubicFit:
    """One fitted cubic and how well it fits its points.

    Attributes
    ----------
    ctrl : (4, D) float
    t : (n,) float
        Parameters of the points after Newton refinement.
    errors : (n,) float
        Distance from each point to the curve point at its parameter (an upper bound of the
        orthogonal distance).
    method : str
        The initial parameterization that gave this fit.
    """

    ctrl: NDArray[np.float64]
    t: NDArray[np.float64]
    errors: NDArray[np.float64]
    method: str

    @property
    def max_error(self) -> float:
        return float(self.errors.max(initial=0.0))

    @property
    def mean_error(self) -> float:
        return float(self.errors.mean()) if len(self.errors) else 0.0


def _unit(v: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    if v is None:
        return None
    n = float(np.linalg.norm(v))
    return None if n < 1e-12 else np.asarray(v, dtype=float) / n


def _constraint_basis(
    p0: NDArray[np.float64],
    p3: NDArray[np.float64],
    tan0: NDArray[np.float64] | None,
    tan3: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Inner control points as ``p1 = base1 + lin1 @ x``, ``p2 = base2 + lin2 @ x``.

    The base is the straight-line (or tangent-following) prior, so a minimum-norm solve of
    an under-determined fit stays near a line instead of flying off.
    """
    dim = len(p0)
    chord_vec = p3 - p0
    prior_len = max(float(np.linalg.norm(chord_vec)) / 3.0, 1e-9)
    eye = np.eye(dim)
    zeros = np.zeros((dim, dim))
    if tan0 is None and tan3 is None:
        return p0 + chord_vec / 3.0, p3 - chord_vec / 3.0, np.hstack([eye, zeros]), np.hstack([zeros, eye])
    if tan3 is None:
        assert tan0 is not None  # both None returned above
        return (p0 + prior_len * tan0, p3 - chord_vec / 3.0,
                np.hstack([tan0[:, None], zeros]), np.hstack([np.zeros((dim, 1)), eye]))
    if tan0 is None:
        return (p0 + chord_vec / 3.0, p3 - prior_len * tan3,
                np.hstack([eye, np.zeros((dim, 1))]), np.hstack([zeros, -tan3[:, None]]))
    return (p0 + prior_len * tan0, p3 - prior_len * tan3,
            np.stack([tan0, np.zeros(dim)], axis=1), np.stack([np.zeros(dim), -tan3], axis=1))


def solve_cubic(
    points: NDArray[np.float64],
    t: NDArray[np.float64],
    p0: NDArray[np.float64],
    p3: NDArray[np.float64],
    tan0: NDArray[np.float64] | None = None,
    tan3: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Inner control points minimizing sum |C(t_i) - P_i|^2 with p0, p3 fixed (Eqs. 3.3-3.9).

    Parameters
    ----------
    points : (n, D) float
    t : (n,) float
    p0, p3 : (D,) float
        Fixed end points.
    tan0, tan3 : (D,) float or None
        Unit tangent directions at the ends; when given, the inner point on that side may
        only move along it (G1 join), with a positive length.

    Returns
    -------
    (4, D) float
    """
    s = 1.0 - t
    a = 3.0 * t * s * s
    b = 3.0 * t * t * s
    c = (s**3)[:, None] * p0 + (t**3)[:, None] * p3 - points
    base1, base2, lin1, lin2 = _constraint_basis(p0, p3, tan0, tan3)
    design = a[:, None, None] * lin1 + b[:, None, None] * lin2  # (n, D, k)
    rhs = -(a[:, None] * base1 + b[:, None] * base2 + c)  # (n, D)
    x = np.linalg.lstsq(design.reshape(-1, design.shape[2]), rhs.reshape(-1), rcond=None)[0]
    return _clamped(np.stack([p0, base1 + lin1 @ x, base2 + lin2 @ x, p3]), a, b, c, tan0, tan3)


def _clamped(ctrl, a, b, c, tan0, tan3) -> NDArray[np.float64]:
    """Keep G1 tangent lengths positive: a length <= 0 reverses the curve at the join (a
    cusp, not G1); clamp it and refit the other side alone."""
    p0, p1, p2, p3 = ctrl
    floor = 1e-3 * max(float(np.linalg.norm(p3 - p0)) / 3.0, 1e-9)
    base2 = p2
    if tan0 is not None and np.dot(p1 - p0, tan0) < floor:
        p1 = p0 + floor * tan0
        res = -(a[:, None] * p1 + b[:, None] * base2 + c)
        if tan3 is None:
            p2 = base2 + _lstsq_vec(b, res)
        else:
            p2 = base2 - tan3 * _lstsq_scalar(b[:, None] * -tan3[None, :], res)
    if tan3 is not None and np.dot(p3 - p2, tan3) < floor:
        p2 = p3 - floor * tan3
    return np.stack([p0, p1, p2, p3])


def _lstsq_vec(coef: NDArray[np.float64], res: NDArray[np.float64]) -> NDArray[np.float64]:
    """argmin_x sum |coef_i x - res_i|^2 for a vector x: (sum coef_i res_i) / sum coef_i^2."""
    den = float(coef @ coef)
    return (coef @ res) / den if den > 1e-300 else np.zeros(res.shape[1])


def _lstsq_scalar(cols: NDArray[np.float64], res: NDArray[np.float64]) -> float:
    """argmin_s sum |cols_i s - res_i|^2 for a scalar s; cols, res are (n, D)."""
    den = float(np.sum(cols * cols))
    return float(np.sum(cols * res)) / den if den > 1e-300 else 0.0


def reparameterize(
    ctrl: NDArray[np.float64], points: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """One Newton step of t_i towards the closest curve point to P_i (Schneider 1990)."""
    diff = bezier.evaluate(ctrl, t) - points
    d1 = bezier.derivative(ctrl, t, 1)
    d2 = bezier.derivative(ctrl, t, 2)
    num = np.sum(diff * d1, axis=1)
    den = np.sum(d1 * d1, axis=1) + np.sum(diff * d2, axis=1)
    step = np.divide(num, den, out=np.zeros_like(num), where=np.abs(den) > 1e-12)
    return np.clip(t - step, 0.0, 1.0)


def fit_with_parameters(
    points: NDArray[np.float64],
    t: NDArray[np.float64],
    p0: NDArray[np.float64],
    p3: NDArray[np.float64],
    tan0: NDArray[np.float64] | None = None,
    tan3: NDArray[np.float64] | None = None,
    rounds: int = NEWTON_ROUNDS,
    method: str = "given",
    weights: NDArray[np.float64] | None = None,
) -> CubicFit:
    """Least-squares fit from initial parameters ``t``, then ``rounds`` Levenberg-Marquardt
    steps on control points and parameters jointly (orthogonal distance regression).

    Alternating the linear solve with Newton reparameterization (Schneider 1990) converges
    slowly; the joint step eliminates each point's parameter by a Schur complement (a scalar
    per point), so it costs about the same as one alternation and converges in a few.
    ``weights`` (n,) weight each point's squared distance (used to push down the maximum).
    """
    sw = np.ones(len(points)) if weights is None else np.sqrt(weights)
    base1, base2, lin1, lin2 = _constraint_basis(p0, p3, tan0, tan3)
    # Design rows are sw_i (a_i lin1 + b_i lin2): every product below reduces to a few
    # weighted sums of a, b and small (D, k) matrices, so each round costs a handful of
    # vector operations whatever the dimension.
    l11, l12, l22 = lin1.T @ lin1, lin1.T @ lin2 + lin2.T @ lin1, lin2.T @ lin2

    def state(t_: ArrayLike, x_: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        t_, x_ = np.asarray(t_, dtype=float), np.asarray(x_, dtype=float)
        s_ = 1.0 - t_
        a_, b_ = 3.0 * t_ * s_ * s_, 3.0 * t_ * t_ * s_
        p1_, p2_ = base1 + lin1 @ x_, base2 + lin2 @ x_
        curve = np.outer(s_ * s_ * s_, p0) + np.outer(a_, p1_) + np.outer(b_, p2_) + np.outer(t_ * t_ * t_, p3)
        return a_ * sw, b_ * sw, s_, p1_, p2_, (curve - points) * sw[:, None]

    s0 = 1.0 - t
    a0, b0 = 3.0 * t * s0 * s0 * sw, 3.0 * t * t * s0 * sw
    c0 = (np.outer(s0**3, p0) + np.outer(t**3, p3) - points) * sw[:, None] + np.outer(a0, base1) + np.outer(b0, base2)
    h0 = (a0 @ a0) * l11 + (a0 @ b0) * l12 + (b0 @ b0) * l22
    rhs0 = -(lin1.T @ (a0 @ c0) + lin2.T @ (b0 @ c0))
    x = np.linalg.lstsq(h0, rhs0, rcond=None)[0] if h0.size else np.zeros(0)
    aw, bw, s, p1, p2, resid = state(t, x)
    cost = float(np.sum(resid * resid))
    lam = 1e-3
    k = len(x)
    for _ in range(rounds if k else 0):
        jt = (3.0 * np.outer(s * s, p1 - p0) + 6.0 * np.outer(t * s, p2 - p1) + 3.0 * np.outer(t * t, p3 - p2)) * sw[:, None]
        ct = np.sum(jt * jt, axis=1)
        g = (aw[:, None] * jt) @ lin1 + (bw[:, None] * jt) @ lin2  # (n, k)
        jtr = np.sum(jt * resid, axis=1)
        h0 = (aw @ aw) * l11 + (aw @ bw) * l12 + (bw @ bw) * l22
        r0 = lin1.T @ (aw @ resid) + lin2.T @ (bw @ resid)
        diag = np.diag(np.diag(h0) + 1e-12)
        improved = False
        for _try in range(4):
            cd = ct * (1.0 + lam) + 1e-12
            gs = g / cd[:, None]
            h = h0 - g.T @ gs + lam * diag
            rhs = -(r0 - gs.T @ jtr)
            try:
                dx = np.linalg.solve(h, rhs)
            except np.linalg.LinAlgError:
                dx = np.linalg.lstsq(h, rhs, rcond=None)[0]
            t_new = np.clip(t - (jtr + g @ dx) / cd, 0.0, 1.0)
            x_new = x + dx
            new_state = state(t_new, x_new)
            cost_new = float(np.sum(new_state[-1] * new_state[-1]))
            if cost_new < cost:
                x, t, cost = x_new, t_new, cost_new
                aw, bw, s, p1, p2, resid = new_state
                lam = max(lam / 3.0, 1e-7)
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
    ctrl = np.stack([p0, base1 + lin1 @ x, base2 + lin2 @ x, p3])
    a, b, c = _abc(t, p0, p3, points)
    ctrl = _clamped(ctrl, a, b, c, tan0, tan3)
    t = reparameterize(ctrl, points, t)
    errors = np.linalg.norm(bezier.evaluate(ctrl, t) - points, axis=1)
    return CubicFit(ctrl, t, errors, method)


def minimax_refine(
    fit: CubicFit,
    points: NDArray[np.float64],
    p0: NDArray[np.float64],
    p3: NDArray[np.float64],
    tan0: NDArray[np.float64] | None = None,
    tan3: NDArray[np.float64] | None = None,
    iterations: int = 3,
) -> CubicFit:
    """Lower a least-squares fit's maximum error by reweighting (Lawson's iteration).

    Least squares balances the squared errors; the fit test only looks at the largest one.
    Raising the weights of the points with large errors trades a little mean error for a
    smaller maximum, which lets one cubic cover more points within the tolerance.
    """
    best = fit
    w = np.ones(len(points))
    for _ in range(iterations):
        e = best.errors
        w = w * (e / max(float(e.max()), 1e-300) + 0.05)
        w = w / w.mean()
        cand = fit_with_parameters(points, best.t, p0, p3, tan0, tan3, rounds=3, method=fit.method, weights=w)
        if cand.max_error < best.max_error:
            best = cand
        else:
            break
    return best


def _abc(t, p0, p3, points):
    s = 1.0 - t
    return 3.0 * t * s * s, 3.0 * t * t * s, (s**3)[:, None] * p0 + (t**3)[:, None] * p3 - points


def fit_cubic(
    points: NDArray[np.float64],
    *,
    p0: NDArray[np.float64] | None = None,
    p3: NDArray[np.float64] | None = None,
    tan0: NDArray[np.float64] | None = None,
    tan3: NDArray[np.float64] | None = None,
    method: str = "optimal",
    param_points: NDArray[np.float64] | None = None,
    tolerance: float | None = None,
    rounds: int = NEWTON_ROUNDS,
) -> CubicFit:
    """Fit one cubic Bézier to ordered points.

    Parameters
    ----------
    points : (n, D) float, n >= 2
    p0, p3 : (D,) float, optional
        End points; default the first and last point.
    tan0, tan3 : (D,) float, optional
        End tangent directions (G1 constraints), normalized here.
    method : str
        A name of :data:`pde2cad.curves.parameterize.METHODS`, or "optimal" to try them all
        and keep the fit with the least maximum error (thesis Section 3.4, Table 3.3).
    param_points : (n, D) float, optional
        Points the parameterization is computed from (e.g. a smoothed copy of a pixel
        staircase, whose raw chord lengths are all 1); default ``points``.
    tolerance : float, optional
        With "optimal", stop at the first parameterization whose maximum error is within it
        (used inside the bisection search, where any passing fit will do).

    Returns
    -------
    CubicFit
    """
    pts = np.asarray(points, dtype=float)
    p0 = pts[0] if p0 is None else np.asarray(p0, dtype=float)
    p3 = pts[-1] if p3 is None else np.asarray(p3, dtype=float)
    tan0, tan3 = _unit(tan0), _unit(tan3)
    ppts = pts if param_points is None else np.asarray(param_points, dtype=float)
    names = list(METHODS) if method == "optimal" else [method]
    best: CubicFit | None = None
    for name in names:
        fit = fit_with_parameters(pts, METHODS[name](ppts), p0, p3, tan0, tan3, rounds, name)
        if best is None or (fit.max_error, fit.mean_error) < (best.max_error, best.mean_error):
            best = fit
        if tolerance is not None and best.max_error <= tolerance:
            break
        # Far outside the tolerance no other parameterization will rescue the fit.
        if tolerance is not None and best.max_error > 1.5 * tolerance:
            break
    assert best is not None
    return best


def curve_to_polyline_distance(
    ctrl: NDArray[np.float64], polyline: NDArray[np.float64], samples: int = 24
) -> float:
    """Largest distance from samples of the curve to an open polyline ``(n, D)``.

    The fit test uses it with the points' own polyline (for a pixel boundary, the exact
    staircase) so a curve cannot bulge away between the points it fits.
    """
    s = bezier.evaluate(ctrl, np.linspace(0.0, 1.0, samples))
    if len(polyline) == 1:
        return float(np.linalg.norm(s - polyline[0], axis=1).max())
    a = polyline[:-1]
    ab = polyline[1:] - a
    len2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    rel = s[:, None, :] - a[None, :, :]  # (S, m, D)
    h = np.clip(np.sum(rel * ab[None], axis=2) / len2[None], 0.0, 1.0)
    d2 = np.sum((rel - h[:, :, None] * ab[None]) ** 2, axis=2)
    return float(np.sqrt(d2.min(axis=1).max()))
