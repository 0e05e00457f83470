"""Piecewise cubic Bézier fitting with break points found by bisection (Algorithm 1).

One curve takes the longest run of points it can fit within the tolerance; the next curve
starts where it stopped. The longest run is found by bisection (thesis Section 3.3) inside a
bracket found by doubling from the previous curve's length, which gives the same break point
as Algorithm 1 with far cheaper tests on long segments. Where a break point is not a corner,
the next curve starts along the previous curve's end tangent (G1 join).

Dimension-free: the same code fits 2D outlines and 3D boundary curves.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field

from typing import Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves import batchfit, bezier
from pde2cad.curves.fit import CubicFit, _unit
from pde2cad.curves.parameterize import METHODS
from pde2cad.errors import FitError, InputError

# Pieces keep at least this many points: fewer do not determine a cubic (the thesis's
# Fig. 3.5(d) shows the 3-point failure of min-error splitting).
MIN_POINTS = 4
# The test runs on the points (pixel vertices); samples of the boundary between them can sit a
# hair farther from the curve, so the test keeps a 2 % margin under the user's tolerance.
SAFETY = 0.98
# Closed loops of at most this many points (pixel perimeter) may close with one cubic.
TINY_LOOP = 40
# Fits whose maximum error is at most this factor over the tolerance get a minimax
# refinement (reweighted least squares) before they are rejected.
MINIMAX_RANGE = 1.4
# Candidate stops per batched step of the break-point search, and the first step's
# spread of lengths relative to the previous piece's.
_ROUND = 3
_SPREAD = np.array([0.6, 1.0, 1.5, 2.5])
# A bracket with at most this many stops left is fitted whole in one batch: the rounds of
# _ROUND stops that would close it (two or three sequential batches, each with its own
# minimax refits) then find their fits in the cache. More rows cost little next to the
# fixed cost of a batch while the rows stay few.
_EXHAUST = 8
# The break-point search tries these parameterizations (the two that win most often on
# pixel boundaries and smooth samples); the chosen piece is then refitted with all of them.
_SEARCH_METHODS = ("chord", "uniform")
#: Joint Levenberg-Marquardt rounds per piece fit (the minimax refits' count). The rounds
#: move the parameters freely, so past a few of them a cubic meets its points more closely
#: by straying from the polyline between them, which the piece test also bounds: of the
#: break search's candidates on icons the whole test passes 59.5 % at 3 rounds, 58.0 % at
#: 5 and 55.4 % at 8 (the points alone: 59.7, 61.7, 62.6 %). Smooth samples (3D
#: boundaries) pass their own, larger count.
PIECE_ROUNDS = 3
#: Largest turn (degrees) between a straight piece and the tangent of a G1 join next to it.
#: Not 8: short chords of round arcs (a 25-px circle at 1 px) passed, and their few-degree
#: kinks split a circle's DXF spline at a corner and show as facets on a laser cut. A real
#: straight edge that meets a round part at a G1 join turns by well under 2 degrees there.
LINE_KINK = 2.0


class DeadlineExceeded(FitError):
    """A fit passed the ``deadline`` (a :func:`time.perf_counter` value) it was given."""


@dataclass
class ChainFit:
    """Cubic pieces fitted to an ordered run of points.

    Attributes
    ----------
    curves : (K, 4, D) float
    fits : list of CubicFit
        One per curve, with per-point errors and the parameterization used.
    breaks : (K + 1,) int
        Index of each piece's first point, then the last index.
    corners : list of int
        Indices of ``breaks`` where the join is sharp (C0 only).
    lines : list of bool
        Per piece: True where it is a straight line segment (stored as the degree-elevated
        cubic ``p0, p0 + d/3, p0 + 2d/3, p3``); empty means no piece is.
    ok : bool
        Every piece passed the tolerance test (False only where even the shortest piece
        could not meet it under the G1 constraints; callers then refit with C0 joins).
    """

    curves: NDArray[np.float64]
    fits: list[CubicFit]
    breaks: NDArray[np.int64]
    corners: list[int] = field(default_factory=list)
    ok: bool = True
    lines: list[bool] = field(default_factory=list)

    @property
    def max_error(self) -> float:
        return max((f.max_error for f in self.fits), default=0.0)

    @property
    def mean_error(self) -> float:
        n = sum(len(f.errors) for f in self.fits)
        return float(sum(f.errors.sum() for f in self.fits) / n) if n else 0.0

    @property
    def methods(self) -> list[str]:
        return [f.method for f in self.fits]


def end_tangent(ctrl: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Unit tangent at the end of a cubic (None for a degenerate curve)."""
    for k in (2, 1, 0):
        v = ctrl[3] - ctrl[k]
        n = float(np.linalg.norm(v))
        if n > 1e-9:
            return v / n
    return None


def start_tangent(ctrl: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Unit tangent at the start of a cubic (None for a degenerate curve)."""
    back = end_tangent(ctrl[::-1])
    return None if back is None else -back


class _Fitter:
    """Shared state of one chain fit: points, tolerance and the batched piece test."""

    def __init__(
        self,
        points: NDArray[np.float64],
        tolerance: float,
        param_points: NDArray[np.float64],
        method: str,
        rounds: int = PIECE_ROUNDS,
        midpoints: bool = False,
    ) -> None:
        self.rounds = rounds
        self.midpoints = midpoints
        self.points = points
        self.tol = tolerance * SAFETY
        self.param_points = param_points
        self.all_names = list(METHODS) if method == "optimal" else [method]
        self.names = [m for m in self.all_names if m in _SEARCH_METHODS] or self.all_names

    def fit_many(
        self, i: int, stops: NDArray[np.int64], p0, p3s, tan0, tan3s, names: list[str] | None = None
    ) -> list[tuple[CubicFit, bool]]:
        """Fit points[i..stop] for every stop at once (:meth:`fit_spans` from one start).

        Parameters
        ----------
        stops : (m,) int, each > i
        p3s : (m, D) float
            End point of each candidate.
        tan3s : (m, D) float or None
            End tangent of each candidate.
        """
        stops = np.asarray(stops, dtype=np.int64)
        m = len(stops)
        p0s = np.broadcast_to(np.asarray(p0, dtype=float), (m, self.points.shape[1]))
        tan0s = None if tan0 is None else np.broadcast_to(np.asarray(_unit(tan0), dtype=float), p0s.shape)
        return self.fit_spans(np.full(m, i, dtype=np.int64), stops, p0s, p3s, tan0s, tan3s, names)

    def fit_spans(
        self, starts: NDArray[np.int64], stops: NDArray[np.int64], p0s, p3s, tan0s, tan3s,
        names: list[str] | None = None,
    ) -> list[tuple[CubicFit, bool]]:
        """Fit points[start..stop] for every span at once, each with every parameterization.

        Steps: 1. pad the candidate runs into one batch (candidates x parameterizations);
        2. fit them all (:func:`pde2cad.curves.batchfit.fit_batch`); 3. minimax-refine those
        just over the tolerance; 4. test (point errors and curve-to-polyline distance);
        5. per candidate keep the best fit: passing first, then the least maximum error.

        Parameters
        ----------
        starts, stops : (m,) int, stops > starts
        p0s, p3s : (m, D) float
            End points of each candidate.
        tan0s, tan3s : (m, D) float or None
            End tangents of each candidate (None: free at that end, for all candidates; a
            row of NaN: free for that candidate).
        """
        names = self.names if names is None else names
        starts = np.asarray(starts, dtype=np.int64)
        stops = np.asarray(stops, dtype=np.int64)
        searched = [n for n in names if n in self.names]
        if 0 < len(searched) < len(names):
            return self._fit_spans_split(starts, stops, p0s, p3s, tan0s, tan3s, names, searched)
        keys = self._keys(starts, stops, p0s, p3s, tan0s, tan3s, names)
        out: list[tuple[CubicFit, bool] | None] = [_CACHE.get(k) for k in keys]
        todo = np.array([j for j, hit in enumerate(out) if hit is None], dtype=np.int64)
        if todo.size:
            fresh = self._fit_spans(starts[todo], stops[todo], _rows(p0s, todo), _rows(p3s, todo),
                                    _rows(tan0s, todo), _rows(tan3s, todo), names)
            for j, result in zip(todo.tolist(), fresh):
                out[j] = result
                _CACHE.put(keys[j], result)
        return out  # type: ignore[return-value]

    def _fit_spans_split(
        self, starts, stops, p0s, p3s, tan0s, tan3s, names: list[str], searched: list[str],
    ) -> list[tuple[CubicFit, bool]]:
        """:meth:`fit_spans` with ``names``, the ``searched`` ones fitted apart from the rest.

        The break search has fitted most spans with the search parameterizations already
        (the cache holds them), so only the other parameterizations cost a fit. The pick is
        :meth:`_fit_spans`'s: passing first, then the least maximum error, then the earlier
        name of ``names``."""
        rest = [n for n in names if n not in searched]
        both = zip(self.fit_spans(starts, stops, p0s, p3s, tan0s, tan3s, searched),
                   self.fit_spans(starts, stops, p0s, p3s, tan0s, tan3s, rest))
        return [min(pair, key=lambda r: (not r[1], r[0].max_error, names.index(r[0].method))) for pair in both]

    def cached(self, start: int, stop: int, p0, tan0, p3, tan3) -> bool:
        """Whether the fit of points[start..stop] with these ends is in the cache."""
        rows = [None if v is None else np.asarray(v, dtype=float)[None]
                for v in (p0, p3, None if tan0 is None else _unit(tan0), tan3)]
        return _CACHE.get(self._keys(np.array([start]), np.array([stop]), rows[0], rows[1], rows[2], rows[3],
                                     self.names)[0]) is not None

    def _keys(self, starts, stops, p0s, p3s, tan0s, tan3s, names: list[str]) -> list[bytes]:
        """One digest per span of everything its fit depends on: the span's points and
        parameter points, its end points and tangents, and the fitter's settings."""
        head = repr((self.tol, self.rounds, self.midpoints, tuple(names))).encode()
        m = len(stops)
        ends = [np.asarray(v, dtype=float).reshape(m, -1) for v in (p0s, p3s, tan0s, tan3s) if v is not None]
        ends_bytes = np.ascontiguousarray(np.concatenate(ends, axis=1)) if ends else None
        # Per row: which ends are free (None, or a NaN row), and the tangents of the others
        # only, so a row keys alike whether it was fitted alone or in a mixed batch.
        free0 = np.ones(m, bool) if tan0s is None else np.isnan(np.asarray(tan0s, dtype=float).reshape(m, -1)[:, 0])
        free3 = np.ones(m, bool) if tan3s is None else np.isnan(np.asarray(tan3s, dtype=float).reshape(m, -1)[:, 0])
        dim = self.points.shape[1]
        keys = []
        for j, (a, b) in enumerate(zip(starts.tolist(), stops.tolist())):
            h = hashlib.blake2b(head, digest_size=16)
            h.update(f"{bool(free0[j])}{bool(free3[j])}".encode())
            h.update(self.points[a : b + 1].tobytes())
            h.update(self.param_points[a : b + 1].tobytes())
            if ends_bytes is not None:
                row = ends_bytes[j]
                if tan0s is not None and free0[j]:
                    row = np.r_[row[: 2 * dim], row[3 * dim :]]
                if tan3s is not None and free3[j]:
                    row = row[:-dim]
                h.update(np.ascontiguousarray(row).tobytes())
            keys.append(h.digest())
        return keys

    def _fit_spans(
        self, starts: NDArray[np.int64], stops: NDArray[np.int64], p0s, p3s, tan0s, tan3s, names: list[str],
    ) -> list[tuple[CubicFit, bool]]:
        """:meth:`fit_spans` without the cache."""
        m, nm = len(stops), len(names)
        lengths = stops - starts + 1
        rows = np.minimum(starts[:, None] + np.arange(int(lengths.max()))[None, :], stops[:, None])
        pts = np.tile(self.points[rows], (nm, 1, 1))
        valid = np.tile(np.arange(rows.shape[1])[None, :] < lengths[:, None], (nm, 1))
        ppts = self.param_points[rows]
        t = np.concatenate([batchfit.parameters(name, ppts, lengths) for name in names])
        batch = batchfit.Batch(
            pts, valid, np.tile(np.asarray(p0s, dtype=float), (nm, 1)), np.tile(np.asarray(p3s, dtype=float), (nm, 1)),
            None if tan0s is None else np.tile(_unit_or_free(tan0s), (nm, 1)),
            None if tan3s is None else np.tile(_unit_or_free(tan3s), (nm, 1)),
        )
        ctrl, t, errors = batchfit.fit_batch(batch, t, self.rounds)
        worst = errors.max(axis=1)
        near = (worst > self.tol) & (worst <= MINIMAX_RANGE * self.tol)
        if near.any():
            sub = _take(batch, near)
            ctrl[near], t[near], errors[near] = batchfit.minimax_batch(sub, ctrl[near], t[near], errors[near])
            worst = errors.max(axis=1)
        ok = worst <= self.tol
        if self.midpoints and ok.any():
            ok[ok] = batchfit.midpoint_errors(ctrl[ok], _take(batch, ok), t[ok]) <= self.tol
        if ok.any():
            ok[ok] = batchfit.curve_to_polyline_batch(ctrl[ok], _take(batch, ok), t[ok]) <= self.tol
        # 5. best per candidate: rows are method-major, candidate j at j, m + j, 2m + j, ...
        score = np.where(ok, worst - 1e9, worst).reshape(nm, m)
        pick = np.argmin(score, axis=0) * m + np.arange(m)
        out = []
        for j, b in enumerate(pick):
            n_j = int(lengths[j])
            fit = CubicFit(_frozen(ctrl[b].copy()), _frozen(t[b, :n_j].copy()), _frozen(errors[b, :n_j].copy()),
                           names[b // m])
            out.append((fit, bool(ok[b])))
        return out


def _frozen(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a`` made read-only: cached fits are shared by every caller that asks again."""
    a.flags.writeable = False
    return a


def _rows(v, rows: NDArray[np.int64]):
    """Rows ``rows`` of a per-candidate array (None stays None)."""
    return None if v is None else np.asarray(v, dtype=float)[rows]


class _FitCache:
    """Fits already made, by span digest (see :meth:`_Fitter._keys`), least recently used
    dropped first once they hold more than :data:`_CACHE_POINTS` points in all.

    One vectorize call fits the same span with the same ends several times (the corner-forced
    and the free loop fit share their first runs, G1 sweeps retry unchanged neighbours, the C0
    fallback refits what the G1 pass tried): about a third of all spans on glyphs.
    """

    def __init__(self, max_points: int) -> None:
        self.max_points = max_points
        self.points = 0
        self.items: OrderedDict[bytes, tuple[CubicFit, bool]] = OrderedDict()

    def clear(self) -> None:
        self.items.clear()
        self.points = 0

    def get(self, key: bytes) -> tuple[CubicFit, bool] | None:
        hit = self.items.get(key)
        if hit is not None:
            self.items.move_to_end(key)
        return hit

    def put(self, key: bytes, value: tuple[CubicFit, bool]) -> None:
        self.items[key] = value
        self.points += len(value[0].t)
        while self.points > self.max_points and self.items:
            _, old = self.items.popitem(last=False)
            self.points -= len(old[0].t)


#: Points (parameters + errors, 16 bytes each) the fit cache may hold: ~32 MB.
_CACHE_POINTS = 2_000_000
_CACHE = _FitCache(_CACHE_POINTS)


def clear_fit_cache() -> None:
    """Forget the fits made so far (each vectorize call starts afresh, so its time and
    memory do not depend on what ran before)."""
    _CACHE.clear()


def _unit_rows(v: NDArray[np.float64]) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 1e-12)


def _unit_or_free(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`_unit_rows`, rows of NaN (free ends) kept NaN."""
    u = _unit_rows(v)
    u[np.isnan(np.asarray(v, dtype=float)[:, 0])] = np.nan
    return u


def _ends(rows: list[Any], dim: int) -> NDArray[np.float64] | None:
    """Per-piece end tangents (None: free) as one array with NaN rows for the free ends,
    or None when every end is free."""
    if all(r is None for r in rows):
        return None
    return np.stack([np.full(dim, np.nan) if r is None else np.asarray(r, dtype=float) for r in rows])


def _take(batch: batchfit.Batch, rows: NDArray[np.bool_]) -> batchfit.Batch:
    return batchfit.Batch(
        batch.points[rows], batch.valid[rows], batch.p0[rows], batch.p3[rows],
        None if batch.tan0 is None else batch.tan0[rows], None if batch.tan3 is None else batch.tan3[rows],
    )


def tangents(points: NDArray[np.float64], k: int = 2) -> NDArray[np.float64]:
    """Unit tangents of an ordered run by central differences over +-k points (one-sided at
    the ends). Returns (n, D)."""
    n = len(points)
    idx = np.arange(n)
    fwd = points[np.minimum(idx + k, n - 1)] - points[np.maximum(idx - k, 0)]
    norm = np.linalg.norm(fwd, axis=1, keepdims=True)
    return np.divide(fwd, norm, out=np.zeros_like(fwd), where=norm > 1e-12)


def fit_chain(
    points: NDArray[np.float64],
    tolerance: float,
    *,
    p_start: NDArray[np.float64] | None = None,
    p_end: NDArray[np.float64] | None = None,
    tan_start: NDArray[np.float64] | None = None,
    tan_end: NDArray[np.float64] | None = None,
    g1: bool = True,
    param_points: NDArray[np.float64] | None = None,
    join_tangents: NDArray[np.float64] | None = None,
    method: str = "optimal",
    rounds: int = PIECE_ROUNDS,
    c0_fallback: bool = True,
    max_pieces: int | None = None,
    deadline: float | None = None,
    edge_midpoints: bool = False,
    free_joins: bool = True,
    prefer_breaks: NDArray[np.bool_] | None = None,
    corner_points: NDArray[np.bool_] | None = None,
) -> ChainFit:
    """Fit an open run of ordered points with the fewest cubics within ``tolerance``.

    Parameters
    ----------
    points : (n, D) float, n >= 2
    tolerance : float
        Maximum distance from every point to the curves (and from the curves back to the
        points' polyline), in the points' units.
    p_start, p_end : (D,) float, optional
        Exact end points of the chain (default the first and last point).
    tan_start, tan_end : (D,) float, optional
        Tangent directions the chain must start / end with.
    g1 : bool
        Join consecutive pieces G1 (default): a break point is placed on ``param_points``
        (a denoised copy of the points) and both pieces take the tangent there. Without it
        joins are C0 at the raw points, as in the thesis.
    param_points : (n, D) float, optional
        Denoised points, used for the parameterizations and as join positions (default
        ``points``).
    join_tangents : (n, D) float, optional
        Unit tangents at the points for G1 joins (default: central differences of
        ``param_points``).
    method : str
        "optimal" (per piece, the parameterization with the least error) or one name of
        :data:`pde2cad.curves.parameterize.METHODS`.
    rounds : int
        Newton reparameterization rounds per fit; a few suffice for noisy pixel data, smooth
        samples (3D boundaries) gain accuracy from more.
    c0_fallback : bool
        When a G1 piece cannot meet the tolerance, refit the chain with C0 joins (default).
        Callers that have a plan B of their own (symmetric fits) switch it off.
    max_pieces : int, optional
        Give up (returning ``ok=False``, its pieces not refined) once more than this many
        pieces, plus one that reaches the end, are needed.
    deadline : float, optional
        Raise :class:`DeadlineExceeded` once ``time.perf_counter()`` passes it.
    edge_midpoints : bool
        Also hold the tolerance at the midpoints between consecutive points (pixel
        boundaries: the middle of a 1-px tip edge can be farther than both its ends).
    free_joins : bool
        With ``g1``, first place the breaks as C0 pieces reach and fit each join's tangent
        as a free unknown shared by both pieces (:func:`g1_joins`); only where that fails,
        search breaks with the tangents of ``join_tangents`` fixed. A G1 join then costs
        no extra curve wherever a G1 fit exists at the C0 breaks.
    prefer_breaks : (n,) bool, optional
        C0 joins only: a break that is not on such a point moves back to the last one in
        the final third of its piece, where one passes.
    corner_points : (n,) bool, optional
        With ``free_joins``: points where a join may stay C0 besides the kinks (detected
        corners).

    Returns
    -------
    ChainFit
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or len(pts) < 2:
        raise InputError(f"a curve fit needs an (n, D) array with n >= 2 points, got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError("points contain NaN or inf; remove those rows before fitting")
    if not tolerance > 0:
        raise InputError(f"tolerance must be > 0, got {tolerance}")
    ppts = pts if param_points is None else np.asarray(param_points, dtype=float)
    if g1:
        joins = ppts
        jtan = tangents(ppts) if join_tangents is None else np.asarray(join_tangents, dtype=float)
    else:
        joins, jtan = pts, None
    fitter = _Fitter(pts, tolerance, ppts, method, rounds, edge_midpoints)
    if g1 and free_joins:
        # Breaks where C0 pieces reach, then one shared tangent per join (see g1_joins).
        # C0 breaks go to kinks where they can (those joins may stay C0).
        kinks = _kinks(pts, np.arange(len(pts)), kink_reach(tolerance))
        if corner_points is not None:
            kinks |= np.asarray(corner_points, dtype=bool)
        c0 = fit_chain(pts, tolerance, p_start=p_start, p_end=p_end, tan_start=tan_start, tan_end=tan_end,
                       g1=False, param_points=ppts, method=method, rounds=rounds, max_pieces=max_pieces,
                       deadline=deadline, edge_midpoints=edge_midpoints, prefer_breaks=kinks)
        joined = g1_joins(fitter, c0, tan_start, tan_end, kinks) if c0.ok else None
        if joined is not None:
            return joined
        if corner_points is not None and np.any(corner_points[1:-1]):
            # No G1 fit at the C0 breaks: the corners become forced breaks after all.
            return _split_at_corners(pts, tolerance, np.flatnonzero(corner_points[1:-1]) + 1, dict(
                p_start=p_start, p_end=p_end, tan_start=tan_start, tan_end=tan_end, param_points=ppts,
                join_tangents=join_tangents, method=method, rounds=rounds, c0_fallback=c0_fallback,
                deadline=deadline, edge_midpoints=edge_midpoints))
    end = len(pts) - 1
    start = 0
    first_p = pts[0] if p_start is None else np.asarray(p_start, dtype=float)
    last_p = pts[end] if p_end is None else np.asarray(p_end, dtype=float)
    tan = None if tan_start is None else np.asarray(tan_start, dtype=float)
    final_tan = None if tan_end is None else np.asarray(tan_end, dtype=float)
    pieces: list[CubicFit] = []
    breaks = [0]
    corners: list[int] = []
    guess = 32
    p0 = first_p
    spans: list[tuple[Any, ...]] = []
    oks: list[bool] = []
    gave_up = False
    while start < end:
        if deadline is not None and time.perf_counter() > deadline:
            raise DeadlineExceeded("the fit ran past its deadline")
        if max_pieces is not None and len(pieces) >= max_pieces:
            # The last piece allowed must reach the end: only the whole rest is tested (the
            # search would reach the end just when the whole rest passes).
            fit, ok = _test(fitter, start, [end], p0, tan, last_p[None], None if final_tan is None else final_tan[None])[0]
            if not ok:
                pieces.append(fit)
                gave_up = True
                break
        stop, fit, ok = _longest_prefix(fitter, start, end, p0, tan, joins, jtan, guess, (last_p, final_tan))
        if stop < end and prefer_breaks is not None and not prefer_breaks[stop]:
            stop, fit, ok = _snap_to_kink(fitter, start, stop, fit, ok, p0, tan, joins, prefer_breaks)
        if stop < end and end - stop < MIN_POINTS - 1:
            # Leave the last piece enough points to be determined, if a slightly shorter
            # piece still passes (fit-ability is only nearly monotone in the length).
            cands = np.arange(end - (MIN_POINTS - 1), max(start + MIN_POINTS - 2, end - 2 * MIN_POINTS), -1)
            if cands.size:
                found = _test(fitter, start, cands, p0, tan, joins[cands], None if jtan is None else jtan[cands])
                passing = [(c, f) for c, (f, good) in zip(cands.tolist(), found) if good]
                if passing:
                    stop, fit = passing[0]
                    ok = True
        p3 = last_p if stop == end else joins[stop]
        t3 = final_tan if stop == end else (None if jtan is None else jtan[stop])
        spans.append((start, stop, p0, p3, tan, t3))
        oks.append(ok)
        pieces.append(fit)
        breaks.append(stop)
        guess = max(stop - start, MIN_POINTS)
        if stop < end and jtan is None:
            corners.append(len(pieces))
        tan = t3 if stop < end else None
        p0 = p3
        start = stop
    if len(fitter.all_names) > len(fitter.names) and not gave_up:
        pieces, oks[: len(spans)] = _refit_all_names(fitter, spans, pieces, oks[: len(spans)])
    all_ok = all(oks) and not gave_up
    curves = np.stack([f.ctrl for f in pieces]) if pieces else np.zeros((0, 4, pts.shape[1]))
    chain = ChainFit(curves, pieces, np.asarray(breaks, dtype=np.int64), corners, all_ok)
    if not all_ok and g1 and c0_fallback:
        # Below about half a pixel a staircase leaves G1 joins no room: fall back to C0 joins
        # on the points themselves, where a two-point piece is exact, so the tolerance holds.
        fallback = fit_chain(
            pts, tolerance, p_start=p_start, p_end=p_end, g1=False, param_points=ppts,
            method=method, rounds=rounds, deadline=deadline, edge_midpoints=edge_midpoints,
        )
        if fallback.ok or fallback.max_error < chain.max_error:
            return fallback
    return chain


def _refit_all_names(
    fitter: _Fitter, spans: list[tuple[Any, ...]], fits: list[CubicFit], oks: list[bool]
) -> tuple[list[CubicFit], list[bool]]:
    """Each piece's fit replaced by its fit with every parameterization where that is at
    least as good (passing first, then the least maximum error).

    ``spans`` holds each piece's (start, stop, p0, p3, tan0, tan3); the pieces are refitted
    together, in one batch, after the break search has placed them
    all (the search does not depend on the refits)."""
    fits, oks = list(fits), list(oks)
    dim = fitter.points.shape[1]
    res = fitter.fit_spans(
        np.array([r[0] for r in spans]), np.array([r[1] for r in spans]),
        np.stack([r[2] for r in spans]).reshape(-1, dim), np.stack([r[3] for r in spans]).reshape(-1, dim),
        _ends([r[4] for r in spans], dim), _ends([r[5] for r in spans], dim), fitter.all_names,
    )
    for i, (best, best_ok) in enumerate(res):
        if (best_ok, -best.max_error) >= (oks[i], -fits[i].max_error):
            fits[i], oks[i] = best, best_ok
    return fits, oks


#: Shared join tangents tried per sweep, as blends ``(1 - w) a + w b`` of the two C0
#: pieces' own tangents ``a`` (ending) and ``b`` (starting) there; w outside [0, 1] turns
#: past both.
_BLENDS = np.array([-0.5, 0.0, 0.5, 1.0, 1.5])
_SWEEPS = 2


def g1_joins(fitter: _Fitter, c0: ChainFit, tan_start, tan_end, sharp_ok: NDArray[np.bool_]) -> ChainFit | None:
    """Make the interior joins of a C0 chain G1 at the same break points, or None.

    The tangent at each join is a free unknown shared by the two pieces there. A join
    stays C0 only where ``sharp_ok`` (per point) allows it and no G1 tangent passes:
    detected corners, and kinks where the points turn by :data:`KINK_ANGLE` or more within
    twice the tolerance on either side (a corner at the tolerance's scale, such as the
    steps of an upscaled staircase).
    Steps: 1. start each join from the mean of its two C0 tangents; 2. red-black sweeps:
    for all odd joins at once (then all even ones), refit both neighbouring pieces for
    every tangent of :data:`_BLENDS` (the other ends held) and keep the tangent that passes
    with the least error (a kink with none keeps C0: free tangents); 3. refit every piece
    with the final tangents and all parameterizations; None unless every piece passes.
    """
    k = len(c0.fits)
    if k < 2:
        return c0
    curves, breaks = c0.curves, c0.breaks
    a = np.array([end_tangent(c) if end_tangent(c) is not None else np.zeros(curves.shape[2]) for c in curves[:-1]])
    b = np.array([start_tangent(c) if start_tangent(c) is not None else np.zeros(curves.shape[2]) for c in curves[1:]])
    theta = _unit_rows(a + b)  # (k - 1,) joins 1..k-1
    kink = sharp_ok[breaks[1:-1]]
    cusp = np.linalg.norm(theta, axis=1) < 0.5  # the pieces leave the join in opposite directions
    if np.any(cusp & ~kink):
        return None
    theta[cusp] = np.nan
    for _ in range(_SWEEPS):
        settled = True
        for parity in (1, 0):
            joins = np.arange(1, k)[np.arange(1, k) % 2 == parity]
            if joins.size:
                theta[joins - 1], found = _best_tangents(fitter, c0, theta, joins, a, b, tan_start, tan_end, kink)
                settled &= bool(found.all())
        if settled:  # every join found a passing tangent: the final refit checks them together
            break
    fits = _fit_pieces(fitter, c0, theta, np.arange(k), None, None, tan_start, tan_end, fitter.all_names)
    if not all(good for _, good in fits):
        return None
    sharp = [int(j) for j in np.flatnonzero(np.isnan(theta[:, 0])) + 1]
    return ChainFit(np.stack([f.ctrl for f, _ in fits]), [f for f, _ in fits], breaks.copy(), sharp, True)


#: Turn (degrees) of the points within twice the tolerance either side of a join above
#: which the join may stay C0 (the corner angle of :mod:`pde2cad.image.corners`).
KINK_ANGLE = 50.0


def kink_reach(tolerance: float) -> int:
    """Points either side over which a kink is measured: twice the tolerance, at least 2."""
    return max(2, int(round(2.0 * tolerance)))


def _kinks(points: NDArray[np.float64], at: NDArray[np.int64], reach: int) -> NDArray[np.bool_]:
    """Per index in ``at``: the chords to the points ``reach`` back and ahead turn by at
    least :data:`KINK_ANGLE` (ends clipped to the run)."""
    n = len(points)
    u = points[at] - points[np.maximum(at - reach, 0)]
    v = points[np.minimum(at + reach, n - 1)] - points[at]
    cos = (u * v).sum(axis=1) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-12)
    return cos <= np.cos(np.radians(KINK_ANGLE))


def _best_tangents(fitter: _Fitter, c0: ChainFit, theta, joins, a, b, tan_start, tan_end, kink):
    """For each join (1..k-1) in ``joins``, the blend tangent that lets both its pieces pass
    with the least maximum error; where none passes, free tangents (NaN) at a kink, else
    the current one. Also returns which joins found a passing tangent."""
    m = len(_BLENDS)
    cand = _unit_rows(((1.0 - _BLENDS)[None, :, None] * a[joins - 1, None] + _BLENDS[None, :, None] * b[joins - 1, None]).reshape(-1, a.shape[1]))
    rep = np.repeat(joins, m)
    # Both sides of every join in one batch: the left pieces end on the candidate, the
    # right ones start on it.
    k = len(c0.fits)
    dim = a.shape[1]
    theta0 = [tan_start if j == 0 else theta[j - 1] for j in rep - 1] + list(cand)
    theta3 = list(cand) + [tan_end if j == k - 1 else theta[j] for j in rep]
    both = _fit_pieces(fitter, c0, theta, np.r_[rep - 1, rep], theta0, theta3, tan_start, tan_end)
    left, right = both[: len(rep)], both[len(rep) :]
    err = np.array([max(fl.max_error, fr.max_error) for (fl, _), (fr, _) in zip(left, right)])
    good = np.array([gl and gr for (_, gl), (_, gr) in zip(left, right)])
    err = np.where(good & (np.linalg.norm(cand, axis=1) > 0.5), err, np.inf).reshape(-1, m)
    pick = np.argmin(err, axis=1)
    found = np.isfinite(err[np.arange(len(joins)), pick])
    new = cand.reshape(-1, m, a.shape[1])[np.arange(len(joins)), pick]
    keep = np.where(kink[joins - 1, None], np.nan, theta[joins - 1])
    return np.where(found[:, None], new, keep), found


def _fit_pieces(fitter: _Fitter, c0: ChainFit, theta, pieces, start_tan, end_tan, tan_start, tan_end, names=None):
    """Fit C0 chain pieces at their break points with join tangents ``theta`` (joins 1..k-1)
    or the overrides ``start_tan`` / ``end_tan`` (one row per piece); chain ends keep
    ``tan_start`` / ``tan_end`` (None: free). One batch for every kind of end constraint."""
    k = len(c0.fits)
    dim = c0.curves.shape[2]
    t0 = [None if j == 0 and tan_start is None else (np.asarray(tan_start, float) if j == 0 else theta[j - 1]) for j in pieces]
    t3 = [None if j == k - 1 and tan_end is None else (np.asarray(tan_end, float) if j == k - 1 else theta[j]) for j in pieces]
    if start_tan is not None:
        t0 = list(start_tan)
    if end_tan is not None:
        t3 = list(end_tan)
    js = np.asarray(pieces, dtype=np.int64)
    # NaN rows: a C0 join, free; all kinds of end constraint in one batch.
    return fitter.fit_spans(c0.breaks[js], c0.breaks[js + 1], c0.curves[js, 0], c0.curves[js, 3],
                            _ends(t0, dim), _ends(t3, dim), names)


def _split_at_corners(pts: NDArray[np.float64], tolerance: float, cuts: NDArray[np.int64], kw: dict[str, Any]) -> ChainFit:
    """:func:`fit_chain` of each run between the ``cuts`` (C0 joins there), joined in order.

    ``kw`` holds the whole run's options; end points and tangents apply to its ends only,
    per-point arrays are sliced."""
    bounds = np.r_[0, cuts, len(pts) - 1]
    curves: list[Any] = []
    fits: list[Any] = []
    breaks: list[Any] = [0]
    corners: list[int] = []
    flags: list[Any] = []
    ok = True
    for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        first, last = j == 0, j == len(bounds) - 2
        part: dict[str, Any] = {key: (v[a : b + 1] if isinstance(v, np.ndarray) and v.ndim == 2 and len(v) == len(pts) else v)
                for key, v in kw.items()}
        part.update(p_start=kw["p_start"] if first else None, p_end=kw["p_end"] if last else None,
                    tan_start=kw["tan_start"] if first else None, tan_end=kw["tan_end"] if last else None)
        chain = fit_chain(pts[a : b + 1], tolerance, g1=True, **part)
        if not first:
            corners.append(len(fits))
        corners.extend(len(fits) + c for c in chain.corners if c != 0)
        curves.append(chain.curves)
        fits.extend(chain.fits)
        flags.extend(chain.lines or [False] * len(chain.fits))
        breaks.extend(int(a) + chain.breaks[1:])
        ok = ok and chain.ok
    out = ChainFit(np.concatenate(curves), fits, np.asarray(breaks, dtype=np.int64), corners, ok)
    out.lines = flags if any(flags) else []
    return out


def _snap_to_kink(fitter: _Fitter, start: int, stop: int, fit: CubicFit, ok: bool, p0, tan, joins, prefer):
    """The piece start..stop moved back to end on the last preferred point in its final
    third, when that shorter piece passes; else the piece as it was."""
    lo = start + max(MIN_POINTS - 1, (2 * (stop - start)) // 3)
    cand = np.flatnonzero(prefer[lo:stop]) + lo
    if not ok or not cand.size:
        return stop, fit, ok
    c = int(cand[-1])
    new, good = _test(fitter, start, [c], p0, tan, joins[c][None], None)[0]
    return (c, new, True) if good else (stop, fit, ok)


def _test(fitter: _Fitter, start: int, stops, p0, tan, p3s, tan3s) -> list[tuple[CubicFit, bool]]:
    return fitter.fit_many(start, np.asarray(stops, dtype=np.int64), p0, p3s, tan, tan3s)


def _longest_prefix(
    fitter: _Fitter, start: int, end: int, p0: NDArray[np.float64], tan, joins, jtan, guess: int, tail=None,
) -> tuple[int, CubicFit, bool]:
    """Largest stop in (start, end] such that points[start..stop] pass the test.

    ``tail`` (end point, end tangent or None) are the ends of the whole rest start..end,
    taken when it passes; None: ``end`` is known to fail.
    Algorithm 1's bisection, with many candidates per step: 0. test the whole rest, in the
    first batch when the spread reaches ``end`` (no longer rows, one batch less); 1. test
    a spread of lengths around ``guess`` (the previous piece's) in one batch; 2. keep the
    longest passing one as
    the lower bracket and the shortest failing one above it as the upper; 3. test
    ``_ROUND`` evenly spaced stops inside the bracket, again in one batch, until it closes.
    Each batch shrinks the bracket about ninefold, so a few batches replace ~10 sequential
    fits. 4. If even the shortest regular piece fails, shorten down to two points (a
    straight piece, exact on its own points when its ends are free).
    """

    def test(cands: NDArray[np.int64]) -> list[tuple[CubicFit, bool]]:
        return _test(fitter, start, cands, p0, tan, joins[cands], None if jtan is None else jtan[cands])

    lo = max(start + 1, min(start + MIN_POINTS - 1, end - 1))
    spread = start + np.round(max(guess, MIN_POINTS - 1) * _SPREAD).astype(np.int64)
    cands = np.unique(np.clip(np.r_[lo, spread], lo, end - 1))
    first = None
    if tail is not None:
        fold = (lo < end and spread[-1] >= end and (tail[1] is None) == (jtan is None)
                and not fitter.cached(start, end, p0, tan, tail[0], tail[1]))
        rows = np.r_[cands, end] if fold else np.array([end])
        p3s = np.vstack([joins[rows[:-1]], tail[0][None]])
        t3s = None if tail[1] is None else tail[1][None]
        if fold and t3s is not None:
            t3s = np.vstack([jtan[cands], t3s])
        results = _test(fitter, start, rows, p0, tan, p3s, t3s)
        if results[-1][1]:
            return end, results[-1][0], True
        first = results[:-1] if fold else None
    if lo >= end:  # two points left: nothing shorter to try
        fit, good = test(np.array([end]))[0]
        return end, fit, good
    hi = end
    lo_fit: CubicFit | None = None
    exhausted = False
    while cands.size:
        if first is None and not exhausted and cands.size < hi - lo - 1 <= _EXHAUST:
            exhausted = True
            test(np.arange(lo if lo_fit is None else lo + 1, hi))  # into the cache
        results = test(cands) if first is None else first
        first = None
        passing = [(c, f) for c, (f, good) in zip(cands.tolist(), results) if good]
        if passing and (lo_fit is None or passing[-1][0] > lo):
            lo, lo_fit = passing[-1]
        failing = [c for c, (_, good) in zip(cands.tolist(), results) if not good and c > lo]
        hi = min([hi, *failing])
        if lo_fit is None and lo in cands.tolist():
            break  # the shortest regular piece failed
        inner = np.unique(np.round(np.linspace(lo, hi, _ROUND + 2)[1:-1]).astype(np.int64))
        cands = inner[(inner > lo) & (inner < hi)]
        if lo_fit is None:
            cands = np.r_[lo, cands]
    if lo_fit is not None:
        return lo, lo_fit, True
    shorter = np.arange(lo, start, -1)
    results = test(shorter)
    for c, (f, good) in zip(shorter.tolist(), results):
        if good:
            return c, f, True
    return start + 1, results[-1][0], False


def denoise(
    points: NDArray[np.float64], closed: bool, pos_window: int = 7, tan_window: int = 17
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Denoised positions and unit tangents of an ordered run (Savitzky-Golay, quadratic).

    Pixel staircases have chord lengths of exactly 1 and tangents that flip by 90 degrees at
    every step; the parameterizations and G1 joins need the underlying smooth curve. Runs
    are smoothed on their own (``closed=False``: polynomial extrapolation at the ends, so a
    corner never blurs into its neighbours) or cyclically (``closed=True``).

    Returns
    -------
    positions : (n, D) float
    tangents : (n, D) float, unit
    """
    n = len(points)

    def window(w: int) -> int:
        w = min(w | 1, n if n % 2 else n - 1)  # odd, at most n
        return w if w >= 5 else 0

    wp, wt = window(pos_window), window(tan_window)
    pts = np.asarray(points, dtype=float)
    pos = _savgol(pts, wp, 0, closed) if wp else pts.copy()
    der = _savgol(pts, wt, 1, closed) if wt else (np.gradient(pts, axis=0) if n > 1 else np.zeros_like(pts))
    norm = np.linalg.norm(der, axis=1, keepdims=True)
    tan = np.divide(der, norm, out=np.zeros_like(der), where=norm > 1e-12)
    return pos, tan


def _savgol(points: NDArray[np.float64], window: int, deriv: int, closed: bool) -> NDArray[np.float64]:
    """Savitzky-Golay (quadratic) value or first derivative, as scipy.signal.savgol_filter
    with mode "wrap" / "interp", without importing scipy.signal (seconds to import)."""
    half = window // 2
    x = np.arange(-half, half + 1, dtype=float)
    vander = np.stack([np.ones_like(x), x, x * x], axis=1)  # (w, 3)
    pinv = np.linalg.pinv(vander)  # (3, w): polynomial coefficients from window values
    n = len(points)
    if closed:
        idx = (np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :]) % n
        return np.einsum("w,nwd->nd", pinv[deriv], points[idx])
    out = np.empty_like(points)
    idx = np.arange(half, n - half)[:, None] + np.arange(-half, half + 1)[None, :]
    out[half : n - half] = np.einsum("w,nwd->nd", pinv[deriv], points[idx])
    # Ends: evaluate the polynomial fitted to the first / last full window.
    for block, rows in ((points[:window], np.arange(half)), (points[n - window :], np.arange(n - half, n))):
        coef = pinv @ block  # (3, D)
        xs = (rows - (rows[0] if rows[0] == 0 else n - window)).astype(float) - half
        if deriv == 0:
            out[rows] = coef[0] + xs[:, None] * coef[1] + (xs * xs)[:, None] * coef[2]
        else:
            out[rows] = coef[1] + 2.0 * xs[:, None] * coef[2]
    return out


def fit_closed(
    points: NDArray[np.float64],
    tolerance: float,
    *,
    corners: NDArray[np.int64] | None = None,
    g1: bool = True,
    smooth: bool = True,
    method: str = "optimal",
    start: int | None = None,
    sharpen: bool = True,
    deadline: float | None = None,
    lines: bool = True,
    soft_corners: NDArray[np.int64] | None = None,
    rounds: int = PIECE_ROUNDS,
) -> tuple[ChainFit, int]:
    """Fit a closed loop of points (``points[-1]`` joins back to ``points[0]``).

    With corners, each run between consecutive corners is fitted on its own (sharp joins at
    the corners, G1 inside). Without corners the loop is opened at ``start`` (default: its
    sharpest turn) and closed with a G1 join there.

    Parameters
    ----------
    points : (n, D) float
    tolerance : float
    corners : (c,) int, optional
        Indices of corner points.
    g1 : bool
        G1 joins at break points that are not corners.
    smooth : bool
        Parameterize and place joins on a denoised copy of the points (:func:`denoise`);
        off for points that are already smooth samples.
    method : str
        See :func:`fit_chain`.
    sharpen : bool
        Place corners between straight sides where the two sides' lines meet (see
        :func:`corner_positions`) instead of on their nearest point.
    deadline : float, optional
        See :func:`fit_chain`.
    lines : bool
        Straight runs become line segments (:func:`line_chain`, :func:`straighten`).
    soft_corners : (s,) int, optional
        Points where joins inside a run may stay C0 (corners that are not forced breaks;
        see :func:`fit_chain`'s ``corner_points``).
    rounds : int
        See :func:`fit_chain`.

    Returns
    -------
    (ChainFit, offset)
        The curves run around the loop starting at point index ``offset``; the chain's
        ``breaks`` index the rolled loop ``np.roll(points, -offset)`` closed by its first point.
    """
    pts = np.asarray(points, dtype=float)
    n = len(pts)
    cidx = np.unique(np.asarray(corners, dtype=np.int64) % n) if corners is not None and len(corners) else None
    if cidx is None:
        pos, tan = denoise(pts, closed=True) if smooth else (pts, _closed_tangents(pts))
        offset = int(_max_curvature_index(pos)) if start is None else int(start) % n
        ring = np.r_[offset:n, 0 : offset + 1]
        chain = None
        if n <= TINY_LOOP:
            # A speck: one cubic closing on itself (a single C0 join) is the cheapest outline,
            # and at this size the join cannot be seen.
            one = fit_chain(pts[ring], tolerance, g1=False, param_points=pos[ring], method=method,
                            rounds=rounds, max_pieces=0, deadline=deadline, edge_midpoints=True)
            if one.ok and len(one.fits) == 1:
                one.corners = [0]
                return one, offset
        if g1:
            # Open the loop on its denoised curve with the loop's own tangent there, so the
            # closing join is G1 like every other.
            chain = fit_chain(
                pts[ring], tolerance, p_start=pos[offset], p_end=pos[offset],
                tan_start=tan[offset], tan_end=tan[offset], g1=True,
                param_points=pos[ring], join_tangents=tan[ring], method=method, deadline=deadline,
                edge_midpoints=True, rounds=rounds,
            )
        if chain is not None and not chain.ok:
            chain = None  # opened on the denoised curve it cannot hold: reopen on a vertex
        if chain is None or len(chain.fits) == 1:
            # One cubic cannot close G1 with itself: there the join is a corner.
            chain = fit_chain(pts[ring], tolerance, g1=g1, param_points=pos[ring],
                              join_tangents=tan[ring], method=method, deadline=deadline,
                              edge_midpoints=True, rounds=rounds)
            chain.corners = sorted(set(chain.corners) | {0})
        return (straighten(chain, pts[ring], tolerance) if lines else chain), offset
    offset = int(cidx[0])
    ring = np.r_[offset:n, 0 : offset + 1]
    closed = pts[ring]
    soft = None
    if soft_corners is not None:
        soft = np.zeros(n, bool)
        soft[np.asarray(soft_corners, dtype=np.int64) % n] = True
    cuts = np.concatenate([cidx - offset, [n]])
    tips = corner_positions(pts, cidx, max_shift=0.75 * tolerance) if sharpen else pts[cidx]
    tips = np.vstack([tips, tips[:1]])
    curves: list[NDArray[np.float64]] = []
    fits: list[CubicFit] = []
    breaks, corner_list, flags = [0], [], []
    runs = [closed[a : b + 1] for a, b in zip(cuts[:-1], cuts[1:])]
    smoothed = [denoise(run, closed=False) if smooth else (run, tangents(run)) for run in runs]
    straight = [line_chain(run, tips[j], tips[j + 1], tolerance) if lines else None for j, run in enumerate(runs)]
    curved = [j for j, c in enumerate(straight) if c is None]
    prefetch_whole_runs([runs[j] for j in curved], [smoothed[j][0] for j in curved], tips[curved],
                        tips[np.asarray(curved, dtype=np.int64) + 1], tolerance, method, rounds)
    for j, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        run, (pos, tan), chain = runs[j], smoothed[j], straight[j]
        if chain is None:
            chain = fit_chain(run, tolerance, p_start=tips[j], p_end=tips[j + 1], g1=g1,
                              param_points=pos, join_tangents=tan, method=method, deadline=deadline,
                              edge_midpoints=True, corner_points=None if soft is None else soft[ring][a : b + 1],
                              rounds=rounds)
            chain = straighten(chain, run, tolerance) if lines else chain
        flags.extend(chain.lines or [False] * len(chain.fits))
        corner_list.append(len(fits))
        corner_list.extend(len(fits) + c for c in chain.corners if c != 0)
        curves.append(chain.curves)
        fits.extend(chain.fits)
        breaks.extend(int(a) + chain.breaks[1:])
    chain = ChainFit(np.concatenate(curves), fits, np.asarray(breaks, dtype=np.int64), sorted(set(corner_list)))
    chain.lines = flags
    return chain, offset


def prefetch_whole_runs(
    runs: list[NDArray[np.float64]], params: list[NDArray[np.float64]], p_starts: NDArray[np.float64],
    p_ends: NDArray[np.float64], tolerance: float, method: str, rounds: int = PIECE_ROUNDS,
) -> None:
    """Fit each run as one C0 piece (every parameterization where the search ones pass),
    all runs in a few batches, into the fit cache.

    The runs between a loop's corners are fitted one :func:`fit_chain` after the other, and
    each begins by testing its whole run: most runs are one piece, and their two fits (the
    test and the refit with every parameterization) then cost a batch each. Fitted here
    together, :func:`fit_chain` finds them in the cache. Runs are batched by length
    (sorted, a batch closed where padding would more than double its points).
    """
    if len(runs) < 2:
        return
    fitter = _Fitter(np.concatenate(runs), tolerance, np.concatenate(params), method, rounds, True)
    sizes = np.array([len(r) for r in runs], dtype=np.int64)
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    rest = [n for n in fitter.all_names if n not in fitter.names]
    for group in _length_groups(sizes):
        res = fitter.fit_spans(starts[group], starts[group] + sizes[group] - 1, p_starts[group], p_ends[group], None, None)
        good = group[[ok for _, ok in res]]
        if rest and good.size:
            fitter.fit_spans(starts[good], starts[good] + sizes[good] - 1, p_starts[good], p_ends[good], None, None, rest)


def _length_groups(sizes: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Indices of ``sizes`` in groups of similar size: sorted, a new group begun where
    padding to the group's largest would more than double its points."""
    order = np.argsort(sizes, kind="stable")
    groups: list[list[int]] = [[]]
    for i in order.tolist():
        g = groups[-1]
        if g and sizes[i] * (len(g) + 1) > 2 * (int(sizes[g].sum()) + sizes[i]):
            groups.append([])
        groups[-1].append(i)
    return [np.asarray(g, dtype=np.int64) for g in groups if g]


def fit_closed_free(
    points: NDArray[np.float64],
    tolerance: float,
    *,
    corners: NDArray[np.int64] | None = None,
    method: str = "optimal",
    deadline: float | None = None,
    rounds: int = PIECE_ROUNDS,
) -> tuple[ChainFit, int]:
    """Fit a closed loop with breaks wherever C0 pieces reach and G1 joins made on them.

    Unlike :func:`fit_closed`, the detected corners are not forced breaks, only places
    where a join may stay C0 (as may kinks, see :func:`g1_joins`), so a loop whose
    "corners" are raster noise costs what a plain least-squares fitter would.
    Steps: 1. open the loop at its first corner or kink (C0 closing join), else at its
    sharpest turn with the denoised tangent there (G1 closing join); 2. fit the run with
    :func:`fit_chain` (``free_joins``); 3. make pieces straight where their chord fits.
    ``rounds`` is :func:`fit_chain`'s.

    Returns
    -------
    (ChainFit, offset)
        As :func:`fit_closed`.
    """
    pts = np.asarray(points, dtype=float)
    n = len(pts)
    pos, tan = denoise(pts, closed=True)
    loop3 = np.vstack([pts, pts, pts])
    allowed = _kinks(loop3, n + np.arange(n), min(kink_reach(tolerance), max(1, n // 4)))
    cidx = np.asarray(corners, dtype=np.int64) % n if corners is not None and len(corners) else np.arange(0)
    allowed[cidx] = True
    if allowed.any():
        offset = int(cidx[0]) if cidx.size else int(np.flatnonzero(allowed)[0])
        t_end = None
    else:
        offset = _max_curvature_index(pos)
        t_end = tan[offset]
    ring = np.r_[offset:n, 0 : offset + 1]
    chain = fit_chain(pts[ring], tolerance, tan_start=t_end, tan_end=t_end, g1=True, param_points=pos[ring],
                      join_tangents=tan[ring], method=method, deadline=deadline, edge_midpoints=True,
                      corner_points=allowed[ring], rounds=rounds)
    if t_end is None or len(chain.fits) == 1:
        chain.corners = sorted(set(chain.corners) | {0})
    return straighten(chain, pts[ring], tolerance, closed=True), offset


def _segment_distance(points: NDArray[np.float64], p0: NDArray[np.float64], p3: NDArray[np.float64]):
    """Distances (n,) of points to the segment p0-p3 and their parameters (n,) on it."""
    d = p3 - p0
    length2 = float(d @ d)
    t = np.clip((points - p0) @ d / length2, 0.0, 1.0) if length2 > 1e-24 else np.zeros(len(points))
    return np.linalg.norm(points - (p0 + t[:, None] * d), axis=1), t


def line_cubic(p0: NDArray[np.float64], p3: NDArray[np.float64]) -> NDArray[np.float64]:
    """The straight segment p0-p3 as a cubic (degree-elevated line), shape (4, D)."""
    return np.stack([p0, p0 + (p3 - p0) / 3.0, p0 + 2.0 * (p3 - p0) / 3.0, p3])


def line_chain(points, p0, p3, tolerance: float) -> ChainFit | None:
    """One straight piece p0-p3 when every point lies within the tolerance of it, else None."""
    err, t = _segment_distance(np.asarray(points, dtype=float), p0, p3)
    if err.max() > tolerance * SAFETY:
        return None
    fit = CubicFit(line_cubic(p0, p3), t, err, "line")
    chain = ChainFit(fit.ctrl[None], [fit], np.array([0, len(points) - 1], dtype=np.int64))
    chain.lines = [True]
    return chain


def straighten(
    chain: ChainFit, points: NDArray[np.float64], tolerance: float, closed: bool = False
) -> ChainFit:
    """Make every piece whose points lie within the tolerance of its chord a straight line.

    A least-squares cubic over a straight pixel edge bulges gently within the tolerance; its
    chord has the same end points and follows the edge. At a G1 join (not in
    ``chain.corners``; the chain's own ends count as corners) the chord may turn at most
    :data:`LINE_KINK` degrees from the join tangent, so a short chord of a round arc never
    puts a corner into a smooth outline. With ``closed`` the chain's ends meet at a join,
    sharp only when 0 is in ``chain.corners``.
    """
    lines = list(chain.lines) or [False] * len(chain.fits)
    ends = {0, len(chain.fits)} if not closed or 0 in chain.corners else set()
    sharp = set(chain.corners) | ends
    cos_kink = np.cos(np.radians(LINE_KINK))
    for k, (a, b) in enumerate(zip(chain.breaks[:-1], chain.breaks[1:])):
        if lines[k]:
            continue
        c = chain.curves[k]
        chord = _unit(c[3] - c[0])
        t0, t3 = start_tangent(c), end_tangent(c)
        if chord is None or (k not in sharp and (t0 is None or t0 @ chord < cos_kink)):
            continue
        if k + 1 not in sharp and (t3 is None or t3 @ chord < cos_kink):
            continue
        line = line_chain(points[a : b + 1], chain.curves[k, 0], chain.curves[k, 3], tolerance)
        if line is not None:
            chain.curves[k] = line.curves[0]
            chain.fits[k] = line.fits[0]
            lines[k] = True
    chain.lines = lines
    return chain


def corner_positions(
    points: NDArray[np.float64],
    corners: NDArray[np.int64],
    reach: int = 10,
    max_shift: float = 0.75,
    straightness: float = 0.75,
) -> NDArray[np.float64]:
    """Corner points between straight sides, placed where the sides' lines meet.

    A digitized corner is blunt: its nearest boundary point can sit most of a pixel off
    both sides' lines, and a side forced through it then needs a second piece. Where both
    sides are straight near the corner (total-least-squares line through ``reach`` points
    with every point within ``straightness``), the corner moves to the lines' intersection
    if that is within ``max_shift``; other corners stay on their point.

    Parameters
    ----------
    points : (n, D) float, a closed loop
    corners : (c,) int, increasing

    Returns
    -------
    (c, D) float
    """
    n = len(points)
    out = points[corners].astype(float).copy()
    gaps = np.diff(np.r_[corners, corners[0] + n])
    for j, i in enumerate(corners):
        before = min(reach, int(gaps[j - 1]) // 2)
        after = min(reach, int(gaps[j]) // 2)
        if before < 4 or after < 4:
            continue
        lines = []
        for side in (points[(i - np.arange(1, before + 1)) % n], points[(i + np.arange(1, after + 1)) % n]):
            c = side.mean(axis=0)
            direction = np.linalg.svd(side - c)[2][0]
            off = side - c - np.outer((side - c) @ direction, direction)
            lines.append((c, direction, float(np.linalg.norm(off, axis=1).max())))
        (c1, d1, r1), (c2, d2, r2) = lines
        if max(r1, r2) > straightness:
            continue
        m = np.array([[d1 @ d1, -d1 @ d2], [d1 @ d2, -d2 @ d2]])
        if abs(np.linalg.det(m)) < 0.1:  # nearly parallel sides: no reliable tip
            continue
        s1, s2 = np.linalg.solve(m, np.array([(c2 - c1) @ d1, (c2 - c1) @ d2]))
        tip = 0.5 * ((c1 + s1 * d1) + (c2 + s2 * d2))
        if np.linalg.norm(tip - points[i]) <= max_shift:
            out[j] = tip
    return out


def _closed_tangents(points: NDArray[np.float64], k: int = 2) -> NDArray[np.float64]:
    """Unit tangents of a closed polygon by central differences over +-k vertices."""
    fwd = np.roll(points, -k, axis=0) - np.roll(points, k, axis=0)
    norm = np.linalg.norm(fwd, axis=1, keepdims=True)
    return np.divide(fwd, norm, out=np.zeros_like(fwd), where=norm > 1e-12)


def _max_curvature_index(points: NDArray[np.float64]) -> int:
    """Index of the sharpest turn of a closed polygon, measured over +-3 vertices."""
    n = len(points)
    k = min(3, max(1, n // 4))
    a = np.roll(points, k, axis=0) - points
    b = np.roll(points, -k, axis=0) - points
    na = np.linalg.norm(a, axis=1)
    nb = np.linalg.norm(b, axis=1)
    cos = np.sum(a * b, axis=1) / np.maximum(na * nb, 1e-12)
    return int(np.argmax(cos))  # the smallest interior angle


def chain_curves(chain: ChainFit) -> NDArray[np.float64]:
    """The chain's control points ``(K, 4, D)`` (convenience for callers)."""
    return chain.curves


def sample(chain: ChainFit, per_curve: int = 16) -> NDArray[np.float64]:
    """Points along the chain, ``per_curve`` per piece (end point excluded)."""
    return bezier.sample_chain(chain.curves, per_curve)
