"""Cubic Béziers as circular arcs and lines (biarcs) or as polylines, within a tolerance.

Laser cutters, plasma tables and many CNC controllers only understand lines and circular
arcs (G1/G2/G3, DXF LWPOLYLINE bulges). This module approximates one cubic Bézier by a
tangent-continuous (G1) chain of arcs using biarcs with the incenter joint, and flattens a
Bézier into a polyline with a guaranteed chord error.

Orientation: ``ccw`` is the mathematical sense of the coordinate frame the control points
are given in (positive cross product, x to the right, y up). In an image frame (y down) a
"ccw" arc therefore looks clockwise on screen; the DXF writer converts to y-up first.

Pure numpy; no CAD dependency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.curves.bezier import evaluate, power_coefficients, split
from pde2cad.errors import InputError

__all__ = [
    "Arc",
    "Line",
    "Segment",
    "bezier_to_arcs",
    "bezier_to_polyline",
    "inflections",
    "segments_distance",
    "sample_segments",
]

# Samples per Bézier piece when measuring the biarc error (the brief: ~32, vectorized).
_N_SAMPLES = 32
# Subdivision depth cap: 2**16 pieces per Bézier is far beyond any useful tolerance, so the
# cap only protects against pathological input (NaN-free but absurdly tiny tolerances).
_MAX_DEPTH = 16
# Pieces whose end tangents turn by more than this are split before fitting: the incenter
# biarc is then always well formed (both arcs turn the same way, each sweep < 120 deg), so
# the bulge of every arc stays small and far from the full-circle singularity.
_MAX_TURN = 2.0 * np.pi / 3.0


@dataclass(frozen=True)
class Arc:
    """A circular arc from ``start`` to ``end`` around ``center``.

    Attributes
    ----------
    start, end, center : (2,) float
    radius : float
    ccw : bool
        True when the arc runs counter-clockwise (mathematical sense) from start to end.
    """

    start: NDArray[np.float64]
    end: NDArray[np.float64]
    center: NDArray[np.float64]
    radius: float
    ccw: bool

    @property
    def sweep(self) -> float:
        """Unsigned swept angle in radians, in (0, 2 pi)."""
        a0 = np.arctan2(*(self.start - self.center)[::-1])
        a1 = np.arctan2(*(self.end - self.center)[::-1])
        d = (a1 - a0) if self.ccw else (a0 - a1)
        return float(np.mod(d, 2.0 * np.pi))

    @property
    def bulge(self) -> float:
        """DXF bulge tan(sweep / 4): positive for ccw arcs, negative for cw arcs."""
        b = float(np.tan(self.sweep / 4.0))
        return b if self.ccw else -b

    def tangent_at_start(self) -> NDArray[np.float64]:
        """Unit tangent (2,) at ``start`` in the direction of travel."""
        r = (self.start - self.center) / self.radius
        return np.array([-r[1], r[0]]) if self.ccw else np.array([r[1], -r[0]])

    def tangent_at_end(self) -> NDArray[np.float64]:
        """Unit tangent (2,) at ``end`` in the direction of travel."""
        r = (self.end - self.center) / self.radius
        return np.array([-r[1], r[0]]) if self.ccw else np.array([r[1], -r[0]])

    def sample(self, n: int) -> NDArray[np.float64]:
        """``n`` points (n, 2) from start to end inclusive."""
        a0 = np.arctan2(*(self.start - self.center)[::-1])
        sign = 1.0 if self.ccw else -1.0
        a = a0 + sign * self.sweep * np.linspace(0.0, 1.0, n)
        return self.center + self.radius * np.stack([np.cos(a), np.sin(a)], axis=-1)


@dataclass(frozen=True)
class Line:
    """A straight segment from ``start`` to ``end``, both (2,) float."""

    start: NDArray[np.float64]
    end: NDArray[np.float64]

    @property
    def bulge(self) -> float:
        """DXF bulge of a straight segment: 0."""
        return 0.0

    def tangent_at_start(self) -> NDArray[np.float64]:
        d = self.end - self.start
        return d / np.linalg.norm(d)

    def tangent_at_end(self) -> NDArray[np.float64]:
        return self.tangent_at_start()

    def sample(self, n: int) -> NDArray[np.float64]:
        """``n`` points (n, 2) from start to end inclusive."""
        t = np.linspace(0.0, 1.0, n)[:, None]
        return (1.0 - t) * self.start + t * self.end


Segment = Arc | Line


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """z component of the 2D cross product, broadcasting over leading axes."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _check(ctrl: ArrayLike, tol: float) -> NDArray[np.float64]:
    c = np.asarray(ctrl, dtype=float)
    if c.shape != (4, 2):
        raise InputError(f"a cubic Bézier needs 4 control points of shape (4, 2), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise InputError("Bézier control points contain NaN or inf; clean the input curves")
    if not (np.isfinite(tol) and tol > 0):
        raise InputError(f"tolerance must be a positive number, got {tol}")
    return c


def _scale(c: NDArray[np.float64]) -> float:
    """Size of the control polygon, used to make the degeneracy thresholds relative."""
    return float(np.max(np.abs(c - c[0]))) + 1e-300


def _end_tangents(
    c: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Unit tangents (2,) at both ends, or None for a curve collapsed to a point.

    When P1 == P0 the curve leaves P0 towards P2 (the limit of B'(t) as t -> 0), and
    likewise at the other end, so coincident control points are skipped in order.
    """
    eps = 1e-12 * _scale(c)
    t0 = t1 = None
    for q in (c[1], c[2], c[3]):
        d = q - c[0]
        n = float(np.hypot(*d))
        if n > eps:
            t0 = d / n
            break
    for q in (c[2], c[1], c[0]):
        d = c[3] - q
        n = float(np.hypot(*d))
        if n > eps:
            t1 = d / n
            break
    if t0 is None or t1 is None:
        return None
    return t0, t1


def inflections(ctrl: ArrayLike) -> NDArray[np.float64]:
    """Parameters in (0, 1) where the curvature of the cubic changes sign (or is a cusp).

    With B(t) = c0 + c1 t + c2 t^2 + c3 t^3, cross(B', B'') = 2 c1xc2 + 6 c1xc3 t + 6 c2xc3 t^2
    (the cubic term cancels), so inflections are the roots of a quadratic.

    Parameters
    ----------
    ctrl : (4, 2) float

    Returns
    -------
    (m,) float, sorted, m <= 2
    """
    co = power_coefficients(ctrl)
    a = 6.0 * _cross(co[2], co[3])
    b = 6.0 * _cross(co[1], co[3])
    c = 2.0 * _cross(co[1], co[2])
    scale = max(abs(a), abs(b), abs(c))
    if scale == 0.0:
        return np.zeros(0)
    a, b, c = a / scale, b / scale, c / scale
    if abs(a) < 1e-12:
        roots = np.array([-c / b]) if abs(b) > 1e-12 else np.zeros(0)
    else:
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return np.zeros(0)
        sq = np.sqrt(disc)
        # Numerically stable quadratic roots (no cancellation in b +- sq).
        q = -0.5 * (b + np.copysign(sq, b))
        roots = np.array([q / a, c / q]) if q != 0.0 else np.array([0.0])
    # Roots at the very ends would only create zero-length pieces.
    roots = roots[(roots > 1e-9) & (roots < 1.0 - 1e-9)]
    return np.unique(roots)


def _arc_from_tangent(
    a: NDArray[np.float64], ta: NDArray[np.float64], b: NDArray[np.float64], eps: float
) -> Segment | None:
    """The arc (or line) from ``a`` with unit tangent ``ta`` through ``b``.

    The center lies on the normal at ``a``: C = a + s n with |C - b| = |s|, which gives
    s = |b - a|^2 / (2 n.(b - a)); s > 0 means the center is on the left (ccw).
    """
    d = b - a
    dd = float(d @ d)
    if dd <= eps * eps:
        return None  # zero-length piece: nothing to draw
    n = np.array([-ta[1], ta[0]])
    h = float(n @ d)
    # b lies (almost) on the tangent line: a straight segment, exactly tangent.
    if abs(h) <= 1e-12 * np.sqrt(dd):
        return Line(a.copy(), b.copy())
    s = dd / (2.0 * h)
    return Arc(a.copy(), b.copy(), a + s * n, abs(s), s > 0)


def _incenter_biarc(
    c: NDArray[np.float64], t0: NDArray[np.float64], t1: NDArray[np.float64]
) -> list[Segment] | None:
    """Biarc from c[0] (tangent t0) to c[3] (tangent t1) with the joint at the incenter.

    The tangent lines meet at V = P0 + u t0 = P3 - w t1. For a convex piece turning by less
    than pi, u, w > 0 and the incenter J of triangle (P0, V, P3) gives a biarc whose joint
    tangent is parallel to the chord P0P3. Returns None when the triangle is not proper
    (the caller subdivides).
    """
    p0, p3 = c[0], c[3]
    eps = 1e-12 * _scale(c)
    den = float(_cross(t0, t1))
    chord = p3 - p0
    lc = float(np.hypot(*chord))
    if lc <= eps or abs(den) <= 1e-12:
        return None
    u = float(_cross(chord, t1)) / den
    w = float(_cross(t0, chord)) / den
    if u <= 0.0 or w <= 0.0:
        return None
    v = p0 + u * t0
    # Incenter: vertices weighted by the length of the opposite side.
    l_p0 = float(np.hypot(*(p3 - v)))
    l_p3 = float(np.hypot(*(p0 - v)))
    j = (l_p0 * p0 + l_p3 * p3 + lc * v) / (l_p0 + l_p3 + lc)
    first = _arc_from_tangent(p0, t0, j, eps)
    second = _arc_from_tangent(j, chord / lc, p3, eps)
    out = [s for s in (first, second) if s is not None]
    return out or None


def _distance_to_segment(pts: NDArray[np.float64], seg: Segment) -> NDArray[np.float64]:
    """Exact distance (n,) from points (n, 2) to one arc or line segment."""
    if isinstance(seg, Line):
        d = seg.end - seg.start
        t = np.clip(((pts - seg.start) @ d) / float(d @ d), 0.0, 1.0)
        return np.hypot(*(pts - (seg.start + t[:, None] * d)).T)
    rel = pts - seg.center
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    a0 = np.arctan2(*(seg.start - seg.center)[::-1])
    # Angle travelled from the start in the arc's direction, in [0, 2 pi).
    trav = np.mod((ang - a0) if seg.ccw else (a0 - ang), 2.0 * np.pi)
    on_arc = trav <= seg.sweep
    radial = np.abs(np.hypot(rel[:, 0], rel[:, 1]) - seg.radius)
    ends = np.minimum(np.hypot(*(pts - seg.start).T), np.hypot(*(pts - seg.end).T))
    return np.where(on_arc, radial, ends)


def segments_distance(pts: ArrayLike, segments: list[Segment]) -> NDArray[np.float64]:
    """Distance (n,) from each point (n, 2) to the nearest of ``segments`` (arcs/lines)."""
    p = np.asarray(pts, dtype=float)
    if not segments:
        raise InputError("segments_distance needs at least one segment")
    return np.min(np.stack([_distance_to_segment(p, s) for s in segments]), axis=0)


def sample_segments(segments: list[Segment], per_segment: int = 16) -> NDArray[np.float64]:
    """Points (m, 2) along a chain of arcs/lines, ``per_segment`` per segment, both ends."""
    if not segments:
        return np.zeros((0, 2))
    return np.concatenate([s.sample(per_segment) for s in segments])


def _straight(c: NDArray[np.float64]) -> list[Segment] | None:
    """Lines for a Bézier whose control points are collinear, else None.

    A collinear cubic is a straight path but may run past P3 (or behind P0) and come back,
    so it is cut at the turning points of its projection onto the line.
    """
    p0 = c[0]
    ext = c - p0
    axis_i = int(np.argmax(np.hypot(ext[:, 0], ext[:, 1])))
    d = ext[axis_i]
    ld = float(np.hypot(*d))
    if ld <= 1e-12 * _scale(c):
        return None
    dn = d / ld
    if np.max(np.abs(_cross(ext, dn))) > 1e-9 * ld:
        return None
    # Projection u(t) onto the line is a 1D cubic; its turning points split the path.
    u_ctrl = ext @ dn
    co = power_coefficients(u_ctrl[:, None])[:, 0]
    # u'(t) = co1 + 2 co2 t + 3 co3 t^2
    roots = np.roots([3.0 * co[3], 2.0 * co[2], co[1]]) if np.any(co[1:] != 0) else np.zeros(0)
    ts = sorted(
        float(r.real)
        for r in np.atleast_1d(roots)
        if abs(r.imag) < 1e-12 and 1e-9 < r.real < 1.0 - 1e-9
    )
    pts = evaluate(c, np.array([0.0, *ts, 1.0]))
    pts[0], pts[-1] = c[0], c[3]  # exact end points keep loops closed bit for bit
    eps = 1e-12 * _scale(c)
    out: list[Segment] = [
        Line(pts[k].copy(), pts[k + 1].copy())
        for k in range(len(pts) - 1)
        if np.hypot(*(pts[k + 1] - pts[k])) > eps
    ]
    return out


def bezier_to_arcs(ctrl: ArrayLike, tol: float) -> list[Segment]:
    """Approximate one cubic Bézier by G1 biarcs (and lines) within ``tol``.

    The curve is split at its inflection points, then each piece is fitted by the incenter
    biarc and subdivided (de Casteljau at t = 1/2) until the largest distance from
    ``32`` samples of the piece to its biarc is at most ``tol`` (or the depth cap of 16 is
    reached). Straight (collinear) pieces become :class:`Line` segments. Consecutive
    segments share end points exactly and are tangent-continuous wherever the Bézier is.

    Parameters
    ----------
    ctrl : (4, 2) float
        Control points.
    tol : float
        Maximum distance between the Bézier and the returned arcs, in the units of ``ctrl``.

    Returns
    -------
    list of Arc or Line
        Ordered from ``ctrl[0]`` to ``ctrl[3]``; empty when the curve is a single point.
    """
    c = _check(ctrl, tol)
    whole_line = _straight(c)
    if whole_line is not None:
        return whole_line
    if _end_tangents(c) is None:
        return []

    # Split at inflections first: a biarc cannot follow an S bend within one piece.
    pieces: list[NDArray[np.float64]] = []
    rest, t_done = c, 0.0
    for t in inflections(c):
        left, rest = split(rest, (t - t_done) / (1.0 - t_done))
        pieces.append(left)
        t_done = t
    pieces.append(rest)

    ts = np.linspace(0.0, 1.0, _N_SAMPLES)
    out: list[Segment] = []
    # Depth-first stack (reversed so pieces come out in curve order) instead of recursion.
    stack: list[tuple[NDArray[np.float64], int]] = [(p, 0) for p in reversed(pieces)]
    while stack:
        piece, depth = stack.pop()
        straight = _straight(piece)
        if straight is not None:
            out.extend(straight)
            continue
        tangents = _end_tangents(piece)
        if tangents is None:
            continue  # collapsed to a point: contributes nothing
        t0, t1 = tangents
        turn = abs(float(np.arctan2(_cross(t0, t1), t0 @ t1)))
        biarc = _incenter_biarc(piece, t0, t1) if turn <= _MAX_TURN else None
        if biarc is not None:
            err = _biarc_error(piece, biarc, ts, tol)
            if err <= tol or depth >= _MAX_DEPTH:
                out.extend(biarc)
                continue
        elif depth >= _MAX_DEPTH:
            # A tiny piece the biarc cannot describe (cusp remnant): a chord is within tol.
            if np.hypot(*(piece[3] - piece[0])) > 1e-12 * _scale(piece):
                out.append(Line(piece[0].copy(), piece[3].copy()))
            continue
        left, right = split(piece, 0.5)
        stack.append((right, depth + 1))
        stack.append((left, depth + 1))
    # Exact shared end points so chains of Béziers stay closed without gaps.
    if out:
        out[0] = _with_start(out[0], c[0])
        out[-1] = _with_end(out[-1], c[3])
    return out


def _biarc_error(
    piece: NDArray[np.float64], biarc: list[Segment], ts: NDArray[np.float64], tol: float
) -> float:
    """Largest distance from the Bézier ``piece`` to ``biarc``, sampled then refined.

    Uniform samples miss the peak between two samples by a few percent, so the (at most
    four) sampled local maxima above half the tolerance are re-sampled finely over their
    neighbouring intervals before the result is compared with the tolerance.
    """
    err = segments_distance(evaluate(piece, ts), biarc)
    best = float(np.max(err))
    if best > tol:
        return best  # rejected anyway: refinement cannot lower the maximum
    padded = np.concatenate([[-np.inf], err, [-np.inf]])
    peaks = np.flatnonzero((err >= padded[:-2]) & (err >= padded[2:]) & (err > 0.5 * tol))
    peaks = peaks[np.argsort(err[peaks])[::-1][:4]]
    if len(peaks) == 0:
        return best
    step = ts[1] - ts[0]
    fine = np.linspace(-step, step, 17)
    t_ref = np.clip((ts[peaks][:, None] + fine).ravel(), 0.0, 1.0)
    return max(best, float(np.max(segments_distance(evaluate(piece, t_ref), biarc))))


def _with_start(seg: Segment, p: NDArray[np.float64]) -> Segment:
    if isinstance(seg, Line):
        return Line(p.copy(), seg.end)
    return Arc(p.copy(), seg.end, seg.center, seg.radius, seg.ccw)


def _with_end(seg: Segment, p: NDArray[np.float64]) -> Segment:
    if isinstance(seg, Line):
        return Line(seg.start, p.copy())
    return Arc(seg.start, p.copy(), seg.center, seg.radius, seg.ccw)


def bezier_to_polyline(ctrl: ArrayLike, tol: float) -> NDArray[np.float64]:
    """Flatten one cubic Bézier into a polyline whose chord error is at most ``tol``.

    A piece is accepted when both inner control points lie within ``tol`` of the chord
    P0P3: by the convex hull property the curve then stays within ``tol`` of the chord, and
    since the curve runs from P0 to P3 every chord point is within ``tol`` of the curve.
    Pieces are halved (de Casteljau) otherwise, up to a depth of 16.

    Parameters
    ----------
    ctrl : (4, 2) float
    tol : float
        Maximum distance between the polyline and the curve.

    Returns
    -------
    (n, 2) float
        Vertices from ``ctrl[0]`` to ``ctrl[3]`` inclusive, n >= 2.
    """
    c = _check(ctrl, tol)
    pts: list[NDArray[np.float64]] = [c[0]]
    stack: list[tuple[NDArray[np.float64], int]] = [(c, 0)]
    while stack:
        piece, depth = stack.pop()
        if depth >= _MAX_DEPTH or _flat_error(piece) <= tol:
            pts.append(piece[3])
            continue
        left, right = split(piece, 0.5)
        stack.append((right, depth + 1))
        stack.append((left, depth + 1))
    out = np.array(pts)
    out[-1] = c[3]
    return out


def _flat_error(c: NDArray[np.float64]) -> float:
    """Largest distance from the inner control points (2, 2) to the chord segment."""
    a, b = c[0], c[3]
    d = b - a
    dd = float(d @ d)
    inner = c[1:3]
    if dd == 0.0:
        return float(np.max(np.hypot(*(inner - a).T)))
    t = np.clip(((inner - a) @ d) / dd, 0.0, 1.0)
    return float(np.max(np.hypot(*(inner - (a + t[:, None] * d)).T)))
