"""Merge adjacent pieces of a closed chain into one cubic wherever one fits (global pass).

Bisection places every break as far as the current piece reaches, and corner detection
forces a break at every sharp turn of the raster, so a loop can end up with pieces that one
cubic would cover: on jagged level sets of a height map nine breaks in ten sit on detected
"corners" that a single curve passes within the tolerance. This pass tests every pair of
neighbouring pieces of a closed loop at once (one batched fit per round), replaces the
best non-overlapping passing pairs by one cubic each, and repeats until no pair merges.

A merge removes the join between the two pieces; the joins at its ends keep their position
and, where they are G1, their tangent, so the neighbours stay tangent-continuous. Merging
the last piece with the first moves the loop's start (the start-point search of a loop
without corners). The test is that of the break-point search (points, edge midpoints and
the curve back to the points' polyline), so the symmetric tolerance still holds.

Two things are never merged away, though a cubic could pass within the tolerance: a
straight side (a line piece at least ``side`` long keeps its line, or a plate's straight
edge would bulge within the tolerance), and a crisp corner (a merge across a sharp join is
refused when the merged cubic bends there with a radius under ``min_radius``: within the
tolerance such a bend is a rounded-off corner, not the smooth curve the raster hid).
"""

from __future__ import annotations

import time

from typing import Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves.fit import CubicFit
from pde2cad.curves.piecewise import (
    PIECE_ROUNDS, ChainFit, DeadlineExceeded, _Fitter, end_tangent, start_tangent, straighten,
)


def merge_closed(
    chain: ChainFit,
    points: NDArray[np.float64],
    offset: int,
    tolerance: float,
    *,
    param_points: NDArray[np.float64] | None = None,
    method: str = "optimal",
    deadline: float | None = None,
    lines: bool = True,
    side: float = 8.0,
    min_radius: float | None = None,
    rounds: int = PIECE_ROUNDS,
) -> tuple[ChainFit, int]:
    """Merge neighbouring pieces of a closed chain while one cubic fits both.

    Steps: 1. describe each piece by its first point index on the loop, its length and
    whether the join at its start is sharp; 2. fit every pair of neighbours as one cubic
    with the outer joins' points and (G1) tangents, all pairs in one batch per kind of end
    constraint; 3. take the passing pairs, least error first, that share no piece; 4. repeat
    on the new pieces (failed pairs are remembered: their ends never change) until none
    merges; 5. make pieces straight where their chord fits (:func:`straighten`).

    Parameters
    ----------
    chain : ChainFit
        A closed chain as returned by :func:`pde2cad.curves.piecewise.fit_closed`: its
        ``breaks`` index ``np.roll(points, -offset)`` closed by its first point, and
        ``corners`` lists its sharp joins (0 is the closing join).
    points : (n, D) float
        The loop's points.
    offset : int
        Index in ``points`` of the chain's first point.
    tolerance : float
    param_points : (n, D) float, optional
        Denoised loop points for the parameterizations (default ``points``).
    method : str
        See :func:`pde2cad.curves.piecewise.fit_chain`.
    deadline : float, optional
        Raise :class:`DeadlineExceeded` once ``time.perf_counter()`` passes it.
    lines : bool
        Try straight pieces after merging.
    side : float
        Line pieces at least this long (chord, in the points' units) are straight sides
        and stay as they are.
    min_radius : float, optional
        Least bend radius of a cubic merged across a sharp join (default a quarter of the
        tolerance: a tighter bend turns within a fraction of the tolerance, a corner in
        disguise, and can hide a tiny self-intersecting loop).
    rounds : int
        Levenberg-Marquardt rounds per pair fit (see
        :func:`pde2cad.curves.piecewise.fit_chain`).

    Returns
    -------
    (ChainFit, offset)
        As :func:`fit_closed` returns them (the offset moves when the closing join goes).
    """
    n = len(points)
    k = len(chain.fits)
    if k < 2 or n < 4:
        return chain, offset
    twice = np.vstack([points, points, points[:1]])
    ptwice = twice if param_points is None else np.vstack([param_points, param_points, param_points[:1]])
    fitter = _Fitter(twice, tolerance, ptwice, method, rounds, midpoints=True)
    starts = (offset + chain.breaks[:-1]) % n
    lengths = np.diff(chain.breaks).astype(np.int64)
    sharp = np.isin(np.arange(k), chain.corners)
    fits, curves = list(chain.fits), [c for c in chain.curves]
    flags = list(chain.lines) or [False] * k
    failed: set[tuple[int, int]] = set()
    limits = (side, 0.25 * tolerance if min_radius is None else min_radius)
    while len(fits) >= 2:
        if deadline is not None and time.perf_counter() > deadline:
            raise DeadlineExceeded("the merge pass ran past its deadline")
        found = _passing_pairs(fitter, starts, lengths, sharp, curves, flags, failed, limits)
        if not found:
            break
        starts, lengths, sharp, fits, curves, flags = _apply(found, starts, lengths, sharp, fits, curves, flags, n)
    first = int(np.argmin(starts))
    order = np.r_[first : len(fits), 0:first]
    new_offset = int(starts[first])
    rel = (starts[order] - new_offset) % n
    out = ChainFit(
        np.stack([curves[j] for j in order]),
        [fits[j] for j in order],
        np.r_[rel, n].astype(np.int64),
        [int(i) for i in np.flatnonzero(sharp[order])],
    )
    out.lines = [flags[j] for j in order]
    if lines:
        ring = np.r_[new_offset:n, 0 : new_offset + 1]
        out = straighten(out, points[ring], tolerance, closed=True)
    return out, new_offset


def _passing_pairs(
    fitter: _Fitter,
    starts: NDArray[np.int64],
    lengths: NDArray[np.int64],
    sharp: NDArray[np.bool_],
    curves: list[NDArray[np.float64]],
    flags: list[bool],
    failed: set[tuple[int, int]],
    limits: tuple[float, float],
) -> list[tuple[int, CubicFit]]:
    """Pairs (index of the first piece, merged fit) that pass, not sharing a piece.

    The pair ``j`` is pieces ``j`` and ``j + 1`` (cyclic). Fits are batched per kind of end
    constraint (free or G1 at either end), since a batch shares that kind. Pairs with a
    straight side, and merges that round off a sharp join (bend radius under the limit),
    are refused (see the module docstring).
    """
    k = len(starts)
    side, min_radius = limits
    pairs = np.arange(k if k > 2 else 1)
    nxt = (pairs + 1) % k
    span = lengths[pairs] + lengths[nxt]
    chord = np.array([np.linalg.norm(c[3] - c[0]) for c in curves])
    straight = np.asarray(flags, bool) & (chord >= side)
    todo = ~(straight[pairs] | straight[nxt])
    todo &= np.array([(int(starts[j]), int(s)) not in failed for j, s in zip(pairs, span)], bool)
    g0 = ~sharp[pairs]
    g3 = ~sharp[(pairs + 2) % k]
    results: list[tuple[float, int, CubicFit]] = []
    for need0 in (False, True):
        for need3 in (False, True):
            sel = pairs[todo & (g0 == need0) & (g3 == need3)]
            if not sel.size:
                continue
            after = (sel + 1) % k
            p0s = np.stack([curves[j][0] for j in sel])
            p3s = np.stack([curves[j][3] for j in after])
            t0s = np.stack([_tangent(start_tangent(curves[j]), p0s[0]) for j in sel]) if need0 else None
            t3s = np.stack([_tangent(end_tangent(curves[j]), p0s[0]) for j in after]) if need3 else None
            out = fitter.fit_spans(starts[sel], starts[sel] + span[sel], p0s, p3s, t0s, t3s)
            corner = sharp[(sel + 1) % k] & (k > 2)
            bends = _min_radius(np.stack([f.ctrl for f, _ in out]))
            for j, (fit, good), at_corner, bend in zip(sel.tolist(), out, corner, bends):
                if good and at_corner and bend < min_radius:
                    failed.add((int(starts[j]), int(span[j])))
                elif good:
                    results.append((fit.max_error, j, fit))
                else:
                    failed.add((int(starts[j]), int(span[j])))
    results.sort(key=lambda r: r[0])
    used: set[int] = set()
    chosen = []
    for _, j, fit in results:
        a, b = j, (j + 1) % k
        if a in used or b in used:
            continue
        used.update((a, b))
        chosen.append((j, fit))
    return chosen


def _min_radius(ctrl: NDArray[np.float64], samples: int = 33) -> NDArray[np.float64]:
    """Least radius of curvature of each cubic (K, 4, D), sampled; inf for a straight one.

    Radius ``|C'|^3 / |C' x C''|`` with the cross product's norm from Lagrange's identity,
    so it works in any dimension.
    """
    t = np.linspace(0.0, 1.0, samples)[:, None]
    s = 1.0 - t
    d1 = 3.0 * np.diff(ctrl, axis=1)  # (K, 3, D)
    d2 = 6.0 * np.diff(ctrl, n=2, axis=1)  # (K, 2, D)
    v = np.einsum("sj,kjd->ksd", np.hstack([s * s, 2 * t * s, t * t]), d1)
    a = np.einsum("sj,kjd->ksd", np.hstack([s, t]), d2)
    vv = (v * v).sum(-1)
    cross2 = np.maximum(vv * (a * a).sum(-1) - (v * a).sum(-1) ** 2, 0.0)
    radius = np.divide(vv**1.5, np.sqrt(cross2), out=np.full_like(vv, np.inf), where=cross2 > 1e-18)
    radius[vv < 1e-18] = 0.0  # a cusp
    return radius.min(axis=1)


def _tangent(v: NDArray[np.float64] | None, like: NDArray[np.float64]) -> NDArray[np.float64]:
    """The tangent, or zeros for a degenerate piece (the merged cubic then starts with a cusp there)."""
    return np.zeros_like(like) if v is None else v


def _apply(found, starts, lengths, sharp, fits, curves, flags, n: int):
    """Replace each chosen pair by its merged piece; returns the new piece lists."""
    k = len(starts)
    merged = dict(found)
    drop = {(j + 1) % k for j in merged}
    new: tuple[list[Any], ...] = ([], [], [], [], [], [])
    for j in range(k):
        if j in drop:
            continue
        if j in merged:
            fit = merged[j]
            row = (starts[j], lengths[j] + lengths[(j + 1) % k], sharp[j], fit, fit.ctrl, False)
        else:
            row = (starts[j], lengths[j], sharp[j], fits[j], curves[j], flags[j])
        for lst, v in zip(new, row):
            lst.append(v)
    s, ln, sh, f, c, fl = new
    return np.asarray(s, dtype=np.int64) % n, np.asarray(ln, dtype=np.int64), np.asarray(sh, bool), f, c, fl
