"""Crossings between the fitted curves of an outline, and trimming them away.

A fit within the tolerance may let two neighbouring curves cross just before a sharp
corner: the outline then runs past the crossing to the corner and back, a tiny loop that
CAD kernels refuse as a face boundary (a wire must not cross itself). This module finds
crossings between any two curves of a shape's loops (outer loop and holes) on a dense
polyline of each curve, refines them by Newton's method on the curves themselves, and
trims a crossing of two consecutive curves of a loop to the crossing point.

Curves are cubic Béziers ``(K, 4, 2)``, consecutive ones joined end to start, each loop
closed (the last curve ends where the first starts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves import bezier

__all__ = ["Crossing", "find_crossings", "trim_corner_crossings"]

# Polyline segments per curve for the search; a cubic's polyline of 16 chords lies
# within a few hundredths of a pixel of it at the curve sizes of a pixel outline.
_SEGMENTS = 16
# Chords sharing an end point cannot cross, yet consecutive curves often cross within
# their last / first chord (a cusp-like turn at a joint): the polyline is refined
# geometrically towards both ends, down to 2^-16 of the curve.
_GRID = np.unique(np.r_[np.linspace(0.0, 1.0, _SEGMENTS + 1), 2.0 ** -np.arange(5, 17),
                        1.0 - 2.0 ** -np.arange(5, 17)])
# Consecutive curves meeting this close (in parameter) to their shared joint touch there.
_EPS = 1e-7
# Pairs tested at once (bounds the (pairs, 16, 16) temporaries).
_CHUNK = 1024


@dataclass(frozen=True)
class Crossing:
    """Curve ``a`` at parameter ``ta`` meets curve ``b`` at ``tb`` (indices into the
    concatenated curves of all loops searched); ``adjacent`` when ``b`` follows ``a``."""

    a: int
    b: int
    ta: float
    tb: float
    adjacent: bool


def _boxes_overlap(curves: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs i < j of curves whose control-point boxes overlap (the curves lie in them)."""
    lo, hi = curves.min(axis=1), curves.max(axis=1)
    pairs_i, pairs_j = [], []
    rows = max(1, 4_000_000 // max(len(curves), 1))
    for s in range(0, len(curves), rows):
        ok = np.all((lo[s : s + rows, None] <= hi[None]) & (lo[None] <= hi[s : s + rows, None]), axis=2)
        i, j = np.nonzero(ok)
        i = i + s
        keep = i < j
        pairs_i.append(i[keep])
        pairs_j.append(j[keep])
    return np.concatenate(pairs_i), np.concatenate(pairs_j)


def _segment_hits(
    pa: NDArray[np.float64], pb: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Proper crossings of the polylines ``pa[p]`` and ``pb[p]`` ((P, S + 1, 2) each).

    Both are sampled at :data:`_GRID`. Returns the pair index and the curve parameters
    (linear along the chords) of every crossing.
    """
    p, r = pa[:, :-1, None, :], np.diff(pa, axis=1)[:, :, None, :]
    q, u = pb[:, None, :-1, :], np.diff(pb, axis=1)[:, None, :, :]
    w = q - p
    den = r[..., 0] * u[..., 1] - r[..., 1] * u[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[..., 0] * u[..., 1] - w[..., 1] * u[..., 0]) / den
        t = (w[..., 0] * r[..., 1] - w[..., 1] * r[..., 0]) / den
    # Half-open chords: a crossing exactly at a chord joint (integer pixel points!) counts once.
    hit = (np.abs(den) > 1e-15) & (s >= 0.0) & (s < 1.0) & (t >= 0.0) & (t < 1.0)
    k, i, j = np.nonzero(hit)
    step = np.diff(_GRID)
    return k, _GRID[i] + s[k, i, j] * step[i], _GRID[j] + t[k, i, j] * step[j]


def _self_hits(poly: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Curves whose polyline crosses itself (a loop inside one cubic): index and the two
    polyline parameters of each crossing of non-neighbouring chords."""
    k, ta, tb = _segment_hits(poly, poly)
    # Neighbouring chords only touch; crossings of a chord with itself are excluded too.
    ia, ib = np.searchsorted(_GRID, ta), np.searchsorted(_GRID, tb)
    keep = (ta < tb) & (ib - ia > 1)
    return k[keep], ta[keep], tb[keep]


def _refine(ca: NDArray[np.float64], cb: NDArray[np.float64], ta: NDArray[np.float64],
            tb: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Newton steps on ``a(ta) - b(tb) = 0`` for batches of curve pairs ((m, 4, 2) each)."""
    for _ in range(6):
        fa = np.einsum("mk,mkd->md", bezier.bernstein(ta), ca)
        fb = np.einsum("mk,mkd->md", bezier.bernstein(tb), cb)
        da = np.einsum("mk,mkd->md", _d_bernstein(ta), ca)
        db = np.einsum("mk,mkd->md", _d_bernstein(tb), cb)
        # Solve [da, -db] (dta, dtb) = fb - fa per pair (2 x 2, Cramer).
        det = da[:, 0] * -db[:, 1] + db[:, 0] * da[:, 1]
        rhs = fb - fa
        ok = np.abs(det) > 1e-12
        safe = np.where(ok, det, 1.0)
        dta = (rhs[:, 0] * -db[:, 1] + db[:, 0] * rhs[:, 1]) / safe
        dtb = (da[:, 0] * rhs[:, 1] - da[:, 1] * rhs[:, 0]) / safe
        ta = np.clip(ta + np.where(ok, dta, 0.0), 0.0, 1.0)
        tb = np.clip(tb + np.where(ok, dtb, 0.0), 0.0, 1.0)
    return ta, tb


def _d_bernstein(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Derivative weights of the cubic Bernstein basis, (m, 4)."""
    s = 1.0 - t
    return np.stack([-3 * s * s, 3 * s * s - 6 * t * s, 6 * t * s - 3 * t * t, 3 * t * t], axis=1)


def find_crossings(loops: list[NDArray[np.float64]]) -> list[Crossing]:
    """Every crossing between two curves of the given closed loops.

    Steps: 1. the curves of all loops are concatenated; pairs whose control-point boxes
    overlap are candidates; 2. each candidate pair's polylines (16 chords, refined towards
    the ends, :data:`_GRID`) are intersected
    (proper crossings only: consecutive curves touching at their shared end do not
    count); 3. every hit is refined by Newton's method on the two cubics.

    Parameters
    ----------
    loops : list of (K_i, 4, 2) float
        Closed loops of cubics (a shape's outer loop and holes, or any set).

    Returns
    -------
    list of Crossing
        Indices into the concatenation of ``loops``; ``a == b`` for a curve crossing
        itself (then ``ta`` and ``tb`` are the polyline parameters, not refined).
    """
    if not loops:
        return []
    curves = np.concatenate(loops)
    sizes = np.array([len(lp) for lp in loops])
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    owner = np.repeat(np.arange(len(loops)), sizes)
    nxt = np.arange(len(curves)) + 1
    ends = start + sizes - 1
    nxt[ends] = start  # the loops close
    poly = bezier.evaluate(curves, _GRID)  # (K, G, 2)
    ii, jj = _boxes_overlap(curves)
    out = [Crossing(int(i), int(i), float(u), float(v), False) for i, u, v in zip(*_self_hits(poly))]
    for s in range(0, len(ii), _CHUNK):
        i, j = ii[s : s + _CHUNK], jj[s : s + _CHUNK]
        k, ta, tb = _segment_hits(poly[i], poly[j])
        if not k.size:
            continue
        a, b = i[k], j[k]
        ta, tb = _refine(curves[a], curves[b], ta, tb)
        for x, y, u, v in zip(a.tolist(), b.tolist(), ta.tolist(), tb.tolist()):
            follows = bool(nxt[x] == y and owner[x] == owner[y])
            precedes = bool(nxt[y] == x and owner[x] == owner[y])
            # Report consecutive pairs in loop order; in a loop of two curves each follows
            # the other, and the crossing is at the joint it is nearer to.
            if precedes and (not follows or u + (1.0 - v) < (1.0 - u) + v):
                x, y, u, v, follows = y, x, v, u, True
            at_joint = (follows and u > 1 - _EPS and v < _EPS) or (precedes and u < _EPS and v > 1 - _EPS)
            if not at_joint:
                out.append(Crossing(x, y, u, v, follows))
    return out


def trim_corner_crossings(
    curves: NDArray[np.float64], points: NDArray[np.float64], tolerance: float,
) -> tuple[NDArray[np.float64], int, int]:
    """Cut the little loop where two consecutive curves of one closed loop cross.

    Steps, per crossing of curve ``a`` with its successor ``b``: 1. ``a`` is cut at the
    crossing (its part after it dropped) and ``b`` likewise (its part before it dropped),
    both exact pieces of the fitted cubics (de Casteljau); 2. the cut drops the corner
    tip the little loop reached, so the new joint is moved from the crossing towards the
    old one (the two end control points shifted with it, keeping the end tangents) by
    the least of 0, 1/4, 1/2, 3/4 of the way that brings the boundary points near the
    corner within ``tolerance`` without the two pieces crossing again; 3. a crossing no
    step resolves is left as it is (counted as unresolved); 4. a curve crossing both its
    neighbours is trimmed at one joint per pass, the crossings searched again after each
    pass that trimmed something (a two-curve loop's curves can cross at both joints).

    Parameters
    ----------
    curves : (K, 4, 2) float
        One closed loop.
    points : (n, 2) float
        The boundary the loop was fitted to.
    tolerance : float
        Largest distance allowed from a boundary point to the curves.

    Returns
    -------
    (K, 4, 2) float, int, int
        The trimmed loop, the number of crossings trimmed, and of those left (including
        crossings of non-consecutive curves and within one curve, which are not trimmed).
    """
    out = curves.copy()
    fixed = 0
    while True:
        every = find_crossings([out])
        found = [c for c in every if c.adjacent]
        others = len(every) - len(found)
        done: set[int] = set()
        left = waiting = now = 0
        for c in found:
            if not (0.0 < c.ta < 1.0 and 0.0 < c.tb < 1.0):
                continue
            if c.a in done or c.b in done:
                # A curve crossing both neighbours (each joint of a two-curve sliver) is
                # trimmed at one joint per pass: the cut moves the other's parameters.
                waiting += 1
                continue
            done.update((c.a, c.b))
            # The two curves of a two-curve loop may cross at their other joint too; that
            # crossing stays for the next pass.
            pair = _untangle_pair(out, c, points, tolerance, int(any((d.a, d.b) == (c.b, c.a) for d in found)))
            if pair is None:
                left += 1
                continue
            out[c.a], out[c.b] = pair
            now += 1
        fixed += now
        if not waiting or not now:
            return out, fixed, left + waiting + others


def _untangle_pair(
    curves: NDArray[np.float64], c: Crossing, points: NDArray[np.float64], tolerance: float, others: int = 0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The two trimmed curves of one crossing (steps 1-2 of :func:`trim_corner_crossings`);
    ``others`` crossings of the two elsewhere (at their other joint) may remain."""
    from pde2cad.curves.distance import points_to_curves

    head, _ = bezier.split(curves[c.a], c.ta)
    _, tail = bezier.split(curves[c.b], c.tb)
    cross = 0.5 * (head[3] + tail[0])
    joint = curves[c.a][3]
    reach = np.linalg.norm(joint - cross) + 2.0 * tolerance + 1.0
    near = points[np.linalg.norm(points - joint, axis=1) <= reach]
    trial = curves.copy()
    for mu in (0.0, 0.25, 0.5, 0.75):
        shift = mu * (joint - cross)
        h, t = head.copy(), tail.copy()
        h[2:] += shift
        t[:2] += shift
        h[3] = t[0] = cross + shift
        trial[c.a], trial[c.b] = h, t
        poly = bezier.evaluate(np.stack([h, t]), _GRID)
        if _segment_hits(poly[:1], poly[1:])[0].size > others:
            continue
        if not len(near) or points_to_curves(near, trial).max() <= tolerance:
            return h, t
    return None
