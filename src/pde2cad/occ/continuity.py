"""Measure gaps and normal kinks across the shared edges of a (read-back) shape.

For every edge bounded by two faces, points are sampled along the edge; each sample is
mapped into both faces through the edge's pcurves (the face-local parameter curves that
STEP/IGES carry and sewing builds), evaluated on both surfaces, and compared:

* **gap** -- distance between the two surface points: the position (G0) mismatch;
* **angle** -- angle between the two outward normals (each flipped when its face is
  ``TopAbs_REVERSED``): the tangent-plane (G1) mismatch. A consistently oriented smooth
  shell gives 0; a crease gives its dihedral kink.

When an edge has no pcurve on a face the 3D edge point is projected onto that face's
surface instead (``ShapeAnalysis_Surface.ValueOfUV``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Curve2d, BRepAdaptor_Surface
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepLProp import BRepLProp_SLProps
from OCP.ShapeAnalysis import ShapeAnalysis_Surface
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_REVERSED, TopAbs_SHELL
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape, TopTools_IndexedMapOfShape

from pde2cad.errors import InputError


def _faces_of(ancestors: Any) -> list[TopoDS_Face]:
    """Distinct faces in an ancestor list (a seam edge lists its one face twice)."""
    out: list[TopoDS_Face] = []
    for shape in ancestors:
        face = TopoDS.Face_s(shape)
        if not any(face.IsSame(f) for f in out):
            out.append(face)
    return out


class _FaceSampler:
    """Point and oriented unit normal of one face at the parameter of an edge."""

    def __init__(self, face: TopoDS_Face, edge: TopoDS_Edge) -> None:
        self.surface = BRepAdaptor_Surface(face, True)
        self.flip = face.Orientation() == TopAbs_REVERSED
        self.props = BRepLProp_SLProps(self.surface, 1, 1e-9)
        self.pcurve: BRepAdaptor_Curve2d | None
        try:
            # The pcurve may be stored for the reversed edge orientation, so pass the edge
            # as it sits in this face; BRepAdaptor_Curve2d looks it up by IsSame.
            self.pcurve = BRepAdaptor_Curve2d(edge, face)
        except Exception:  # noqa: BLE001 - OCCT raises Standard_NullObject without a pcurve
            self.pcurve = None
        # BRep_Tool.Surface(face) is the untransformed surface; the face location is applied
        # to the query point instead (inverted) before projecting.
        self.location = face.Location()
        self.projector = (
            ShapeAnalysis_Surface(BRep_Tool.Surface_s(face)) if self.pcurve is None else None
        )

    def uv(self, t: float, point: Any) -> tuple[float, float]:
        if self.pcurve is not None:
            p2 = self.pcurve.Value(t)
            return p2.X(), p2.Y()
        assert self.projector is not None
        local = point.Transformed(self.location.Transformation().Inverted())
        p2 = self.projector.ValueOfUV(local, 1e-9)
        return p2.X(), p2.Y()

    def sample(self, t: float, point: Any) -> tuple[np.ndarray, np.ndarray | None]:
        u, v = self.uv(t, point)
        self.props.SetParameters(u, v)
        p = self.props.Value()
        xyz = np.array([p.X(), p.Y(), p.Z()])
        if not self.props.IsNormalDefined():
            return xyz, None
        n = self.props.Normal()
        normal = np.array([n.X(), n.Y(), n.Z()])
        return xyz, -normal if self.flip else normal


def _edge_deviation(
    edge: TopoDS_Edge, f1: TopoDS_Face, f2: TopoDS_Face, samples: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Edge points (samples, 3), gaps (samples,) and normal angles in degrees (samples,).

    An angle is NaN where either face has no defined normal (e.g. at a collapsed pole).
    """
    curve = BRepAdaptor_Curve(edge)
    t0, t1 = curve.FirstParameter(), curve.LastParameter()
    s1, s2 = _FaceSampler(f1, edge), _FaceSampler(f2, edge)
    xyz = np.empty((samples, 3))
    gaps = np.empty(samples)
    angles = np.full(samples, np.nan)
    for k, t in enumerate(np.linspace(t0, t1, samples)):
        point = curve.Value(float(t))
        xyz[k] = point.X(), point.Y(), point.Z()
        p1, n1 = s1.sample(float(t), point)
        p2, n2 = s2.sample(float(t), point)
        gaps[k] = float(np.linalg.norm(p1 - p2))
        if n1 is not None and n2 is not None:
            # atan2 of |cross| and dot keeps full precision near 0 deg, where arccos of a
            # dot product close to 1 would lose about half the digits.
            sin = float(np.linalg.norm(np.cross(n1, n2)))
            angles[k] = math.degrees(math.atan2(sin, float(n1 @ n2)))
    return xyz, gaps, angles


def measure(shape: TopoDS_Shape, samples: int = 20, *, profile: bool = False) -> dict[str, Any]:
    """Measure position gaps and normal angles across every edge shared by two faces.

    Parameters
    ----------
    shape : TopoDS_Shape
        Shell, solid or compound, typically read back from STEP/IGES.
    samples : int
        Points per edge (including both ends), at least 2.
    profile : bool
        Also return, per shared edge, the samples themselves (see below). Off by default:
        the profile costs nothing extra to compute but makes the result larger.

    Returns
    -------
    dict
        ``{"max_gap", "max_angle_deg", "free_edges", "shared_edges", "n_faces", "valid",
        "closed", "edges"}`` where ``edges`` is a list of ``{"faces": (i, j), "max_gap",
        "max_angle_deg"}`` for shared edges, ``i`` and ``j`` being 0-based face indices in
        ``TopExp`` map order. Edges with more than two faces (non-manifold) are measured
        between their first two faces and counted in ``"nonmanifold_edges"``. ``closed``
        is true when there is at least one shell, every shell is closed, and no edge is free.
    """
    if samples < 2:
        raise InputError(f"samples must be at least 2, got {samples}")
    if shape is None or shape.IsNull():
        raise InputError("cannot measure a null shape")
    face_map = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_FACE, face_map)
    edge_faces = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, edge_faces)

    edges: list[dict[str, Any]] = []
    free = 0
    nonmanifold = 0
    for k in range(1, edge_faces.Extent() + 1):
        edge = TopoDS.Edge_s(edge_faces.FindKey(k))
        # Degenerate edges (a pole collapsed to a point) have no 3D curve to sample.
        if BRep_Tool.Degenerated_s(edge):
            continue
        faces = _faces_of(edge_faces.FindFromIndex(k))
        if len(faces) < 2:
            # A seam of a closed face also has one face but two pcurves; it is not free.
            if len(faces) == 1 and BRep_Tool.IsClosed_s(edge, faces[0]):
                continue
            free += 1
            continue
        if len(faces) > 2:
            nonmanifold += 1
        xyz, gaps, angles = _edge_deviation(edge, faces[0], faces[1], samples)
        defined = angles[~np.isnan(angles)]
        entry: dict[str, Any] = {
            "faces": (face_map.FindIndex(faces[0]) - 1, face_map.FindIndex(faces[1]) - 1),
            "max_gap": float(gaps.max()),
            "max_angle_deg": float(defined.max()) if len(defined) else 0.0,
        }
        if profile:
            entry["profile"] = {"points": xyz, "angles_deg": angles, "gaps": gaps}
        edges.append(entry)

    shells = []
    explorer = TopExp_Explorer(shape, TopAbs_SHELL)
    while explorer.More():
        shells.append(TopoDS.Shell_s(explorer.Current()))
        explorer.Next()
    closed = bool(shells) and free == 0 and all(BRep_Tool.IsClosed_s(s) for s in shells)
    return {
        "max_gap": max((e["max_gap"] for e in edges), default=0.0),
        "max_angle_deg": max((e["max_angle_deg"] for e in edges), default=0.0),
        "free_edges": free,
        "shared_edges": len(edges),
        "nonmanifold_edges": nonmanifold,
        "n_faces": face_map.Extent(),
        "n_shells": len(shells),
        "valid": bool(BRepCheck_Analyzer(shape).IsValid()),
        "closed": closed,
        "edges": edges,
    }


__all__ = ["measure"]
