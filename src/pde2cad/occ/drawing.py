"""Vectorized drawings as planar OCP faces, ready for build123d's / CadQuery's ``extrude``.

Each shape of a :class:`~pde2cad.image.drawing.Drawing` (an outer loop and its holes)
becomes one face in the XY plane: every cubic Bézier an exact ``Geom_BezierCurve`` edge,
consecutive edges sharing one vertex, the outer wire counter-clockwise and the holes
clockwise seen from +Z (so the face normal is +Z and ``extrude(face, h)`` grows upwards).
Coordinates follow the DXF writer: ``x = x_px * s``, ``y = (height - y_px) * s`` with
``s = mm_per_px`` when the drawing has a scale (the faces are then in mm), else 1 (pixels).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from OCP.BRepBuilderAPI import (
    BRepBuilderAPI_MakeEdge,
    BRepBuilderAPI_MakeFace,
    BRepBuilderAPI_MakeVertex,
    BRepBuilderAPI_MakeWire,
)
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.Geom import Geom_BezierCurve
from OCP.gp import gp_Pln, gp_Pnt
from OCP.TColgp import TColgp_Array1OfPnt
from OCP.TopoDS import TopoDS_Face, TopoDS_Wire

from pde2cad.errors import ExportError, InputError

if TYPE_CHECKING:
    from pde2cad.image.drawing import Drawing

#: Shortest chord of a curve kept as an edge: 10 x OCCT's absolute confusion (1e-7), the
#: distance under which it merges two vertices.
MIN_CHORD = 1e-6


def _plane_coords(curves: NDArray[np.float64], height: int, scale: float) -> NDArray[np.float64]:
    """Image pixels (y down) to plane coordinates (y up, scaled): (K, 4, 2)."""
    out = np.array(curves, dtype=float) * scale
    out[..., 1] = height * scale - out[..., 1]
    return out


def _signed_area(curves: NDArray[np.float64]) -> float:
    """Signed area of the closed Bézier loop (K, 4, 2), positive counter-clockwise: the
    exact Green integral of a cubic, ``(1/20) * sum`` of the control-point cross terms."""
    p0, p1, p2, p3 = (curves[:, i] for i in range(4))

    def cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]

    total = (
        6 * cross(p0, p1) + 3 * cross(p0, p2) + cross(p0, p3)
        + 3 * cross(p1, p2) + 3 * cross(p1, p3) + 6 * cross(p2, p3)
    )
    return float(total.sum() / 20.0)


def _split_loops(curves: NDArray[np.float64]) -> NDArray[np.float64]:
    """Curves that start and end at one point but are not a point (a small hole fitted with
    one cubic) split in two at t = 1/2 (de Casteljau), so every edge has two vertices."""
    chord = np.linalg.norm(curves[:, 3] - curves[:, 0], axis=1)
    polygon = np.linalg.norm(np.diff(curves, axis=1), axis=2).sum(axis=1)
    split = (chord <= MIN_CHORD) & (polygon > 4 * MIN_CHORD)
    if not split.any():
        return curves
    p = curves[split]
    a = (p[:, :-1] + p[:, 1:]) / 2
    b = (a[:, :-1] + a[:, 1:]) / 2
    c = (b[:, 0] + b[:, 1]) / 2
    left = np.stack([p[:, 0], a[:, 0], b[:, 0], c], axis=1)
    right = np.stack([c, b[:, 1], a[:, 2], p[:, 3]], axis=1)
    pieces = [[cv] for cv in curves]
    for k, i in enumerate(np.flatnonzero(split)):
        pieces[i] = [left[k], right[k]]
    return np.array([cv for group in pieces for cv in group])


def _wire(curves: NDArray[np.float64], counter_clockwise: bool) -> TopoDS_Wire:
    """One closed wire of Bézier edges, turned to the asked orientation.

    1. Reverse the loop (curve order and each curve's control points) if it runs the other way.
    2. A curve closing on itself is split in two (:func:`_split_loops`).
    3. Curves whose ends are closer than ``MIN_CHORD`` are dropped and the next curve starts
       where the previous kept one ends (OCCT takes such ends as one vertex and refuses the
       edge); a loop then differs from the drawing by at most that much per dropped curve.
    4. One vertex per join, shared by the two edges that meet there.
    """
    if (_signed_area(curves) > 0) != counter_clockwise:
        curves = curves[::-1, ::-1]
    curves = _split_loops(curves)
    curves = curves[np.linalg.norm(curves[:, 3] - curves[:, 0], axis=1) > MIN_CHORD].copy()
    if len(curves) == 0:
        raise InputError("a drawing loop has no curve of non-zero length")
    curves[:, 0] = np.roll(curves[:, 3], 1, axis=0)
    starts = [BRepBuilderAPI_MakeVertex(gp_Pnt(float(x), float(y), 0.0)).Vertex()
              for x, y in curves[:, 0]]
    maker = BRepBuilderAPI_MakeWire()
    for k, c in enumerate(curves):
        poles = TColgp_Array1OfPnt(1, 4)
        for i, (x, y) in enumerate(c, start=1):
            poles.SetValue(i, gp_Pnt(float(x), float(y), 0.0))
        edge = BRepBuilderAPI_MakeEdge(
            Geom_BezierCurve(poles), starts[k], starts[(k + 1) % len(curves)]
        )
        if not edge.IsDone():
            raise ExportError(f"OCCT could not make an edge of a drawing loop (error {edge.Error()})")
        maker.Add(edge.Edge())
    if not maker.IsDone():
        raise ExportError("OCCT could not join a drawing loop into a wire")
    return maker.Wire()


def drawing_faces(drawing: Drawing) -> list[TopoDS_Face]:
    """One planar face per shape of ``drawing`` (outer loop with its holes), in +Z.

    Parameters
    ----------
    drawing : Drawing

    Returns
    -------
    list of TopoDS_Face
        In the order of :meth:`Drawing.shapes`; in mm when ``drawing.mm_per_px`` is set.

    Raises
    ------
    InputError
        A drawing that does not validate, a shape without an outer loop, or no loops at all.
    ExportError
        Some shapes' outlines cross themselves (fitted curves overshooting each other at a
        sharp corner of a ragged region): the message lists them.
    """
    drawing.validate()
    scale = float(drawing.mm_per_px) if drawing.mm_per_px is not None else 1.0
    faces, broken = [], []
    for group in drawing.shapes():
        outer = [lp for lp in group if not lp.is_hole]
        if len(outer) != 1:
            raise InputError(f"shape {group[0].shape} has {len(outer)} outer loops; expected 1")
        coords = [_plane_coords(lp.curves, drawing.height, scale) for lp in group]
        maker = BRepBuilderAPI_MakeFace(gp_Pln(), _wire(coords[0], True), True)
        for hole in coords[1:]:
            maker.Add(_wire(hole, False))
        # No healing: ShapeFix can untangle some crossings, but the faces it returns may
        # extrude to invalid solids (measured on a photo); an exact outline or an error.
        if maker.IsDone() and BRepCheck_Analyzer(maker.Face()).IsValid():
            faces.append(maker.Face())
        else:
            broken.append(group[0].shape)
    if broken:
        raise ExportError(
            f"the outlines of shape(s) {broken[:10]} cross themselves or their holes (a fit "
            "within the tolerance of a ragged or one-pixel-thin region), so they bound no "
            "valid face; vectorize with a smaller tolerance, or smooth the image first"
        )
    if not faces:
        raise InputError("the drawing has no loops to make faces of")
    return faces


def drawing_to_build123d(drawing: Drawing) -> list[Any]:
    """:func:`drawing_faces` as build123d ``Face`` objects."""
    from build123d import Face

    return [Face(face) for face in drawing_faces(drawing)]


def drawing_to_cadquery(drawing: Drawing) -> list[Any]:
    """:func:`drawing_faces` as CadQuery ``Face`` objects."""
    from cadquery import Face

    return [Face(face) for face in drawing_faces(drawing)]


__all__ = ["drawing_faces", "drawing_to_build123d", "drawing_to_cadquery"]
