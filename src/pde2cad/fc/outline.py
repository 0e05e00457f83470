"""FreeCAD adapter of the image side: a :class:`~pde2cad.image.drawing.Drawing` to Part faces
(ready for Pad / Extrude) and to a constrained Sketcher sketch.

Coordinates: the drawing's pixels (x right, y down) become millimetres in the plane of the
sketch, y up, as in the DXF writer: ``(x * s, (height - y) * s)`` with ``s`` mm per pixel
(:func:`pde2cad.io.dxf.to_dxf_coords`).

Each cubic Bézier becomes one sketch piece: a line segment where its control points lie on
its chord (a straight run), otherwise a degree-3 B-spline with the four Bézier control
points as poles (Sketcher 0.20 has no Bézier geometry; this B-spline is the same curve).
At every joint the end of one piece is tied to the start of the next: an endpoint-to-
endpoint ``Tangent`` constraint at a G1 join (in Sketcher that constraint *is* coincidence
plus tangency; adding a ``Coincident`` as well makes the sketch redundant), a
``Coincident`` constraint at every other joint (corners).
"""

from __future__ import annotations

from typing import Any

import FreeCAD  # noqa: F401  (initialises the application before Part)
import numpy as np
import Part
import Sketcher
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import InputError
from pde2cad.image.drawing import Drawing
from pde2cad.io.dxf import to_dxf_coords

#: A Bézier is a straight run when its inner control points are this close to the chord
#: (relative to the chord length) and between its ends: the vectorizer writes straight runs
#: with handles exactly on the chord, so this only absorbs rounding.
STRAIGHT = 1e-9
#: A joint is G1 when the sine of the angle between the incoming and outgoing tangents is
#: below this (G1 joins are collinear handles, exact to rounding).
SMOOTH = 1e-9
#: Largest tolerance ShapeFix may use on an invalid face, as a fraction of the fit tolerance.
FIX_FRACTION = 0.01
#: Sketch plane -> rotation of the sketch placement (FreeCAD's own XY/XZ/YZ planes).
PLANES = {
    "XY": FreeCAD.Rotation(),
    "XZ": FreeCAD.Rotation(FreeCAD.Vector(1, 0, 0), 90),
    "YZ": FreeCAD.Rotation(0.5, 0.5, 0.5, 0.5),
}


def plane_placement(plane: str) -> FreeCAD.Placement:
    """The placement of a sketch on ``plane`` ("XY", "XZ" or "YZ") through the origin."""
    if plane not in PLANES:
        raise InputError(f"plane must be one of {', '.join(PLANES)}, got {plane!r}")
    return FreeCAD.Placement(FreeCAD.Vector(), PLANES[plane])


def drawing_mm(drawing: Drawing, mm_per_px: float) -> list[NDArray[np.float64]]:
    """Every loop's Béziers ``(K, 4, 2)`` in millimetres, y up (loop order of the drawing),
    without Béziers collapsed to a point (no geometry, and Part rejects them), untangled at
    corners (:func:`untangle`)."""
    out = []
    for loop in drawing.loops:
        curves = to_dxf_coords(np.asarray(loop.curves, dtype=float).reshape(-1, 4, 2),
                               drawing.height, mm_per_px)
        spread = np.abs(curves - curves[:, :1]).max(axis=(1, 2), initial=0.0)
        out.append(untangle(curves[spread > 1e-12 * max(drawing.width, drawing.height) * mm_per_px]))
    return out


# --------------------------------------------------------------------------- untangling
def _bezier(c: NDArray[np.float64], t: ArrayLike, d: int = 0) -> NDArray[np.float64]:
    """Points (``d = 0``) or first derivatives (``d = 1``) of the cubic ``c (4, 2)`` at ``t``."""
    t = np.asarray(t, dtype=float)[..., None]
    if d == 1:
        q = 3 * np.diff(c, axis=0)
        return (1 - t) ** 2 * q[0] + 2 * (1 - t) * t * q[1] + t**2 * q[2]
    return (1 - t) ** 3 * c[0] + 3 * (1 - t) ** 2 * t * c[1] + 3 * (1 - t) * t**2 * c[2] + t**3 * c[3]


def split(c: NDArray[np.float64], t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """De Casteljau: the cubic ``c (4, 2)`` cut at ``t`` into two cubics (exactly)."""
    a = c[:-1] + t * np.diff(c, axis=0)
    b = a[:-1] + t * np.diff(a, axis=0)
    m = b[0] + t * (b[1] - b[0])
    return np.array([c[0], a[0], b[0], m]), np.array([m, b[1], a[2], c[3]])


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _polyline_hits(p: NDArray[np.float64], q: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Proper crossings of the polylines ``p`` and ``q``: segment pairs ``(i, j)`` (rows of
    the returned index array) and the fractions along each (shared end points do not count)."""
    r, s = np.diff(p, axis=0)[:, None], np.diff(q, axis=0)[None, :]
    qp = q[None, :-1] - p[:-1, None]
    den = _cross(r, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = _cross(qp, s) / den, _cross(qp, r) / den
    hit = (x > 0) & (x < 1) & (y > 0) & (y < 1) & (np.abs(den) > 0)
    ij = np.argwhere(hit)
    return ij, x[hit], y[hit]


def _refine(a: NDArray[np.float64], b: NDArray[np.float64], u: float, v: float) -> tuple[float, float] | None:
    """Newton steps on ``a(u) - b(v) = 0`` from ``(u, v)``; None when it leaves (0, 1)."""
    for _ in range(8):
        f = _bezier(a, u) - _bezier(b, v)
        jac = np.column_stack([_bezier(a, u, 1), -_bezier(b, v, 1)])
        if abs(np.linalg.det(jac)) < 1e-300:
            break
        du, dv = np.linalg.solve(jac, -f)
        u, v = float(np.clip(u + du, 0, 1)), float(np.clip(v + dv, 0, 1))
    return (u, v) if 0 < u < 1 and 0 < v < 1 else None


def crossing(
    a: NDArray[np.float64], b: NDArray[np.float64], samples: int = 200, zoom: int = 2
) -> tuple[float, float] | None:
    """Where the cubic ``a`` crosses the cubic ``b`` that starts at its end, nearest that
    joint along ``a``: parameters ``(u, v)`` with ``a(u) = b(v)``, or None.

    1. Proper crossings of the two sampled polylines (the shared end point does not count).
    2. The one of largest ``u``, refined by Newton steps on ``a(u) - b(v)``.
    3. None found: the last sample span of ``a`` and the first of ``b`` share the joint, so
       a crossing inside them (a cusp whose two sides run back over each other) cannot show;
       look again in those spans, magnified ``samples`` times (``zoom`` levels).
    """
    t = np.linspace(0.0, 1.0, samples + 1)
    ij, x, y = _polyline_hits(_bezier(a, t), _bezier(b, t))
    if len(ij):
        k = int(np.argmax(ij[:, 0] + x))
        return _refine(a, b, t[ij[k, 0]] + x[k] / samples, t[ij[k, 1]] + y[k] / samples)
    if zoom <= 0:
        return None
    h = 1.0 / samples
    inner = crossing(split(a, 1.0 - h)[1], split(b, h)[0], samples, zoom - 1)
    if inner is None:
        return None
    return _refine(a, b, 1.0 - h + inner[0] * h, inner[1] * h)


def self_crossing(a: NDArray[np.float64], samples: int = 200) -> tuple[float, float] | None:
    """The parameters ``u1 < u2`` where the cubic ``a`` crosses itself (a loop), or None."""
    t = np.linspace(0.0, 1.0, samples + 1)
    p = _bezier(a, t)
    ij, x, y = _polyline_hits(p, p)
    keep = ij[:, 1] >= ij[:, 0] + 2
    if not keep.any():
        return None
    (i, j), xi, yj = ij[keep][0], x[keep][0], y[keep][0]
    return _refine(a, a, t[i] + xi / samples, t[j] + yj / samples)


def _cut_loops(curves: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each cubic that loops on itself becomes two, meeting at the crossing (a corner); the
    loop between them is dropped."""
    out = []
    for c in curves:
        uv = self_crossing(c)
        if uv is None or not uv[0] < uv[1]:
            out.append(c)
            continue
        head = split(c, uv[0])[0]
        tail = split(c, uv[1])[1]
        tail[0] = head[3]
        out.extend([head, tail])
    return np.asarray(out, dtype=float).reshape(-1, 4, 2)


def untangle(curves: NDArray[np.float64]) -> NDArray[np.float64]:
    """Make a loop simple where the fit left sub-tolerance tangles (which make the wire
    self-intersecting: no valid face, no Pad).

    1. A cubic that loops on itself is cut at its crossing into two (:func:`_cut_loops`).
    2. Where two consecutive Béziers cross just before a corner joint (not G1; both
       overshoot the corner), both are cut at the crossing (:func:`split`), which becomes
       the joint; only the tiny "fishtail" beyond it is dropped.
    """
    out = _cut_loops(np.array(curves, dtype=float))
    smooth = smooth_joints(out) if len(out) > 1 else np.ones(len(out), dtype=bool)
    for k in np.flatnonzero(~smooth):
        nxt = (k + 1) % len(out)
        uv = crossing(out[k], out[nxt])
        if uv is None:
            continue
        out[k] = split(out[k], uv[0])[0]
        out[nxt] = split(out[nxt], uv[1])[1]
        out[nxt, 0] = out[k, 3]
    return out


def straight(curves: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(K,)``: which Béziers ``(K, 4, 2)`` are straight runs (handles on the chord, inside)."""
    chord = curves[:, 3] - curves[:, 0]
    length2 = np.maximum(np.einsum("kd,kd->k", chord, chord), 1e-300)
    rel = curves[:, 1:3] - curves[:, None, 0]
    t = np.einsum("khd,kd->kh", rel, chord) / length2[:, None]
    off = np.abs(rel[..., 0] * chord[:, None, 1] - rel[..., 1] * chord[:, None, 0])
    on_chord = off <= STRAIGHT * length2[:, None]
    return np.all(on_chord & (t >= 0) & (t <= 1), axis=1) & (length2 > 1e-300)


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def smooth_joints(curves: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(K,)``: whether the joint from Bézier ``k`` to Bézier ``k + 1`` (cyclic) is G1.

    Tangents are taken from the first control point distinct from the end (a zero-length
    handle leaves the direction to the next control point)."""
    def direction(a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64]) -> NDArray[np.float64]:
        d = b - a
        short = np.linalg.norm(d, axis=1) <= 1e-12 * np.maximum(np.linalg.norm(c - a, axis=1), 1.0)
        d[short] = (c - a)[short]
        return _unit(d)

    t_in = -direction(curves[:, 3], curves[:, 2], curves[:, 1])
    nxt = np.roll(curves, -1, axis=0)
    t_out = direction(nxt[:, 0], nxt[:, 1], nxt[:, 2])
    sine = np.abs(t_in[:, 0] * t_out[:, 1] - t_in[:, 1] * t_out[:, 0])
    return (sine <= SMOOTH) & (np.einsum("kd,kd->k", t_in, t_out) > 0)


def _vec(p: NDArray[np.float64]) -> FreeCAD.Vector:
    return FreeCAD.Vector(float(p[0]), float(p[1]), 0.0)


def piece(bezier: NDArray[np.float64], is_straight: bool) -> Any:
    """The sketch/Part geometry of one Bézier ``(4, 2)``: a ``Part.LineSegment`` or a
    degree-3 ``Part.BSplineCurve`` with the control points as poles."""
    if is_straight:
        return Part.LineSegment(_vec(bezier[0]), _vec(bezier[3]))
    curve = Part.BSplineCurve()
    curve.buildFromPolesMultsKnots([_vec(p) for p in bezier], [4, 4], [0.0, 1.0], False, 3)
    return curve


def loop_wire(curves: NDArray[np.float64]) -> Part.Wire:
    """The closed wire of one loop (in its own plane, z = 0)."""
    flags = straight(curves)
    edges = [piece(c, bool(s)).toShape() for c, s in zip(curves, flags)]
    wire = Part.Wire(edges)
    if not wire.isClosed():
        raise InputError("an outline loop does not close; refit the image with a larger tolerance")
    return wire


def outline_shape(drawing: Drawing, mm_per_px: float) -> Part.Shape:
    """A compound of one planar face per shape of the drawing (outer loop minus its holes).

    1. Each loop to a closed wire (:func:`loop_wire`), in mm.
    2. Per shape, ``Part.makeFace`` with the bullseye face maker (outer loop, holes inside).
    3. A face that is not valid (curves of a noisy loop crossing) is repaired by ShapeFix
       within ``FIX_FRACTION`` of the fit tolerance.

    Raises
    ------
    InputError
        The drawing has no loop.
    """
    loops = drawing_mm(drawing, mm_per_px)
    if not any(len(c) for c in loops):
        raise InputError("the image gave no outline loop; check the threshold or use invert")
    by_shape: dict[int, list[Part.Wire]] = {}
    for loop, curves in zip(drawing.loops, loops):
        if len(curves):
            by_shape.setdefault(loop.shape, []).append(loop_wire(curves))
    faces = [Part.makeFace(w, "Part::FaceMakerBullseye") for _, w in sorted(by_shape.items())]
    for face in faces:
        if not face.isValid():
            # A Bézier of a noisy loop can cross its neighbour within the fit tolerance
            # (measured: noisy_blob, logo_scanned); ShapeFix repairs the wire well below it.
            face.fix(1e-7, 1e-7, FIX_FRACTION * drawing.tolerance * mm_per_px)
    return Part.Compound(faces)


def _joint(prev: int, nxt: int, g1: bool) -> Any:
    """The constraint tying the end (2) of geometry ``prev`` to the start (1) of ``nxt``."""
    return Sketcher.Constraint("Tangent" if g1 else "Coincident", prev, 2, nxt, 1)


def fill_sketch(sketch: Any, drawing: Drawing, mm_per_px: float) -> dict[str, int]:
    """Replace the sketch's geometry by the drawing's loops, with their joint constraints.

    1. Delete the sketch's geometry and constraints.
    2. Per loop: one piece per Bézier (:func:`piece`), then one constraint per joint
       (:func:`_joint`), the last piece's end tied to the first's start.
    3. Solve; the geometry already satisfies every constraint, so nothing moves.

    Returns
    -------
    dict
        ``{"loops", "lines", "bsplines", "coincident", "tangent", "solver"}``, ``solver``
        being ``sketch.solve()`` (0 when solved without conflict or redundancy).
    """
    sketch.deleteAllGeometry()
    counts = {"loops": 0, "lines": 0, "bsplines": 0, "coincident": 0, "tangent": 0}
    constraints = []
    for curves in drawing_mm(drawing, mm_per_px):
        if not len(curves):
            continue
        flags, smooth = straight(curves), smooth_joints(curves)
        ids = list(sketch.addGeometry([piece(c, bool(s)) for c, s in zip(curves, flags)], False))
        for k, g in enumerate(ids):
            constraints.append(_joint(g, ids[(k + 1) % len(ids)], bool(smooth[k])))
        counts["loops"] += 1
        counts["lines"] += int(flags.sum())
        counts["bsplines"] += int((~flags).sum())
        counts["tangent"] += int(smooth.sum())
        counts["coincident"] += int((~smooth).sum())
    if constraints:
        sketch.addConstraint(constraints)
    counts["solver"] = int(sketch.solve())
    return counts


__all__ = [
    "PLANES", "drawing_mm", "fill_sketch", "loop_wire", "outline_shape", "piece",
    "plane_placement", "smooth_joints", "straight",
]
