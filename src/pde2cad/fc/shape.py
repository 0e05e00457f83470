"""FreeCAD Part adapter of the reconstruction: a :class:`~pde2cad.reconstruct.SurfaceModel`
to a sewn ``Part`` shell or solid, and the continuity figures measured on it.

The counterpart of :func:`pde2cad.occ.build.build_shape` for FreeCAD's own OpenCASCADE
(never import this module in a process that imported OCP: the two bundle different
OpenCASCADE builds). It needs FreeCAD's ``Part`` module: run it inside FreeCAD, or in
Debian's ``/usr/bin/python3`` after adding ``/usr/lib/freecad-python3/lib`` to ``sys.path``.

The same model gives the same faces as the OCP adapter: one untrimmed face per B-spline
surface (its full parameter rectangle), sewn at ``model.sew_tolerance``, made a solid
(oriented outward) when the sewn shell is closed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import FreeCAD  # noqa: F401  (initialises the application before Part)
import numpy as np
import Part
from numpy.typing import NDArray

from pde2cad.errors import ExportError, InputError

if TYPE_CHECKING:
    from pde2cad.bspline.data import BSplineSurface
    from pde2cad.reconstruct import SurfaceModel

#: Knots closer than this fraction of the parameter range are one knot (rounding noise in a
#: computed full knot vector would otherwise give OCCT a zero-length span).
KNOT_MERGE = 1e-12


@dataclass(frozen=True)
class SewResult:
    """Topology of the sewn shape (the FreeCAD twin of :class:`pde2cad.occ.shape.SewInfo`).

    Attributes
    ----------
    n_faces, n_shells, n_free_edges : int
    is_closed : bool
        Exactly one shell, closed, without free edges.
    is_solid : bool
        A solid was made of it.
    valid : bool
        ``Shape.isValid()`` of the result.
    """

    n_faces: int
    n_shells: int
    n_free_edges: int
    is_closed: bool
    is_solid: bool
    valid: bool


def _knots(full: NDArray[np.float64]) -> tuple[list[float], list[int]]:
    """Distinct knots and multiplicities of a full clamped vector, merging rounding noise."""
    k = np.asarray(full, dtype=float)
    new = np.concatenate(([True], np.diff(k) > KNOT_MERGE * (k[-1] - k[0])))
    starts = np.flatnonzero(new)
    mults = np.diff(np.append(starts, k.size))
    return [float(x) for x in k[starts]], [int(m) for m in mults]


def to_part_surface(surface: BSplineSurface) -> Part.BSplineSurface:
    """A ``Part.BSplineSurface`` equal to a kernel-neutral one (pole ``(i, j)`` stays ``(i, j)``).

    Parameters
    ----------
    surface : BSplineSurface
        Poles ``(nu, nv, 3)``, full clamped knot vectors, degrees.

    Raises
    ------
    InputError
        OpenCASCADE rejected the data (inconsistent knots or poles).
    """
    poles = np.asarray(surface.poles, dtype=float)
    if poles.ndim != 3 or poles.shape[2] != 3:
        raise InputError(f"poles must have shape (nu, nv, 3), got {poles.shape}")
    ku, mu = _knots(surface.knots_u)
    kv, mv = _knots(surface.knots_v)
    net = [[FreeCAD.Vector(*map(float, p)) for p in row] for row in poles]
    part = Part.BSplineSurface()
    try:
        part.buildFromPolesMultsKnots(
            net, mu, mv, ku, kv, False, False, int(surface.degree_u), int(surface.degree_v)
        )
    except Exception as exc:  # noqa: BLE001 - Part raises Part.OCCError / RuntimeError
        raise InputError(f"FreeCAD rejected the B-spline surface: {exc}") from exc
    return part


def make_face(surface: BSplineSurface) -> Part.Face:
    """A face bounded by the surface's full parameter rectangle (collapsed sides become
    degenerated edges, as at the apex of a 3-sided patch)."""
    return Part.Face(to_part_surface(surface))


def _free_edges(shape: Part.Shape) -> int:
    """Edges of ``shape`` bounded by one face only (degenerated edges not counted)."""
    return sum(
        1 for e in shape.Edges
        if not e.Degenerated and len(shape.ancestorsOfType(e, Part.Face)) == 1
    )


def _as_solid(shell: Part.Shell) -> Part.Solid:
    """The solid of a closed shell, oriented so its volume is positive."""
    solid = Part.Solid(shell)
    if solid.Volume < 0:
        solid.reverse()
    return solid


def sew(faces: list[Part.Face], tolerance: float) -> tuple[Part.Shape, SewResult]:
    """Sew faces into a shell, and into a solid when the shell is closed.

    1. Sew a compound of the faces at ``tolerance`` (``Shape.sewShape``).
    2. One shell without free edges: make it a solid (outward).

    Raises
    ------
    InputError
        No faces, or a non-positive tolerance.
    ExportError
        Sewing failed.
    """
    if not faces:
        raise InputError("sewing needs at least one face")
    if not tolerance > 0:
        raise InputError(f"sewing tolerance must be positive, got {tolerance}")
    sewn = Part.Compound(faces)
    try:
        sewn.sewShape(float(tolerance))
    except Exception as exc:  # noqa: BLE001 - Part.OCCError
        raise ExportError(f"FreeCAD could not sew the faces: {exc}") from exc
    shells = sewn.Shells
    free = _free_edges(sewn)
    closed = len(shells) == 1 and shells[0].isClosed() and free == 0
    shape = _as_solid(shells[0]) if closed else (shells[0] if len(shells) == 1 else sewn)
    info = SewResult(
        n_faces=len(shape.Faces), n_shells=len(shells), n_free_edges=free,
        is_closed=closed, is_solid=closed, valid=bool(shape.isValid()),
    )
    return shape, info


def build_shape(model: SurfaceModel) -> tuple[Part.Shape, list[Part.Face], SewResult]:
    """Faces of the model's surfaces, sewn into a shell (a solid when closed).

    1. One face per surface, in ``model.labels`` order.
    2. Sew them at ``model.sew_tolerance`` (:func:`sew`).

    Returns
    -------
    shape : Part.Shape
        ``Part.Solid`` when closed, else the sewn ``Part.Shell`` (or a compound of shells).
    faces : list of Part.Face
        One per segment, in ``model.labels`` order (before sewing).
    info : SewResult
    """
    faces = [make_face(model.surfaces[label]) for label in model.labels]
    shape, info = sew(faces, model.sew_tolerance)
    return shape, faces, info


# --------------------------------------------------------------------------- continuity
def _shared_edges(shape: Part.Shape) -> tuple[list[tuple[Any, Any, Any]], int]:
    """``(edge, face_a, face_b)`` for every non-degenerate edge of two faces, and the number
    of free edges."""
    shared, free = [], 0
    for edge in shape.Edges:
        if edge.Degenerated:
            continue
        owners: list[Any] = []
        for face in shape.ancestorsOfType(edge, Part.Face):
            if not any(face.isSame(f) for f in owners):
                owners.append(face)
        if len(owners) == 1:
            free += 1
        elif len(owners) >= 2:
            shared.append((edge, owners[0], owners[1]))
    return shared, free


def _sampler(face: Any, edge: Any) -> Any:
    """``sample(t, point) -> (surface point, oriented normal or None)`` of ``face`` along
    ``edge``: through the edge's pcurve on the face (exact parameters, as in
    :mod:`pde2cad.occ.continuity`), else by projecting the edge point onto the surface."""
    try:
        pcurve = face.curveOnSurface(edge)
    except Exception:  # noqa: BLE001 - Part raises when the edge has no pcurve on the face
        pcurve = None

    def sample(t: float, point: Any) -> tuple[Any, Any]:
        if pcurve:
            uv = pcurve[0].value(t)
            u, v = uv.x, uv.y
        else:
            u, v = face.Surface.parameter(point)
        try:
            normal = face.normalAt(u, v)
        except Part.OCCError:  # undefined at a collapsed pole
            normal = None
        return face.Surface.value(u, v), normal

    return sample


def measure_continuity(shape: Part.Shape, samples: int = 20) -> dict[str, Any]:
    """Gap and normal angle across every edge shared by two faces, as FreeCAD evaluates them.

    1. Find each edge's two faces (``ancestorsOfType``); count free edges.
    2. At ``samples`` points along the edge, map it into both faces (pcurves, see
       :func:`_sampler`): the distance of the two surface points is the gap, the angle of
       the two oriented normals the kink.

    Returns
    -------
    dict
        ``{"max_gap", "max_angle_deg", "shared_edges", "free_edges"}``; samples where a
        normal is undefined (a collapsed pole) count for the gap only.
    """
    if samples < 2:
        raise InputError(f"samples must be at least 2, got {samples}")
    shared, free = _shared_edges(shape)
    max_gap = max_angle = 0.0
    for edge, fa, fb in shared:
        first, last = edge.ParameterRange
        sample_a, sample_b = _sampler(fa, edge), _sampler(fb, edge)
        for t in np.linspace(first, last, samples):
            point = edge.valueAt(float(t))
            pa, na = sample_a(float(t), point)
            pb, nb = sample_b(float(t), point)
            max_gap = max(max_gap, (pa - pb).Length)
            if na is not None and nb is not None:
                max_angle = max(max_angle, math.degrees(math.atan2(na.cross(nb).Length, na.dot(nb))))
    return {
        "max_gap": float(max_gap), "max_angle_deg": float(max_angle),
        "shared_edges": len(shared), "free_edges": free,
    }


def continuity_figures(model: SurfaceModel, shape: Part.Shape, samples: int = 20) -> dict[str, Any]:
    """The figures a user checks on a reconstruction: :func:`measure_continuity` of the
    shape, plus the worst patch error (largest fit error of any patch to its points, model
    units) and the patches kept C0 under ``continuity="c1"``."""
    figures = measure_continuity(shape, samples)
    figures["worst_patch_error"] = max(
        (float(p.fit_errors["max"]) for p in model.patches.values()), default=0.0
    )
    figures["c0_fallback"] = [int(label) for label in model.c0_fallback]
    return figures


__all__ = [
    "SewResult", "build_shape", "continuity_figures", "make_face", "measure_continuity",
    "sew", "to_part_surface",
]
