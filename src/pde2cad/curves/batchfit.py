"""Many least-squares cubic fits at once (the batched form of :mod:`pde2cad.curves.fit`).

The break-point search tests many candidate pieces (several lengths, several
parameterizations). One fit of a few dozen points costs far more in interpreter overhead than
in arithmetic, so the candidates are padded into one ``(B, N, D)`` batch and fitted by the
same joint Levenberg-Marquardt iteration as :func:`pde2cad.curves.fit.fit_with_parameters`,
every product a batched ``matmul``. Padded rows carry zero weight and never move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Batch:
    """Padded fit problems.

    Attributes
    ----------
    points : (B, N, D) float
    valid : (B, N) bool
        True for the real (unpadded) rows of each problem; each problem has >= 2.
    p0, p3 : (B, D) float
        Fixed end points.
    tan0, tan3 : (B, D) float or None
        Unit end tangents (G1 constraints); None frees that end of every problem, a row of
        NaN frees it for that problem only (problems of every kind share one batch).
    """

    points: NDArray[np.float64]
    valid: NDArray[np.bool_]
    p0: NDArray[np.float64]
    p3: NDArray[np.float64]
    tan0: NDArray[np.float64] | None
    tan3: NDArray[np.float64] | None


def _dot(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Dot products along the last axis (``einsum`` is many times slower on small axes).

    Over a point's 2 or 3 coordinates the products are added one by one, in the order
    the reduction adds them (the same numbers, at half its cost on such short axes)."""
    if x.shape[-1] <= 3 and y.shape[-1] == x.shape[-1]:
        out = x[..., 0] * y[..., 0]
        for i in range(1, x.shape[-1]):
            out = out + x[..., i] * y[..., i]
        return out
    return _ADD(x * y, axis=-1)


def _norm(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.linalg.norm(x, axis=-1)``, the same numbers without its Python wrapper."""
    return np.sqrt(_dot(x, x))


# The ufunc reductions themselves: ``ndarray.sum`` and ``np.clip`` pass through Python
# wrappers that cost as much as the arithmetic on these small arrays.
_ADD = np.add.reduce


def _unit_clip(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.clip(x, 0, 1)``."""
    return np.minimum(np.maximum(x, 0.0), 1.0)


def _free_rows(tan: NDArray[np.float64] | None) -> NDArray[np.bool_] | None:
    """Rows of a tangent array that leave their end free (NaN); None when there are none."""
    if tan is None:
        return None
    free = np.isnan(tan[:, 0])
    return free if free.any() else None


def _mixed_basis(batch: Batch):
    """:func:`_basis` for a batch mixing free and tangent-constrained ends.

    Each end takes the columns of a free end (D of them); a constrained end uses the first
    only and leaves the others zero, so their unknowns stay 0 (minimum-norm first solve,
    zero gradient in the damped steps)."""
    p0, p3 = batch.p0, batch.p3
    bsz, dim = p0.shape
    chord = p3 - p0
    prior = np.maximum(_norm(chord)[:, None] / 3.0, 1e-9)
    free0 = np.ones(bsz, bool) if batch.tan0 is None else np.isnan(batch.tan0[:, 0])
    free3 = np.ones(bsz, bool) if batch.tan3 is None else np.isnan(batch.tan3[:, 0])
    tan0 = np.zeros_like(p0) if batch.tan0 is None else np.where(free0[:, None], 0.0, batch.tan0)
    tan3 = np.zeros_like(p3) if batch.tan3 is None else np.where(free3[:, None], 0.0, batch.tan3)
    lin1 = np.zeros((bsz, dim, 2 * dim))
    lin2 = np.zeros((bsz, dim, 2 * dim))
    eye = np.eye(dim)
    lin1[free0, :, :dim] = eye
    lin1[~free0, :, 0] = tan0[~free0]
    lin2[free3, :, dim:] = eye
    lin2[~free3, :, dim] = -tan3[~free3]
    base1 = np.where(free0[:, None], p0 + chord / 3.0, p0 + prior * tan0)
    base2 = np.where(free3[:, None], p3 - chord / 3.0, p3 - prior * tan3)
    return base1, base2, lin1, lin2


def _basis(batch: Batch):
    """Batched :func:`pde2cad.curves.fit._constraint_basis`: ``p1 = base1 + lin1 @ x``."""
    if _free_rows(batch.tan0) is not None or _free_rows(batch.tan3) is not None:
        return _mixed_basis(batch)
    p0, p3, tan0, tan3 = batch.p0, batch.p3, batch.tan0, batch.tan3
    bsz, dim = p0.shape
    chord = p3 - p0
    prior = np.maximum(_norm(chord)[:, None] / 3.0, 1e-9)
    eye = np.broadcast_to(np.eye(dim), (bsz, dim, dim))
    zero_dd = np.zeros((bsz, dim, dim))
    zero_d1 = np.zeros((bsz, dim, 1))
    if tan0 is None and tan3 is None:
        return p0 + chord / 3.0, p3 - chord / 3.0, np.concatenate([eye, zero_dd], 2), np.concatenate([zero_dd, eye], 2)
    if tan3 is None:
        assert tan0 is not None  # both None returned above
        return (p0 + prior * tan0, p3 - chord / 3.0,
                np.concatenate([tan0[:, :, None], zero_dd], 2), np.concatenate([zero_d1, eye], 2))
    if tan0 is None:
        return (p0 + chord / 3.0, p3 - prior * tan3,
                np.concatenate([eye, zero_d1], 2), np.concatenate([zero_dd, -tan3[:, :, None]], 2))
    return (p0 + prior * tan0, p3 - prior * tan3,
            np.concatenate([tan0[:, :, None], zero_d1], 2), np.concatenate([zero_d1, -tan3[:, :, None]], 2))


def _solve(h: NDArray[np.float64], rhs: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched solve of ``h x = rhs`` (B, k, k) x (B, k), minimum norm where singular."""
    try:
        x = np.linalg.solve(h, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        x = (np.linalg.pinv(h) @ rhs[..., None])[..., 0]
    return np.asarray(x, dtype=np.float64)


class _Problem:
    """The fixed arrays of a batch in the stacked basis of both inner control points.

    ``inner = base + lin @ x`` stacks p1 over p2 ((B, 2D) and (B, 2D, k)); the Gauss-Newton
    products then take one matmul each instead of one per inner point (the arithmetic is
    tiny, the number of numpy calls is the cost)."""

    def __init__(self, batch: Batch, w: NDArray[np.float64]) -> None:
        base1, base2, lin1, lin2 = _basis(batch)
        self.dim = batch.p0.shape[1]
        self.pts = batch.points
        self.sw = np.sqrt(w)
        self.sw3 = self.sw[..., None]
        self.base = np.concatenate([base1, base2], axis=1)
        self.lin = np.concatenate([lin1, lin2], axis=1)  # (B, 2D, k)
        self.lin_t = self.lin.transpose(0, 2, 1)
        l12 = lin1.transpose(0, 2, 1) @ lin2
        k = lin1.shape[2]
        # H = m00 l11 + m01 (l12 + l12^T) + m11 l22 with m = A^T A (A: the two inner weights).
        self.quad = np.stack([lin1.transpose(0, 2, 1) @ lin1, l12 + l12.transpose(0, 2, 1),
                              lin2.transpose(0, 2, 1) @ lin2], axis=1).reshape(len(w), 3, k * k)
        self.ends = np.zeros((len(w), 4, self.dim))
        self.ends[:, 0], self.ends[:, 3] = batch.p0, batch.p3

    def ctrl(self, x: NDArray[np.float64], r=None) -> NDArray[np.float64]:
        """Control points (B, 4, D) for the unknowns x (problems ``r`` only if given)."""
        base, lin, ends = (self.base, self.lin, self.ends) if r is None else (self.base[r], self.lin[r], self.ends[r])
        out = ends.copy()
        out[:, 1:3] = (base + (lin @ x[..., None])[..., 0]).reshape(len(x), 2, self.dim)
        return out

    def state(self, t_, x_, r=None):
        """Weighted inner Bernstein values A (B, N, 2), control points and weighted residuals."""
        q, w1, w3 = (self.pts, self.sw, self.sw3) if r is None else (self.pts[r], self.sw[r], self.sw3[r])
        ctrl = self.ctrl(x_, r)
        bern = _bernstein(t_)
        return bern[..., 1:3] * w1[..., None], ctrl, (bern @ ctrl - q) * w3

    def hessian(self, a, r=None):
        """Gauss-Newton matrix of the inner control points, (B, k, k)."""
        quad = self.quad if r is None else self.quad[r]
        m = (a.transpose(0, 2, 1) @ a).reshape(len(a), 4)[:, [0, 1, 3]]
        k = self.lin.shape[2]
        return (m[:, None, :] @ quad).reshape(len(a), k, k)

    def project(self, a, resid, r=None):
        """Gradient of the cost in x, (B, k)."""
        lin_t = self.lin_t if r is None else self.lin_t[r]
        return (lin_t @ (a.transpose(0, 2, 1) @ resid).reshape(len(a), -1, 1))[..., 0]

    def coupling(self, a, jt, r=None):
        """Mixed derivatives of the residuals in x and t, (B, N, k)."""
        lin = self.lin if r is None else self.lin[r]
        bsz, n = a.shape[:2]
        return (a[..., :, None] * jt[..., None, :]).reshape(bsz, n, -1) @ lin


def _speed(ctrl: NDArray[np.float64], t: NDArray[np.float64], sw3: NDArray[np.float64]) -> NDArray[np.float64]:
    """Weighted derivatives C'(t) of cubics (B, 4, D) at parameters (B, N): (B, N, D)."""
    s = 1.0 - t
    b1 = np.empty(t.shape + (3,))
    b1[..., 0], b1[..., 1], b1[..., 2] = s * s, 2.0 * t * s, t * t
    return (b1 @ (3.0 * (ctrl[:, 1:] - ctrl[:, :-1]))) * sw3


def _cost(resid: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sums of squared residuals per problem, (B,)."""
    return _ADD(_dot(resid, resid), axis=1)


def fit_batch(
    batch: Batch, t: NDArray[np.float64], rounds: int, weights: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Fit every problem of the batch from initial parameters ``t`` (B, N).

    Steps: 1. linear least squares for the inner control points (Eqs. 3.6-3.9, in the
    constraint basis); 2. ``rounds`` joint Levenberg-Marquardt steps on control points and
    parameters, each problem with its own damping, stopping where it no longer improves;
    3. clamp G1 tangent lengths positive; 4. one Newton step of the parameters and the
    per-point errors.

    Returns
    -------
    ctrl : (B, 4, D) float
    t : (B, N) float
    errors : (B, N) float, 0 on padded rows
    """
    pts, valid = batch.points, batch.valid
    w = valid.astype(float) if weights is None else np.where(valid, weights, 0.0)
    prob = _Problem(batch, w)
    k = prob.lin.shape[2]
    # 1. linear solve around the prior (the residuals at x = 0)
    a0, _, c0 = prob.state(t, np.zeros((len(t), k)))
    x = (np.linalg.pinv(prob.hessian(a0)) @ (-prob.project(a0, c0))[..., None])[..., 0]
    a, ctrl, resid = prob.state(t, x)
    cost = _cost(resid)
    lam = np.full(len(pts), 1e-3)
    active = np.ones(len(pts), bool)
    eye_k = np.eye(k)
    # 2. joint Levenberg-Marquardt rounds
    for _ in range(rounds):
        if not active.any():
            break
        jt = _speed(ctrl, t, prob.sw3)
        ct = _dot(jt, jt)
        g = prob.coupling(a, jt)
        jtr = _dot(jt, resid)
        hh = prob.hessian(a)
        r0 = prob.project(a, resid)
        diag = hh.diagonal(axis1=1, axis2=2) + 1e-12
        pending = active.copy()
        for _try in range(4):
            if pending.all():
                cd = ct * (1.0 + lam[:, None]) + 1e-12
                gs = g / cd[..., None]
                h = hh - g.transpose(0, 2, 1) @ gs + lam[:, None, None] * (diag[:, :, None] * eye_k)
                dx = _solve(h, -(r0 - (gs.transpose(0, 2, 1) @ jtr[..., None])[..., 0]))
                t_new = _unit_clip(t - (jtr + (g @ dx[..., None])[..., 0]) / cd)
                new = prob.state(t_new, x + dx)
                cost_new = _cost(new[-1])
                if (cost_new < cost).all():  # the usual case: every problem improves, no row selection
                    x, t, cost = x + dx, t_new, cost_new
                    a, ctrl, resid = new
                    lam = np.maximum(lam / 3.0, 1e-7)
                    pending[:] = False
                    break
                rows = np.arange(len(pts))
            else:
                # Retries (and problems that stopped) cost only the problems still pending.
                rows = np.flatnonzero(pending)
                t_new, dx, new, cost_new = _retry(rows, x, t, lam, (ct, g, hh, diag, r0, jtr), eye_k, prob)
            take = cost_new < cost[rows]
            got = rows[take]
            x[got], t[got], cost[got] = x[got] + dx[take], t_new[take], cost_new[take]
            a[got], ctrl[got], resid[got] = new[0][take], new[1][take], new[2][take]
            lam[got] = np.maximum(lam[got] / 3.0, 1e-7)
            lam[rows[~take]] *= 10.0
            pending[got] = False
            if not pending.any():
                break
        active &= ~pending
    # 3. positive tangent lengths, 4. errors
    inner = prob.ctrl(x)
    p1, p2 = _clamped(batch, t, valid, inner[:, 1], inner[:, 2])
    ctrl = np.stack([batch.p0, p1, p2, batch.p3], axis=1)
    t = _newton(ctrl, pts, t)
    errors = np.where(valid, _norm(_evaluate(ctrl, t) - pts), 0.0)
    return ctrl, t, errors


def _retry(rows, x, t, lam, step, eye_k, prob: _Problem):
    """The damped step of :func:`fit_batch` for the problems ``rows`` only (``step`` holds
    the round's ``ct, g, hh, diag, r0, jtr``): new parameters, control-point step, state, cost."""
    ct, g, hh, diag, r0, jtr = (v[rows] for v in step)
    cd = ct * (1.0 + lam[rows][:, None]) + 1e-12
    gs = g / cd[..., None]
    h = hh - g.transpose(0, 2, 1) @ gs + lam[rows][:, None, None] * (diag[:, :, None] * eye_k)
    dx = _solve(h, -(r0 - (gs.transpose(0, 2, 1) @ jtr[..., None])[..., 0]))
    t_new = _unit_clip(t[rows] - (jtr + (g @ dx[..., None])[..., 0]) / cd)
    new = prob.state(t_new, x[rows] + dx, rows)
    return t_new, dx, new, _cost(new[-1])


def _clamped(batch: Batch, t, valid, p1, p2):
    """Batched :func:`pde2cad.curves.fit._clamped`: a G1 length <= 0 is a cusp; clamp it and
    refit the other inner point alone."""
    p0, p3, tan0, tan3 = batch.p0, batch.p3, batch.tan0, batch.tan3
    floor = 1e-3 * np.maximum(_norm(p3 - p0) / 3.0, 1e-9)
    if tan0 is not None:
        bad = _dot(p1 - p0, tan0) < floor
        if bad.any():
            s = 1.0 - t
            a, b = 3.0 * t * s * s * valid, 3.0 * t * t * s * valid
            c = (s * s * s)[..., None] * p0[:, None] + (t * t * t)[..., None] * p3[:, None] - batch.points
            p1 = np.where(bad[:, None], p0 + floor[:, None] * tan0, p1)
            res = -(a[..., None] * p1[:, None] + b[..., None] * p2[:, None] + c) * valid[..., None]
            den = np.maximum(_dot(b, b), 1e-300)
            free_shift = (b[:, None, :] @ res)[:, 0] / den[:, None]
            if tan3 is None:
                shift = free_shift
            else:
                shift = -tan3 * (_dot((b[:, None, :] @ res)[:, 0], -tan3) / den)[:, None]
                free3 = _free_rows(tan3)
                if free3 is not None:
                    shift = np.where(free3[:, None], free_shift, shift)
            p2 = np.where(bad[:, None], p2 + shift, p2)
    if tan3 is not None:
        bad = _dot(p3 - p2, tan3) < floor
        p2 = np.where(bad[:, None], p3 - floor[:, None] * tan3, p2)
    return p1, p2


def _bernstein(t: NDArray[np.float64]) -> NDArray[np.float64]:
    s = 1.0 - t
    s2, t2 = s * s, t * t
    # Filled in place (np.stack costs more than the arithmetic); products, not ``**3``,
    # which numpy computes by pow() at ten times the cost of a multiplication.
    out = np.empty(t.shape + (4,))
    out[..., 0] = s2 * s
    out[..., 1] = 3.0 * t * s2
    out[..., 2] = 3.0 * t2 * s
    out[..., 3] = t2 * t
    return out


def _evaluate(ctrl: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points C_b(t_bn) of cubics (B, 4, D) at parameters (B, N): (B, N, D)."""
    return _bernstein(t) @ ctrl


def _newton(ctrl, pts, t):
    """One Newton step of every parameter towards the closest curve point (Schneider 1990)."""
    s = 1.0 - t
    d1c = ctrl[:, 1:] - ctrl[:, :-1]
    d2c = 6.0 * (d1c[:, 1:] - d1c[:, :-1])
    d1c = 3.0 * d1c
    diff = _evaluate(ctrl, t) - pts
    b1 = np.empty(t.shape + (3,))
    b1[..., 0], b1[..., 1], b1[..., 2] = s * s, 2 * t * s, t * t
    b2 = np.empty(t.shape + (2,))
    b2[..., 0], b2[..., 1] = s, t
    d1 = b1 @ d1c
    d2 = b2 @ d2c
    num = _dot(diff, d1)
    den = _dot(d1, d1) + _dot(diff, d2)
    step = np.divide(num, den, out=np.zeros_like(num), where=np.abs(den) > 1e-12)
    return _unit_clip(t - step)


def minimax_batch(batch: Batch, ctrl, t, errors, iterations: int = 3):
    """Batched :func:`pde2cad.curves.fit.minimax_refine`: reweight towards the largest
    errors (Lawson's iteration) and keep each problem's fit while its maximum drops."""
    w = batch.valid.astype(float)
    ctrl, t, errors = ctrl.copy(), t.copy(), errors.copy()
    best_max = errors.max(axis=1)
    live = np.arange(len(t))
    for _ in range(iterations):
        # Only the problems whose maximum still dropped are refitted (rows of the others
        # would be computed and thrown away).
        sub = _rows(batch, live) if len(live) < len(t) else batch
        w = w * (errors[live] / np.maximum(errors[live].max(axis=1, keepdims=True), 1e-300) + 0.05)
        w = np.where(sub.valid, w, 0.0)
        w = w / np.maximum(w.sum(axis=1, keepdims=True) / sub.valid.sum(axis=1, keepdims=True), 1e-300)
        c2, t2, e2 = fit_batch(sub, t[live].copy(), rounds=3, weights=w)
        better = e2.max(axis=1) < best_max[live]
        idx = live[better]
        ctrl[idx], t[idx], errors[idx] = c2[better], t2[better], e2[better]
        best_max[idx] = e2[better].max(axis=1)
        live, w = idx, w[better]
        if not live.size:
            break
    return ctrl, t, errors


def _rows(batch: Batch, rows: NDArray[np.int64]) -> Batch:
    """The problems ``rows`` of a batch."""
    return Batch(batch.points[rows], batch.valid[rows], batch.p0[rows], batch.p3[rows],
                 None if batch.tan0 is None else batch.tan0[rows], None if batch.tan3 is None else batch.tan3[rows])


def midpoint_errors(ctrl: NDArray[np.float64], batch: Batch, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Upper bound on the largest distance from the midpoints of consecutive points to each
    curve: the curve point at the mean of the two parameters, after three Newton steps.

    Returns
    -------
    (B,) float
    """
    mid = 0.5 * (batch.points[:, :-1] + batch.points[:, 1:])
    tm = 0.5 * (t[:, :-1] + t[:, 1:])
    for _ in range(3):
        tm = _newton(ctrl, mid, tm)
    pair = batch.valid[:, 1:]
    return np.where(pair, _norm(_evaluate(ctrl, tm) - mid), 0.0).max(axis=1)


def curve_to_polyline_batch(
    ctrl: NDArray[np.float64], batch: Batch, t: NDArray[np.float64], samples: int = 24, window: int = 8
) -> NDArray[np.float64]:
    """Upper bound on the largest distance from samples of each curve to its points' polyline.

    Each sample is compared with the ``2 * window + 1`` polyline edges around the points
    whose fitted parameters bracket its own (the full polyline costs O(N) per sample); a
    minimum over fewer edges can only be larger, so the fit test stays conservative.

    Returns
    -------
    (B,) float
    """
    pts, valid = batch.points, batch.valid
    bsz, n, _ = pts.shape
    u = np.linspace(0.0, 1.0, samples)
    s = _bernstein(u) @ ctrl
    count = valid.sum(axis=1)
    tm = np.maximum.accumulate(np.where(valid, t, 1.0), axis=1)
    centre = _searchsorted_rows(tm, u)
    edge = centre[:, :, None] - 1 + np.arange(-window, window + 1)[None, None, :]  # (B, S, W)
    last_edge = np.maximum(count - 2, 0)[:, None, None]
    edge = np.clip(edge, 0, last_edge)
    rows = np.arange(bsz)[:, None, None]
    a = pts[rows, edge]
    ab = pts[rows, np.minimum(edge + 1, (count - 1)[:, None, None])] - a
    rel = s[:, :, None, :] - a
    len2 = np.maximum(_dot(ab, ab), 1e-300)
    h = _unit_clip(_dot(rel, ab) / len2)
    off = rel - h[..., None] * ab
    d2 = _dot(off, off)
    return np.sqrt(d2.min(axis=2).max(axis=1))


def _searchsorted_rows(sorted_rows: NDArray[np.float64], values: NDArray[np.float64]) -> NDArray[np.int64]:
    """``np.searchsorted`` of ``values`` (S,) into each row of ``sorted_rows`` (B, N)."""
    bsz, n = sorted_rows.shape
    # Offset every row into its own band so one flat searchsorted serves all rows.
    offs = np.arange(bsz)[:, None] * 2.0
    flat = (sorted_rows + offs).ravel()
    idx = np.searchsorted(flat, (values[None, :] + offs).ravel()).reshape(bsz, -1)
    return idx - np.arange(bsz)[:, None] * n


def parameters(name: str, points: NDArray[np.float64], lengths: NDArray[np.int64]) -> NDArray[np.float64]:
    """Batched :data:`pde2cad.curves.parameterize.METHODS` on padded runs (B, N, D).

    Rows past each run's length repeat its last point (zero-length steps), which leaves the
    chord, centripetal and Foley-Nielson parameters of the real rows unchanged.

    Returns
    -------
    (B, N) float, 0 at each run's start and 1 from its end on
    """
    bsz, n, _ = points.shape
    v = np.diff(points, axis=1)
    d = _norm(v)
    if name == "uniform":
        return np.minimum(np.arange(n)[None, :] / np.maximum(lengths - 1, 1)[:, None], 1.0)
    if name == "chord":
        steps = d
    elif name == "centripetal":
        steps = np.sqrt(d)
    elif name == "foley":
        u = v / np.where(d > 0, d, 1.0)[..., None]
        cos = np.clip(_dot(u[:, :-1], u[:, 1:]), -1.0, 1.0)
        theta = np.minimum(np.arccos(cos), np.pi / 2)
        zero = np.zeros((bsz, 1))
        theta_full = np.concatenate([zero, theta, zero], axis=1)
        d_prev = np.concatenate([zero, d[:, :-1]], axis=1)
        d_next = np.concatenate([d[:, 1:], zero], axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            left = np.where(d_prev + d > 0, theta_full[:, :-1] * d_prev / (d_prev + d), 0.0)
            right = np.where(d + d_next > 0, theta_full[:, 1:] * d_next / (d + d_next), 0.0)
        steps = d * (1.0 + 1.5 * left + 1.5 * right)
    else:
        raise ValueError(f"unknown parameterization {name!r}")
    t = np.concatenate([np.zeros((bsz, 1)), np.cumsum(steps, axis=1)], axis=1)
    total = t[:, -1:]
    flat = np.minimum(np.arange(n)[None, :] / np.maximum(lengths - 1, 1)[:, None], 1.0)
    good = np.isfinite(total) & (total > 0)
    return np.where(good, t / np.where(good, total, 1.0), flat)
