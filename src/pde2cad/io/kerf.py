"""Kerf compensation: offset a drawing's shapes by an exact distance, as lines and arcs.

A laser or plasma beam removes a strip of material of width ``kerf``; cutting along the
drawn outline makes parts too small by ``kerf / 2`` all round. Offsetting every shape by
``d = kerf / 2`` moves outer loops out and hole loops in (the material grows by ``d``), so
the cut parts come out at the drawn size.

Method
    1. Each loop (cubic Béziers, DXF frame) is flattened to a polyline within ``tol / 4``.
    2. The shape (outer loop with its holes) is offset exactly by ``d`` with shapely's
       ``buffer`` (round joins: the true offset of a convex corner is a circular arc of
       radius ``d``), its arcs flattened within ``tol / 4``.
    3. Each resulting ring is fitted greedily with circular arcs and lines within
       ``tol / 2`` (every vertex and edge midpoint checked).

    The written loops are then within ``tol`` of the exact offset of the Béziers. Holes
    that the offset closes (smaller than ``2 d`` across) vanish and are counted; a
    negative ``d`` shrinks shapes and may split or remove them.

shapely is imported only here (an adapter, like ezdxf for the DXF writer).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves.arcs import bezier_to_polyline
from pde2cad.errors import ExportError, InputError

__all__ = ["offset_shape", "ring_to_bulges"]

# A fitted "arc" whose radius exceeds this many tolerances is written as a line.
_LINE_RADIUS = 1e7


def _flatten(curves: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    return np.concatenate([bezier_to_polyline(c, tol)[:-1] for c in curves])


def _quad_segs(distance: float, tol: float) -> int:
    """Segments per quarter circle so a round join's chords stay within ``tol``."""
    ratio = min(tol / abs(distance), 1.0)
    return int(max(2, np.ceil((np.pi / 4.0) / np.arccos(1.0 - ratio))))


def offset_shape(
    loops: list[NDArray[np.float64]], holes: list[bool], distance: float, tol: float
) -> tuple[list[tuple[NDArray[np.float64], bool]], int]:
    """Offset one shape (an outer loop and its holes) by ``distance``.

    Parameters
    ----------
    loops : list of (K, 4, 2) float
        The shape's loops in the DXF frame (y up), any orientation.
    holes : list of bool
        Per loop, whether it is a hole.
    distance : float
        Growth of the material: outer loops move out, holes move in (negative: reverse).
    tol : float
        Maximum distance of the written loops from the exact offset.

    Returns
    -------
    rings : list of ((n, 3) float, bool)
        Bulge vertices ``(x, y, bulge)`` of each closed result loop (outer loops
        counter-clockwise, holes clockwise) and whether it is a hole.
    lost : int
        Loops of the input that the offset closed up (no counterpart in the result).
    """
    try:
        from shapely import geometry, ops  # type: ignore[import-untyped]
        from shapely.geometry.polygon import orient  # type: ignore[import-untyped]
    except ImportError as exc:  # optional dependency
        raise ExportError(
            "--offset needs shapely; install it with: pip install 'pde2cad[dxf]'"
        ) from exc
    e = tol / 4.0
    shells = [_flatten(c, e) for c, h in zip(loops, holes, strict=True) if not h]
    inner = [_flatten(c, e) for c, h in zip(loops, holes, strict=True) if h]
    polys = [geometry.Polygon(s, [r for r in inner if geometry.Polygon(s).contains(
        geometry.Point(r[0]))]) for s in shells]  # fmt: skip
    region = ops.unary_union([p if p.is_valid else p.buffer(0) for p in polys])
    grown = region.buffer(distance, quad_segs=_quad_segs(distance, e), join_style="round")
    parts = list(getattr(grown, "geoms", [grown])) if not grown.is_empty else []
    rings: list[tuple[NDArray[np.float64], bool]] = []
    for part in parts:
        part = orient(part, sign=1.0)
        rings.append((ring_to_bulges(np.asarray(part.exterior.coords)[:-1], 2.0 * e), False))
        for hole in part.interiors:
            rings.append((ring_to_bulges(np.asarray(hole.coords)[:-1], 2.0 * e), True))
    lost = max(len(loops) - len(rings), 0)
    return rings, lost


# --------------------------------------------------------------------------- arc fitting
def _circle(a: NDArray[np.float64], m: NDArray[np.float64], b: NDArray[np.float64]
            ) -> tuple[NDArray[np.float64], float, float]:
    """Centre, radius and signed turn (cross product) of the circle through a, m, b."""
    d = 2.0 * ((m[0] - a[0]) * (b[1] - a[1]) - (m[1] - a[1]) * (b[0] - a[0]))
    if d == 0.0:
        return a, np.inf, 0.0
    am, ab = m - a, b - a
    ux = ((ab[1]) * (am @ am) - (am[1]) * (ab @ ab)) / d
    uy = ((am[0]) * (ab @ ab) - (ab[0]) * (am @ am)) / d
    center = a + np.array([ux, uy])
    return center, float(np.hypot(ux, uy)), d


def _fits(p: NDArray[np.float64], tol: float) -> tuple[bool, float]:
    """Whether one arc (or line) from p[0] to p[-1] stays within ``tol`` of the polyline
    ``p`` (m, 2) at every vertex and edge midpoint; returns (fits, bulge)."""
    a, b = p[0], p[-1]
    mid = p[len(p) // 2]
    q = np.concatenate([p, 0.5 * (p[:-1] + p[1:])])
    chord = b - a
    length = float(np.hypot(*chord))
    center, radius, turn = _circle(a, mid, b)
    if radius > _LINE_RADIUS * tol or len(p) == 2:
        if length == 0.0:
            return False, 0.0
        off = np.abs((q - a) @ np.array([-chord[1], chord[0]])) / length
        along = (q - a) @ chord / length
        ok = bool(np.all(off <= tol) and np.all(along >= -tol) and np.all(along <= length + tol))
        return ok, 0.0
    r = q - center
    if not np.all(np.abs(np.hypot(r[:, 0], r[:, 1]) - radius) <= tol):
        return False, 0.0
    ang = np.unwrap(np.arctan2(r[: len(p), 1], r[: len(p), 0]))
    steps = np.diff(ang) * np.sign(turn)
    sweep = float(ang[-1] - ang[0]) * np.sign(turn)
    if np.any(steps <= 0.0) or not 0.0 < sweep < 1.5 * np.pi:  # monotone, well short of full
        return False, 0.0
    return True, float(np.tan(sweep / 4.0) * np.sign(turn))


def ring_to_bulges(ring: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """Closed polyline (n, 2), last vertex not repeated, as arcs and lines within ``tol``.

    Greedy: from the sharpest vertex (or the largest curvature jump), each arc spans as many vertices as fit (found by
    doubling, then bisection). Returns bulge vertices ``(x, y, bulge)`` (m, 3) of a closed
    LWPOLYLINE/POLYLINE (bulge of the segment that starts at the vertex).
    """
    ring = np.asarray(ring, dtype=float)
    n = len(ring)
    if n < 3:
        raise InputError(f"a ring needs at least 3 vertices, got {n}")
    d_in = ring - np.roll(ring, 1, axis=0)
    d_out = np.roll(ring, -1, axis=0) - ring
    turn = np.arctan2(d_in[:, 0] * d_out[:, 1] - d_in[:, 1] * d_out[:, 0],
                      np.einsum("ij,ij->i", d_in, d_out))
    # Start at a sharp corner, else where the curvature jumps (a line meets an arc), so no
    # arc of the ring is cut in two by the start.
    if np.max(np.abs(turn)) > np.pi / 6.0:
        start = int(np.argmax(np.abs(turn)))
    else:
        kappa = turn / np.maximum(0.5 * (np.hypot(*d_in.T) + np.hypot(*d_out.T)), 1e-300)
        start = int(np.argmax(np.abs(kappa - np.roll(kappa, 1))))
    p = np.vstack([np.roll(ring, -start, axis=0), ring[start:start + 1]])
    out: list[tuple[float, float, float]] = []
    i = 0
    while i < n:
        lo, hi = i + 1, i + 2
        while hi <= n and _fits(p[i:hi + 1], tol)[0]:
            lo, hi = hi, min(2 * hi - i, n + 1)
        hi = min(hi, n + 1)
        while hi - lo > 1:  # lo fits, hi does not (or is past the end)
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if _fits(p[i:mid + 1], tol)[0] else (lo, mid)
        bulge = _fits(p[i:lo + 1], tol)[1]
        out.append((float(p[i, 0]), float(p[i, 1]), bulge))
        i = lo
    return np.asarray(out)
