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
    pts, valid, p0, p3 = batch.points, batch.valid, batch.p0, batch.p3
    w = valid.astype(float) if weights is None else np.where(valid, weights, 0.0)
    sw = np.sqrt(w)
    sw3 = sw[..., None]
    base1, base2, lin1, lin2 = _basis(batch)
    l11 = lin1.transpose(0, 2, 1) @ lin1
    l12 = lin1.transpose(0, 2, 1) @ lin2
    l12 = l12 + l12.transpose(0, 2, 1)
    l22 = lin2.transpose(0, 2, 1) @ lin2
    k = lin1.shape[2]

    def inner(x, r=None):
        if r is not None:  # the problems r only
            return base1[r] + (lin1[r] @ x[..., None])[..., 0], base2[r] + (lin2[r] @ x[..., None])[..., 0]
        return base1 + (lin1 @ x[..., None])[..., 0], base2 + (lin2 @ x[..., None])[..., 0]

    def state(t_, x_, r=None):
        q0, q3, q, w1, w3 = (p0, p3, pts, sw, sw3) if r is None else (p0[r], p3[r], pts[r], sw[r], sw3[r])
        s_ = 1.0 - t_
        ts = 3.0 * t_ * s_
        a_, b_ = ts * s_, ts * t_
        p1_, p2_ = inner(x_, r)
        curve = ((s_ * s_ * s_)[..., None] * q0[:, None] + a_[..., None] * p1_[:, None]
                 + b_[..., None] * p2_[:, None] + (t_ * t_ * t_)[..., None] * q3[:, None])
        return a_ * w1, b_ * w1, s_, p1_, p2_, (curve - q) * w3

    def hessian(aw, bw):
        return (_dot(aw, aw)[:, None, None] * l11 + _dot(aw, bw)[:, None, None] * l12
                + _dot(bw, bw)[:, None, None] * l22)

    def project(aw, bw, r):
        return (lin1.transpose(0, 2, 1) @ (aw[:, None, :] @ r).transpose(0, 2, 1)
                + lin2.transpose(0, 2, 1) @ (bw[:, None, :] @ r).transpose(0, 2, 1))[..., 0]

    # 1. linear solve around the prior
    s0 = 1.0 - t
    a0, b0 = 3.0 * t * s0 * s0 * sw, 3.0 * t * t * s0 * sw
    c0 = (((s0**3)[..., None] * p0[:, None] + (t**3)[..., None] * p3[:, None] - pts) * sw[..., None]
          + a0[..., None] * base1[:, None] + b0[..., None] * base2[:, None])
    h0 = hessian(a0, b0)
    x = (np.linalg.pinv(h0) @ (-project(a0, b0, c0))[..., None])[..., 0]
    aw, bw, s, p1, p2, resid = state(t, x)
    cost = _ADD(_dot(resid, resid), axis=1)
    lam = np.full(len(pts), 1e-3)
    active = np.ones(len(pts), bool)
    eye_k = np.eye(k)
    # 2. joint Levenberg-Marquardt rounds
    for _ in range(rounds):
        if not active.any():
            break
        jt = (3.0 * (s * s)[..., None] * (p1 - p0)[:, None] + 6.0 * (t * s)[..., None] * (p2 - p1)[:, None]
              + 3.0 * (t * t)[..., None] * (p3 - p2)[:, None]) * sw3
        ct = _dot(jt, jt)
        g = (aw[..., None] * jt) @ lin1 + (bw[..., None] * jt) @ lin2
        jtr = _dot(jt, resid)
        hh = hessian(aw, bw)
        r0 = project(aw, bw, resid)
        diag = hh.diagonal(axis1=1, axis2=2) + 1e-12
        pending = active.copy()
        for _try in range(4):
            if pending.all():
                cd = ct * (1.0 + lam[:, None]) + 1e-12
                gs = g / cd[..., None]
                h = hh - g.transpose(0, 2, 1) @ gs + lam[:, None, None] * (diag[:, :, None] * eye_k)
                dx = _solve(h, -(r0 - (gs.transpose(0, 2, 1) @ jtr[..., None])[..., 0]))
                t_new = _unit_clip(t - (jtr + (g @ dx[..., None])[..., 0]) / cd)
                new = state(t_new, x + dx)
                cost_new = _ADD(_dot(new[-1], new[-1]), axis=1)
                if (cost_new < cost).all():  # the usual case: every problem improves, no row selection
                    x, t, cost = x + dx, t_new, cost_new
                    aw, bw, s, p1, p2, resid = new
                    lam = np.maximum(lam / 3.0, 1e-7)
                    pending[:] = False
                    break
                rows = np.arange(len(pts))
            else:
                # Retries (and problems that stopped) cost only the problems still pending.
                rows = np.flatnonzero(pending)
                t_new, dx, new, cost_new = _retry(rows, x, t, lam, (ct, g, hh, diag, r0, jtr), eye_k, state)
            take = cost_new < cost[rows]
            got = rows[take]
            x[got], t[got], cost[got] = x[got] + dx[take], t_new[take], cost_new[take]
            aw[got], bw[got], s[got] = new[0][take], new[1][take], new[2][take]
            p1[got], p2[got], resid[got] = new[3][take], new[4][take], new[5][take]
            lam[got] = np.maximum(lam[got] / 3.0, 1e-7)
            lam[rows[~take]] *= 10.0
            pending[got] = False
            if not pending.any():
                break
        active &= ~pending
    # 3. positive tangent lengths, 4. errors
    p1, p2 = _clamped(batch, t, valid, *inner(x))
    ctrl = np.stack([p0, p1, p2, p3], axis=1)
    t = _newton(ctrl, pts, t)
    errors = np.where(valid, _norm(_evaluate(ctrl, t) - pts), 0.0)
    return ctrl, t, errors


def _retry(rows, x, t, lam, step, eye_k, state):
    """The damped step of :func:`fit_batch` for the problems ``rows`` only (``step`` holds
    the round's ``ct, g, hh, diag, r0, jtr``): new parameters, control-point step, state, cost."""
    ct, g, hh, diag, r0, jtr = (a[rows] for a in step)
    cd = ct * (1.0 + lam[rows][:, None]) + 1e-12
    gs = g / cd[..., None]
    h = hh - g.transpose(0, 2, 1) @ gs + lam[rows][:, None, None] * (diag[:, :, None] * eye_k)
    dx = _solve(h, -(r0 - (gs.transpose(0, 2, 1) @ jtr[..., None])[..., 0]))
    t_new = _unit_clip(t[rows] - (jtr + (g @ dx[..., None])[..., 0]) / cd)
    new = state(t_new, x[rows] + dx, rows)
    return t_new, dx, new, _ADD(_dot(new[-1], new[-1]), axis=1)


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
            c = (s**3)[..., None] * p0[:, None] + (t**3)[..., None] * p3[:, None] - batch.points
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
    out = np.empty(t.shape + (4,))  # filled in place: np.stack costs more than the arithmetic
    out[..., 0] = s**3
    out[..., 1] = 3.0 * t * s * s
    out[..., 2] = 3.0 * t * t * s
    out[..., 3] = t**3
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
