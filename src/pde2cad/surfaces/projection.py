"""Point parameterization by closest-point projection onto a base patch (Section 5.2.3).

The thesis parameterizes each point by its closest point on the bilinear Coons patch, with the
geometric method of Li et al. (2019) run in parallel. Here the same closest point is found
for all points at once: a coarse grid of surface samples and a KD-tree give each point a start
in the right basin, then a damped Newton iteration on ``f(u, v) = |S(u, v) - P|^2 / 2`` with
analytic first and second derivatives converges quadratically, inside the box [0, 1]^2.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from pde2cad.errors import InputError

_EPS = np.finfo(float).eps
# Fewer points than this are projected as one chunk (threads cost more than they save).
_MIN_SPLIT = 8192
# Full Newton steps (in parameter) below this are taken without a surface evaluation: the
# error left is about the step squared (see _taylor_step).
_TAYLOR_STEP = 1e-7
# Largest voxel table of nearest grid samples (see _StartTable); beyond it a KD-tree query.
_MAX_VOXELS = 100_000


def _jet_function(surface: Any) -> Any:
    """``(u, v) -> (S, S_u, S_v, S_uu, S_uv, S_vv)``, each coordinate-major (D, n).

    The Coons patches return transposed views of (D, n) arrays, so the transpose here is
    free and every later operation runs along contiguous rows of n points.
    """
    if hasattr(surface, "jet"):
        raw = surface.jet
    else:
        missing = [
            n for n in ("evaluate", "derivatives", "second_derivatives") if not hasattr(surface, n)
        ]
        if missing:
            raise InputError(
                f"surface lacks {', '.join(missing)}; pass a patch with evaluate(u, v), "
                "derivatives(u, v) and second_derivatives(u, v), such as BilinearCoons"
            )

        def raw(u: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
            return (
                surface.evaluate(u, v),
                *surface.derivatives(u, v),
                *surface.second_derivatives(u, v),
            )

    def jet(u: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        return tuple(np.asarray(a, dtype=float).T for a in raw(u, v))

    return jet


def _dot(
    a: NDArray[np.float64], b: NDArray[np.float64], out: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """Column-wise dot products of two (D, n) arrays: (n,), into ``out`` if given (one
    pass, no temporaries: a third faster than summing the row products)."""
    return np.einsum("ij,ij->j", a, b, out=out)


def _newton_terms(
    jet: tuple[NDArray[np.float64], ...], p: NDArray[np.float64]
) -> dict[str, NDArray[Any]]:
    """Objective ``f = |r|^2``, gradient/2 ``grad = (r.S_u, r.S_v)`` (2, n), a positive
    semi-definite Hessian/2 ``hess = (h_uu, h_uv, h_vv)`` (3, n), whether that is the full
    one (``full``, (n,) bool) and the first-order data ``lin = (r, S_u, S_v)`` (3 D, n);
    ``p`` and the jet are (D, n).

    Full Newton (Gauss-Newton plus the curvature terms ``r.S_xy``) where that is positive
    definite, which gives quadratic convergence even for points off the surface; Gauss-Newton
    elsewhere, so every step is a descent direction.
    """
    s, su, sv, suu, suv, svv = jet
    dim, n = p.shape
    lin = np.empty((3 * dim, n))
    r = np.subtract(s, p, out=lin[:dim])
    lin[dim : 2 * dim], lin[2 * dim :] = su, sv
    grad, gn, full = np.empty((2, n)), np.empty((3, n)), np.empty((3, n))
    for k, (a, b) in enumerate(((r, su), (r, sv))):
        _dot(a, b, out=grad[k])
    for k, (a, b) in enumerate(((su, su), (su, sv), (sv, sv))):
        _dot(a, b, out=gn[k])
    for k, curvature in enumerate((suu, suv, svv)):
        _dot(r, curvature, out=full[k])
    full += gn
    definite = (full[0] > 0) & (full[0] * full[2] - full[1] ** 2 > 0)
    hess = np.where(definite, full, gn)
    return {"f": _dot(r, r), "grad": grad, "hess": hess, "full": definite, "lin": lin}


def _solve_step(
    uv: NDArray[np.float64],
    grad: NDArray[np.float64],
    hess: NDArray[np.float64],
    mu: NDArray[np.float64],
    bounded: bool,
) -> NDArray[np.float64]:
    """Levenberg-Marquardt step ``-(H + mu tr(H)/2 I)^-1 g`` for 2x2 systems, vectorized;
    all arrays coordinate-major ((2, n), (2, n), (3, n), (n,)).

    With ``bounded``, a coordinate sitting on a side of [0, 1]^2 whose gradient pushes it out
    is frozen and the step taken in the other one (a projected Newton step).
    """
    gu, gv = grad
    a, b, c = hess
    # The tiny floor keeps the system solvable where a side degenerates to a point (S_u = 0).
    damp = (mu + 1e-12) * (0.5 * (a + c)) + 1e-300
    a, c = a + damp, c + damp
    if bounded:
        u, v = uv
        fix_u = ((u <= 0.0) & (gu > 0)) | ((u >= 1.0) & (gu < 0))
        fix_v = ((v <= 0.0) & (gv > 0)) | ((v >= 1.0) & (gv < 0))
        if fix_u.any() or fix_v.any():  # most points lie inside: no copies for them
            gu, gv = np.where(fix_u, 0.0, gu), np.where(fix_v, 0.0, gv)
            b = np.where(fix_u | fix_v, 0.0, b)
    det = a * c - b * b
    det = np.where(det > 0, det, np.inf)  # no descent information: stay put
    step = np.empty((2, det.size))
    np.divide(c * gu - b * gv, det, out=step[0])
    np.divide(a * gv - b * gu, det, out=step[1])
    return np.negative(step, out=step)


def _taylor_step(state: dict[str, NDArray[Any]], step: NDArray[np.float64]) -> None:
    """Move points by ``step`` (2, n) without evaluating the surface, in place: ``uv``,
    ``f``, ``grad`` and ``r = S - P`` (the top rows of ``lin``) there from the first-order
    data at the current point (a zero step leaves them bit for bit).

    Used for full Newton steps below ``_TAYLOR_STEP``: quadratic convergence leaves an error
    of about the step squared (below 1e-14), and the first-order values miss the exact ones
    by ``|S_uu| step^2 / 2`` (about 1e-14 of the patch size).
    """
    lin, grad, h = state["lin"], state["grad"], state["hess"]
    dim = lin.shape[0] // 3
    du, dv = step
    r = lin[:dim] + lin[dim : 2 * dim] * du + lin[2 * dim :] * dv
    grad[0] += h[0] * du + h[1] * dv
    grad[1] += h[1] * du + h[2] * dv
    lin[:dim] = r
    state["f"] = _dot(r, r)
    state["uv"] += step


def _project_chunk(
    jet_fn: Any,
    p: NDArray[np.float64],
    uv: NDArray[np.float64],
    jet0: tuple[NDArray[np.float64], ...],
    iters: int,
    xtol: float,
) -> dict[str, NDArray[np.float64]]:
    """Damped projected Newton for one chunk of points ``p`` (D, n) from ``uv`` (2, n), where
    the surface jet is ``jet0``; returns ``uv``, ``f``, ``grad``, ``hess`` and ``lin``
    (``r = S - P``, ``S_u``, ``S_v`` stacked, (3 D, n)) at the final points.

    The state is kept compact for the points still iterating; a finished point is written
    out once, so late iterations cost only what the few slow points need. A converging full
    Newton step below ``_TAYLOR_STEP`` is the last one and needs no evaluation
    (:func:`_taylor_step`).
    """
    n = p.shape[1]
    state = _newton_terms(jet0, p)
    state.update(uv=uv.copy(), mu=np.zeros(n), p=p, scale=np.sqrt(_dot(p, p)))
    out = {k: np.empty((*state[k].shape[:-1], n)) for k in ("uv", "f", "grad", "hess", "lin")}
    idx = np.arange(n)

    def retire(keep: NDArray[np.bool_], step: NDArray[np.float64] | None = None) -> None:
        nonlocal idx, out
        # Index arrays and np.take: several times faster than boolean masks on (k, n) rows.
        stay, gone = np.flatnonzero(keep), np.flatnonzero(~keep)
        if idx.size == n and gone.size >= stay.size:
            # The first and main retirement (usually all but a few points, together): the
            # state arrays become the output as they are, no gather and scatter of ~17
            # rows. A zero step leaves the points that stay bit for bit (_taylor_step);
            # they are copied out below and written back when they retire.
            if step is not None:
                _taylor_step(state, step)
            out = {k: state[k] for k in out}
        else:
            final = {k: np.take(state[k], gone, axis=-1) for k in out}
            if step is not None:
                _taylor_step(final, np.take(step, gone, axis=-1))
            for k, target in out.items():
                target[..., idx[gone]] = final[k]
        for k in state:
            state[k] = np.take(state[k], stay, axis=-1)
        idx = idx[stay]

    for _ in range(iters):
        uv, mu, hess = state["uv"], state["mu"], state["hess"]
        trial = np.clip(uv + _solve_step(uv, state["grad"], hess, mu, True), 0.0, 1.0)
        # Done: the step is below xtol or below the rounding of the parameters themselves
        # (coordinates ~1e7 from the origin carry ~1e-9 of noise: the steps never shrink
        # below it, and the points would iterate to the limit).
        speed = np.sqrt(np.maximum(np.maximum(hess[0], hess[2]), 1e-300))
        noise = 16.0 * _EPS * state["scale"] / speed
        step = np.abs(trial - uv).max(axis=0)
        moved = step > np.maximum(xtol, noise)
        # An undamped full Newton step this small is the last one, taken as the points
        # retire (see _taylor_step).
        last = moved & (step <= _TAYLOR_STEP) & (mu < 1e-6) & state["full"]
        keep = moved & ~last
        if 8 * (moved.size - int(np.count_nonzero(keep))) >= moved.size:
            retire(keep, np.where(last, trial - uv, 0.0))
            trial = np.take(trial, np.flatnonzero(keep), axis=1)
        elif not moved.all():
            # A few finished points stay put for one more (cheap) round rather than
            # compacting every array of the chunk for them.
            trial = np.where(moved, trial, state["uv"])
        if idx.size == 0:
            break
        new = _newton_terms(jet_fn(trial[0], trial[1]), state["p"])
        new["uv"] = trial
        # Accept any decrease, allowing for the rounding of |S - P|^2 itself.
        f, scale = state["f"], state["scale"]
        ok = new["f"] <= f + 4.0 * _EPS * scale * (np.sqrt(f) + _EPS * scale)
        if ok.all():
            state.update(new)
            state["mu"] = 0.1 * state["mu"]
        else:
            for k, value in new.items():
                state[k] = np.where(ok, value, state[k])
            state["mu"] = np.where(ok, 0.1 * state["mu"], np.maximum(10.0 * state["mu"], 1e-3))
            # A step that keeps failing at huge damping means a minimum up to rounding.
            if np.any(state["mu"] >= 1e12):
                retire(state["mu"] < 1e12)
    retire(np.zeros(idx.size, dtype=bool))
    return out


class _StartTable:
    """Nearest surface sample of every point by voxel lookup instead of a KD-tree query.

    The points' bounding box is cut into voxels of half the mean spacing of the samples,
    and each voxel keeps the sample nearest its centre (one KD-tree query per voxel, a few
    thousand). A point's sample is then its voxel's: within one voxel diagonal of its true
    nearest sample, which is start enough for Newton, at the cost of one binning per point
    (a query over 10^6 points cost about a third of the projection).
    """

    def __init__(
        self, tree: cKDTree, lo: NDArray[np.float64], size: float, dims: NDArray[np.int64]
    ) -> None:
        self.lo, self.scale, self.dims = lo, 1.0 / size, dims
        axes = [lo[k] + size * (np.arange(dims[k]) + 0.5) for k in range(len(dims))]
        centres = np.stack([a.reshape(-1) for a in np.meshgrid(*axes, indexing="ij")], axis=1)
        self.nearest = tree.query(centres, workers=-1)[1].astype(np.int64)
        self.strides = np.r_[np.cumprod(dims[::-1])[::-1][1:], 1].astype(np.int64)

    @classmethod
    def build(
        cls, tree: cKDTree, samples: NDArray[np.float64], pts: NDArray[np.float64]
    ) -> _StartTable | None:
        """The table for ``pts`` (N, D), or None when it would need over _MAX_VOXELS voxels
        or more than a quarter as many voxels as points (then the KD-tree query is cheaper).

        The table covers the samples' bounding box and a margin of a tenth of their spread
        (no pass over the points): a point beyond it starts from a border voxel's sample,
        which is no worse a start than a coarse grid's nearest sample for such a point.
        """
        spread = float(np.linalg.norm(np.ptp(samples, axis=0)))
        size = 0.5 * spread / np.sqrt(len(samples))
        if not size > 0:
            return None
        lo = samples.min(axis=0) - 0.1 * spread
        hi = samples.max(axis=0) + 0.1 * spread
        dims = np.floor((hi - lo) / size).astype(np.int64) + 1
        if float(np.prod(dims.astype(float))) > min(_MAX_VOXELS, 0.25 * len(pts)):
            return None
        return cls(tree, lo, size, dims)

    def lookup(self, pts: NDArray[np.float64]) -> NDArray[np.int64]:
        """Index of the start sample of each point (n, D)."""
        cell = np.zeros(len(pts), dtype=np.int64)
        for k in range(pts.shape[1]):
            idx = ((pts[:, k] - self.lo[k]) * self.scale).astype(np.int64)
            np.clip(idx, 0, self.dims[k] - 1, out=idx)
            cell += idx * self.strides[k]
        return self.nearest[cell]


def project_points(
    surface: Any, points: ArrayLike, *args: Any, **options: Any
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The ``(u, v)`` of the closest point on a parametric patch of each point (Sec. 5.2.3).

    :func:`closest_points` (same parameters) without the closest points themselves:
    returns ``params`` (N, 2), ``distances`` (N,) and ``outside`` (N,).
    """
    params, distances, outside, _ = closest_points(surface, points, *args, **options)
    return params, distances, outside


def closest_points(
    surface: Any,
    points: ArrayLike,
    grid: int = 32,
    iters: int = 20,
    *,
    margin: float = 1e-3,
    chunk: int = 20_000,
    xtol: float = 1e-13,
    workers: int = -1,
    initial: ArrayLike | None = None,
) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]
]:
    """Closest points on a parametric patch, and their ``(u, v)`` (Section 5.2.3).

    Parameters
    ----------
    surface : patch
        Anything with ``evaluate(u, v)``, ``derivatives(u, v)`` and
        ``second_derivatives(u, v)`` (or ``jet(u, v)`` returning all six at once), such as
        :class:`~pde2cad.surfaces.coons.BilinearCoons`, ``BicubicCoons`` or
        :class:`~pde2cad.surfaces.deformation.DeformedPatch`.
    points : (N, D) float
    grid : int
        The start is the nearest of ``(grid + 1)^2`` surface samples on a uniform (u, v)
        grid; raise it for strongly curved patches where a coarse sample could pick the wrong
        basin.
    iters : int
        Maximum Newton iterations (typically 3-6 are used).
    margin : float
        Parametric distance beyond [0, 1]^2 at which a point is flagged ``outside``.
    chunk : int
        Largest number of points processed together (bounds memory: about 2 kB per point in
        flight). With several threads the points are split into equal chunks of at most
        this size, a whole number per thread; a point's result does not depend on its chunk.
        The default keeps a chunk's ~40 rows in cache: 1e6 points cost 0.6 s instead of
        0.96 s (one thread) with chunks of 50,000.
    workers : int
        Threads working on chunks; -1 uses every core.
    xtol : float
        Stop when a step moves (u, v) by less than this.
    initial : (N, 2) float, optional
        Start parameters (clipped to [0, 1]^2) instead of the grid search, e.g. the
        parameters on a previous base patch when the surface changed only a little. Newton
        then finds the closest point of that basin: its distance bounds the global one from
        above.

    Returns
    -------
    params : (N, 2) float
        ``(u, v)`` in [0, 1]^2 of the closest point within the patch.
    distances : (N,) float
        ``|P - S(u, v)|``.
    outside : (N,) bool
        True where the unclamped closest point lies beyond [0, 1]^2 by more than ``margin``
        (estimated by one unconstrained Newton step from the clamped optimum): the point is
        past a side, so its parameter is the side's and its residual is not the surface's.
    closest : (N, D) float
        ``S(u, v)`` at ``params``, from the last Newton iterate: what evaluating the
        surface there gives (to about 1e-14 of the patch size), without that evaluation.

    Raises
    ------
    InputError
        Wrong shape, NaN/inf, or a surface without the needed methods.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2:
        raise InputError(f"points must have shape (N, D), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        bad = int(np.argmax(~np.all(np.isfinite(pts), axis=1)))
        raise InputError(f"points contain NaN or inf (first at row {bad}); drop those rows first")
    if grid < 1 or iters < 0 or chunk < 1:
        raise InputError(f"grid, chunk must be >= 1 and iters >= 0; got {grid}, {chunk}, {iters}")
    start_uv: NDArray[np.float64] | None = None
    if initial is not None:
        start_uv = np.asarray(initial, dtype=float)
        if start_uv.shape != (pts.shape[0], 2) or not np.all(np.isfinite(start_uv)):
            raise InputError(
                f"initial must be finite (u, v) of shape ({pts.shape[0]}, 2), one per point; "
                f"got shape {start_uv.shape}"
            )
        start_uv = np.clip(start_uv, 0.0, 1.0)
    jet_fn = _jet_function(surface)
    g = np.linspace(0.0, 1.0, grid + 1)
    gu, gv = (a.reshape(-1) for a in np.meshgrid(g, g, indexing="ij"))
    # The whole jet on the grid: every start is a grid sample, so the first Newton step
    # needs no surface evaluation of its own.
    grid_jet = tuple(np.ascontiguousarray(a) for a in jet_fn(gu, gv))
    samples = grid_jet[0].T
    if samples.shape[-1] != pts.shape[1]:
        raise InputError(
            f"points have dimension {pts.shape[1]} but the surface has {samples.shape[-1]}"
        )
    n = pts.shape[0]
    params = np.empty((n, 2))
    distances = np.empty(n)
    outside = np.zeros(n, dtype=bool)
    closest = np.empty_like(pts)
    if n == 0:
        return params, distances, outside, closest
    # Leave out samples where the patch degenerates (the collapsed side of a 3-sided patch,
    # S_u = 0): there the gradient along the side vanishes too, so a Newton start on the
    # apex would stay there. Points near it start one row in and still reach it.
    _, su, sv = grid_jet[:3]
    area2 = _dot(su, su) * _dot(sv, sv) - _dot(su, sv) ** 2
    usable = np.flatnonzero(area2 > 1e-16 * area2.max())
    if usable.size == 0:
        usable = np.arange(area2.size)
    gu, gv = gu[usable], gv[usable]
    # All six jet arrays as rows of one table: a start is one np.take of its columns.
    jet_table = np.ascontiguousarray(np.stack(grid_jet)[:, :, usable]).reshape(-1, usable.size)
    tree = cKDTree(samples[usable])
    table = _StartTable.build(tree, samples[usable], pts) if start_uv is None else None

    def run(start: int) -> None:
        part = slice(start, min(start + chunk, n))
        if start_uv is not None:
            uv0 = np.ascontiguousarray(start_uv[part].T)
            jet0 = jet_fn(uv0[0], uv0[1])
        else:
            if table is not None:
                idx = table.lookup(pts[part])
            else:
                # An approximate nearest sample (within 2x the true distance) is start
                # enough for Newton and halves the KD-tree time.
                idx = tree.query(pts[part], eps=1.0)[1]
            uv0 = np.stack([gu[idx], gv[idx]])
            jet0 = tuple(np.take(jet_table, idx, axis=1).reshape(6, pts.shape[1], -1))
        p = np.ascontiguousarray(pts[part].T)
        res = _project_chunk(jet_fn, p, uv0, jet0, iters, xtol)
        uv, f, grad, hess = res["uv"], res["f"], res["grad"], res["hess"]
        free = uv + _solve_step(uv, grad, hess, np.zeros(uv.shape[1]), False)
        # Only a coordinate held on a side can have its optimum beyond it.
        past = ((uv <= 0.0) & (free < -margin)) | ((uv >= 1.0) & (free > 1.0 + margin))
        params[part] = uv.T
        distances[part] = np.sqrt(f)
        outside[part] = np.any(past, axis=0)
        closest[part] = (p + res["lin"][: p.shape[0]]).T

    cores = (os.cpu_count() or 1) if workers == -1 else max(1, workers)
    if cores > 1 and n > _MIN_SPLIT:
        # Equal chunks, a whole number per thread: 83k points on 2 threads as 2 x 41.5k,
        # not 50k + 33k (each point's result does not depend on its chunk).
        rounds = -(-n // (cores * chunk))
        chunk = -(-n // (cores * rounds))
    starts = range(0, n, chunk)
    threads = min(len(starts), cores)
    if threads == 1:
        for start in starts:
            run(start)
    else:
        # numpy releases the GIL in its array loops, so chunks run in parallel on threads
        # (chunks write disjoint slices of the outputs).
        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(run, starts))
    return params, distances, outside, closest
