"""B-spline surfaces to OCP faces, sewing into shells/solids, and STEP/IGES exchange.

The kernel-neutral :class:`~pde2cad.bspline.data.BSplineSurface` stores *full* clamped
knot vectors; OCCT wants unique knots plus multiplicities in 1-based arrays, so
:func:`to_geom_surface` converts. Everything here is duck-typed on the attributes
``poles`` (``(nu, nv, 3)``), ``knots_u``, ``knots_v``, ``degree_u``, ``degree_v``, so this
module does not depend on the core package's import order.

Exchange settings (schema, units) are process-global ``Interface_Static`` values in OCCT;
each writer/reader here sets every value it relies on right before use, so the result does
not depend on what ran earlier in the process.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import ArrayLike
from OCP.APIHeaderSection import APIHeaderSection_MakeHeader
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import (
    BRepBuilderAPI_MakeFace,
    BRepBuilderAPI_MakeSolid,
    BRepBuilderAPI_Sewing,
)
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepGProp import BRepGProp
from OCP.Geom import Geom_BSplineSurface
from OCP.gp import gp_Pnt
from OCP.GProp import GProp_GProps
from OCP.IFSelect import IFSelect_ReturnStatus
from OCP.IGESCAFControl import IGESCAFControl_Writer
from OCP.IGESControl import IGESControl_Controller, IGESControl_Reader
from OCP.Interface import Interface_Static
from OCP.ShapeFix import ShapeFix_Solid
from OCP.STEPCAFControl import STEPCAFControl_Controller, STEPCAFControl_Writer
from OCP.STEPControl import (
    STEPControl_Controller,
    STEPControl_Reader,
    STEPControl_StepModelType,
)
from OCP.TColgp import TColgp_Array2OfPnt
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Face, TopoDS_Shape

from pde2cad.errors import ExportError, InputError
from pde2cad.io.atomic import atomic_path
from pde2cad.occ.naming import header_text, named_document

if TYPE_CHECKING:
    import build123d
    import cadquery

#: Names accepted by ``write.step.schema`` (OCCT's CVal spelling) per user-facing schema.
_STEP_SCHEMAS = {"AP203": "AP203", "AP214": "AP214IS", "AP242": "AP242DIS"}
#: User-facing unit names to OCCT's enum spelling (``write.step.unit``,
#: ``xstep.cascade.unit``, ``write.iges.unit``); OCCT calls an inch "INCH" and silently
#: rejects "IN", so the alias is mapped here.
_UNITS = {
    "MM": "MM", "CM": "CM", "M": "M", "KM": "KM", "UM": "UM",
    "IN": "INCH", "INCH": "INCH", "FT": "FT", "MI": "MI", "MIL": "MIL", "UIN": "UIN",
}
#: Millimetres per unit (OCCT spelling), for the IGES model's cascade unit.
_MM_PER_UNIT = {
    "MM": 1.0, "CM": 10.0, "M": 1000.0, "KM": 1e6, "UM": 1e-3,
    "INCH": 25.4, "FT": 304.8, "MI": 1609344.0, "MIL": 0.0254, "UIN": 2.54e-5,
}


class SurfaceLike(Protocol):
    """The attributes of a B-spline surface this adapter reads (full clamped knot vectors)."""

    @property
    def poles(self) -> Any: ...
    @property
    def knots_u(self) -> Any: ...
    @property
    def knots_v(self) -> Any: ...
    @property
    def degree_u(self) -> int: ...
    @property
    def degree_v(self) -> int: ...


@dataclass(frozen=True)
class SewInfo:
    """Topology report of :func:`sew`.

    Attributes
    ----------
    n_faces : int
        Faces in the sewn result.
    n_shells : int
        Shells in the sewn result (1 for a connected patch set).
    n_free_edges : int
        Edges bounded by only one face, as counted by the sewing algorithm.
    is_closed : bool
        Every shell of the result is closed (no free edges).
    is_solid : bool
        Solids were built from those shells (one per outer shell, inner shells as voids).
    valid : bool
        ``BRepCheck_Analyzer`` accepts the returned shape.
    """

    n_faces: int
    n_shells: int
    n_free_edges: int
    is_closed: bool
    is_solid: bool
    valid: bool


def _unique_knots(
    knots: ArrayLike, degree: int, n_poles: int, name: str
) -> tuple[list[float], list[int]]:
    """Split a full clamped knot vector into unique knots and multiplicities.

    Knots closer than ``1e-12`` of the parameter range are merged, because a full knot
    vector computed in floating point may repeat a knot with rounding noise and OCCT would
    then see two distinct knots of multiplicity 1 (a degenerate zero-length span).
    """
    k = np.asarray(knots, dtype=float).ravel()
    if k.size != n_poles + degree + 1:
        raise InputError(
            f"{name}: a degree-{degree} B-spline with {n_poles} poles needs "
            f"{n_poles + degree + 1} knots, got {k.size}"
        )
    if not np.all(np.isfinite(k)) or np.any(np.diff(k) < 0):
        raise InputError(f"{name}: knots must be finite and non-decreasing")
    span = k[-1] - k[0]
    if span <= 0:
        raise InputError(f"{name}: the knot vector spans an empty parameter range")
    tol = 1e-12 * span
    values: list[float] = [float(k[0])]
    mults: list[int] = [1]
    for x in k[1:]:
        if x - values[-1] <= tol:
            mults[-1] += 1
        else:
            values.append(float(x))
            mults.append(1)
    if mults[0] != degree + 1 or mults[-1] != degree + 1:
        raise InputError(
            f"{name}: the knot vector must be clamped (end multiplicity {degree + 1}), "
            f"got {mults[0]} and {mults[-1]}"
        )
    if max(mults[1:-1], default=0) > degree:
        raise InputError(f"{name}: an interior knot has multiplicity above the degree {degree}")
    return values, mults


def _real_array(values: list[float]) -> TColStd_Array1OfReal:
    arr = TColStd_Array1OfReal(1, len(values))
    for i, x in enumerate(values, start=1):
        arr.SetValue(i, x)
    return arr


def _int_array(values: list[int]) -> TColStd_Array1OfInteger:
    arr = TColStd_Array1OfInteger(1, len(values))
    for i, x in enumerate(values, start=1):
        arr.SetValue(i, x)
    return arr


def to_geom_surface(surf: SurfaceLike) -> Geom_BSplineSurface:
    """Build an OCCT ``Geom_BSplineSurface`` from a kernel-neutral B-spline surface.

    Parameters
    ----------
    surf : BSplineSurface
        Poles ``(nu, nv, 3)``, full clamped knot vectors ``knots_u`` (``nu + degree_u + 1``
        values) and ``knots_v``, degrees ``degree_u`` and ``degree_v`` (non-rational).

    Returns
    -------
    Geom_BSplineSurface
        The same surface; pole ``(i, j)`` becomes OCCT pole ``(i + 1, j + 1)``.

    Raises
    ------
    InputError
        On a pole array of the wrong shape, non-finite values, or inconsistent knots.
    """
    poles = np.asarray(surf.poles, dtype=float)
    if poles.ndim != 3 or poles.shape[2] != 3:
        raise InputError(f"poles must have shape (nu, nv, 3), got {poles.shape}")
    if not np.all(np.isfinite(poles)):
        raise InputError("poles contain NaN or infinite values")
    du, dv = int(surf.degree_u), int(surf.degree_v)
    nu, nv = poles.shape[:2]
    if du < 1 or dv < 1 or nu < du + 1 or nv < dv + 1:
        raise InputError(
            f"degrees ({du}, {dv}) need at least ({du + 1}, {dv + 1}) poles, got ({nu}, {nv})"
        )
    ku, mu = _unique_knots(surf.knots_u, du, nu, "knots_u")
    kv, mv = _unique_knots(surf.knots_v, dv, nv, "knots_v")
    arr = TColgp_Array2OfPnt(1, nu, 1, nv)
    for i in range(nu):
        for j in range(nv):
            x, y, z = poles[i, j]
            arr.SetValue(i + 1, j + 1, gp_Pnt(float(x), float(y), float(z)))
    try:
        return Geom_BSplineSurface(
            arr, _real_array(ku), _real_array(kv), _int_array(mu), _int_array(mv), du, dv
        )
    except Exception as exc:  # OCCT raises Standard_ConstructionError subclasses
        raise InputError(f"OCCT rejected the B-spline surface: {exc}") from exc


def make_face(surf: SurfaceLike, tol: float = 1e-7) -> TopoDS_Face:
    """Make a face bounded by the full parameter rectangle of a B-spline surface.

    Parameters
    ----------
    surf : BSplineSurface
        The surface (see :func:`to_geom_surface`).
    tol : float
        Degeneracy tolerance (model units): a boundary side shorter than this is built as
        a degenerated edge (a collapsed pole, as at the apex of a cone-like patch). This is
        OCCT's ``TolDegen``; edge and vertex tolerances stay at OCCT's default 1e-7.

    Returns
    -------
    TopoDS_Face
        A face with four boundary edges, a collapsed side becoming a degenerated edge.
    """
    geom = to_geom_surface(surf)
    u1, u2, v1, v2 = geom.Bounds()
    maker = BRepBuilderAPI_MakeFace(geom, u1, u2, v1, v2, tol)
    if not maker.IsDone():
        raise InputError(f"OCCT could not make a face from the surface (error {maker.Error()})")
    return maker.Face()


def _count(shape: TopoDS_Shape, kind: Any) -> int:
    explorer = TopExp_Explorer(shape, kind)
    n = 0
    while explorer.More():
        n += 1
        explorer.Next()
    return n


def volume(shape: TopoDS_Shape, eps: float | None = None) -> float:
    """Return the volume enclosed by ``shape`` (negative for an inside-out solid), by
    OpenCASCADE's default Gauss rule (as FreeCAD's ``Shape.Volume``), or integrated
    adaptively to a relative error of ``eps`` (5-8x slower; the default rule is off by
    ~1e-4 on B-spline faces: a box cut from a reconstructed can and the part minus their
    common part differed by 1.7e-4 by the default rule, by 2e-10 at ``eps = 1e-9``)."""
    props = GProp_GProps()
    if eps is None:
        BRepGProp.VolumeProperties_s(shape, props)
    else:
        BRepGProp.VolumeProperties_s(shape, props, eps)
    return float(props.Mass())


def sew(
    faces: list[TopoDS_Face] | tuple[TopoDS_Face, ...], tolerance: float = 1e-6
) -> tuple[TopoDS_Shape, SewInfo]:
    """Sew faces into a shell, and into a solid when the shell is closed.

    Parameters
    ----------
    faces : sequence of TopoDS_Face
        Faces whose boundaries should be joined.
    tolerance : float
        Largest gap (model units) between edges that are merged into one shared edge.

    Returns
    -------
    shape : TopoDS_Shape
        When every shell is closed: a solid per outer shell, with the shells inside it as
        voids (one solid, or a compound of solids for several bodies; see :func:`_solids`).
        Otherwise the sewn shell, compound of shells, or single face.
    info : SewInfo
        Face, shell and free-edge counts and the ``BRepCheck_Analyzer`` verdict.
    """
    if len(faces) == 0:
        raise InputError("sew needs at least one face")
    if not tolerance > 0:
        raise InputError(f"sewing tolerance must be positive, got {tolerance}")
    sewing = BRepBuilderAPI_Sewing(tolerance)
    for face in faces:
        sewing.Add(face)
    sewing.Perform()
    sewn = sewing.SewedShape()
    if sewn is None or sewn.IsNull():
        raise ExportError("OCCT sewing produced no shape")
    n_free = int(sewing.NbFreeEdges())
    n_shells = _count(sewn, TopAbs_SHELL)
    shells = [TopoDS.Shell_s(sh) for sh in _subshapes(sewn, TopAbs_SHELL)]
    # BRep_Tool.IsClosed checks every edge is shared by two faces of the shell; the free
    # edge count is checked too so a shell closed only up to tolerance is not trusted.
    closed = bool(shells) and n_free == 0 and all(BRep_Tool.IsClosed_s(sh) for sh in shells)
    shape = sewn
    if closed:
        solids = _solids(shells)
        if solids is not None:
            shape = solids
    info = SewInfo(
        n_faces=_count(shape, TopAbs_FACE),
        n_shells=n_shells,
        n_free_edges=n_free,
        is_closed=closed,
        is_solid=shape is not sewn,
        valid=bool(BRepCheck_Analyzer(shape).IsValid()),
    )
    return shape, info


def _subshapes(shape: TopoDS_Shape, kind: Any) -> list[TopoDS_Shape]:
    explorer = TopExp_Explorer(shape, kind)
    found = []
    while explorer.More():
        found.append(explorer.Current())
        explorer.Next()
    return found


def _oriented_solid(shell: Any) -> tuple[TopoDS_Shape, float] | None:
    """A solid of one closed shell, turned outward (positive volume), and its volume."""
    maker = BRepBuilderAPI_MakeSolid(shell)
    if not maker.IsDone():
        return None
    fixer = ShapeFix_Solid(maker.Solid())
    fixer.Perform()
    solid = fixer.Solid()
    # ShapeFix_Solid orients the shell outward in the usual case; the volume sign is the
    # definitive check, so flip an inside-out result ourselves. (The volume integral is
    # the slow step on B-spline faces: 2-3 s for a 138-face torus; it is computed once.)
    vol = volume(solid)
    return (solid.Reversed(), -vol) if vol < 0 else (solid, vol)


def _solids(shells: list[Any]) -> TopoDS_Shape | None:
    """Solids of closed shells: separate bodies, and shells inside another as its voids.

    1. Each shell alone as an outward solid; the largest volume first.
    2. A shell whose vertex lies inside another shell's solid is inside it; its depth is
       how many shells hold it. Even depth: an outer shell (a body); odd: a void of the
       innermost shell holding it (a ball in a hollow ball is a third body).
    3. One solid per body (``BRepBuilderAPI_MakeSolid`` with the voids added, each
       turned inward); one body is returned as a solid, several as a compound.
    """
    from OCP.BRepClass3d import BRepClass3d_SolidClassifier
    from OCP.TopAbs import TopAbs_IN, TopAbs_VERTEX

    oriented = [_oriented_solid(sh) for sh in shells]
    if any(s is None for s in oriented):
        return None
    alone = [s[0] for s in oriented if s is not None]
    vol = [s[1] for s in oriented if s is not None]
    order = sorted(range(len(shells)), key=lambda i: -vol[i])
    probe = [BRep_Tool.Pnt_s(TopoDS.Vertex_s(_subshapes(sh, TopAbs_VERTEX)[0])) for sh in shells]
    holders: dict[int, list[int]] = {i: [] for i in order}
    for i in order:
        for j in order:
            if i != j and vol[j] > vol[i]:
                inside = BRepClass3d_SolidClassifier(alone[j], probe[i], 1e-7)
                if inside.State() == TopAbs_IN:
                    holders[i].append(j)
    bodies: list[TopoDS_Shape] = []
    for i in order:
        if len(holders[i]) % 2:
            continue
        voids = [j for j in order if len(holders[j]) == len(holders[i]) + 1 and i in holders[j]]
        if not voids:
            bodies.append(alone[i])
            continue
        maker = BRepBuilderAPI_MakeSolid(TopoDS.Shell_s(_subshapes(alone[i], TopAbs_SHELL)[0]))
        for j in voids:
            maker.Add(TopoDS.Shell_s(_subshapes(alone[j], TopAbs_SHELL)[0].Reversed()))
        bodies.append(maker.Solid())
    return _compound(bodies)


def _compound(parts: list[TopoDS_Shape]) -> TopoDS_Shape:
    """One shape alone, several as a compound."""
    if len(parts) == 1:
        return parts[0]
    compound = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(compound)
    for part in parts:
        builder.Add(compound, part)
    return compound


def _check_units(units: str) -> str:
    u = str(units).upper()
    if u not in _UNITS:
        raise InputError(f"unknown unit {units!r}; use one of {', '.join(_UNITS)}")
    return _UNITS[u]


def _set_static(name: str, value: str | int) -> None:
    """Set an OCCT exchange parameter, failing loudly: OCCT only returns False on a bad
    value and would otherwise keep whatever an earlier call left there."""
    ok = (
        Interface_Static.SetIVal_s(name, value)
        if isinstance(value, int)
        else Interface_Static.SetCVal_s(name, value)
    )
    if not ok:
        raise ExportError(f"OCCT rejected the exchange setting {name}={value!r}")


def _originating_system() -> str:
    from pde2cad import __version__

    return f"pde2cad {__version__}"


def _step_header(model: Any, name: str, author: str | None, organization: str | None) -> None:
    """FILE_NAME of the STEP header: the part's name, author, organisation, originating
    system pde2cad x.y; OCCT would write "Author" and leave the rest its own."""
    header = APIHeaderSection_MakeHeader(model)
    header.SetName(header_text(name))
    header.SetAuthorValue(1, header_text(author or ""))
    header.SetOrganizationValue(1, header_text(organization or ""))
    header.SetOriginatingSystem(header_text(_originating_system()))
    header.SetAuthorisation(header_text(organization or ""))


def write_step(
    shape: TopoDS_Shape,
    path: str | Path,
    *,
    schema: str = "AP214",
    units: str = "MM",
    name: str | None = None,
    author: str | None = None,
    organization: str | None = None,
    face_names: Sequence[str] | None = None,
) -> Path:
    """Write ``shape`` to a STEP file atomically, named and traceable.

    1. The shape goes into an XCAF document with its name and face names
       (:func:`~pde2cad.occ.naming.named_document`).
    2. The exchange statics (schema, units, pcurves, sub-shape names) are set right before
       the writer exists, as OCCT reads them when it creates the STEP model.
    3. The header's FILE_NAME gets the name, author, organisation and "pde2cad x.y".

    Parameters
    ----------
    shape : TopoDS_Shape
        Shape to write (face, shell, solid or compound).
    path : str or Path
        Target file; its folder must exist.
    schema : {"AP214", "AP242", "AP203"}
        STEP application protocol written into the header's ``FILE_SCHEMA``.
    units : str
        Length unit of the shape's coordinates; the file declares this unit and no scaling
        is applied.
    name : str, optional
        Product name and header FILE_NAME name; default the file name without suffix.
    author, organization : str, optional
        Header author and organisation (empty when not given).
    face_names : sequence of str, optional
        One name per face in ``TopExp_Explorer`` order, written as the ``ADVANCED_FACE``
        names (e.g. :func:`~pde2cad.occ.naming.segment_face_names`).

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    InputError
        On an unknown schema or unit, a null shape or a ``face_names`` of the wrong length.
    ExportError
        When OCCT fails to translate or write, or the folder does not exist.
    """
    key = schema.upper()
    if key not in _STEP_SCHEMAS:
        raise InputError(f"unknown STEP schema {schema!r}; use one of {', '.join(_STEP_SCHEMAS)}")
    unit = _check_units(units)
    if shape is None or shape.IsNull():
        raise InputError("cannot write a null shape")
    target = Path(path)
    doc = named_document(shape, name or target.stem, face_names)
    STEPCAFControl_Controller.Init_s()
    _set_static("write.step.schema", _STEP_SCHEMAS[key])
    _set_static("xstep.cascade.unit", unit)
    _set_static("write.step.unit", unit)
    # pcurves are what lets a reader (and measure()) rebuild exact face-edge relations.
    _set_static("write.surfacecurve.mode", 1)
    _set_static("write.stepcaf.subshapes.name", 1)
    with atomic_path(target) as tmp:
        writer = STEPCAFControl_Writer()
        writer.SetNameMode(True)
        if not writer.Transfer(doc, STEPControl_StepModelType.STEPControl_AsIs):
            raise ExportError("OCCT could not translate the shape to STEP")
        _step_header(writer.ChangeWriter().Model(), name or target.stem, author, organization)
        status = writer.Write(str(tmp))
        if status != IFSelect_ReturnStatus.IFSelect_RetDone or not tmp.stat().st_size:
            raise ExportError(f"OCCT could not write {target} (status {status.name})")
    return target


def write_iges(
    shape: TopoDS_Shape,
    path: str | Path,
    units: str = "MM",
    *,
    name: str | None = None,
    author: str | None = None,
    organization: str | None = None,
    face_names: Sequence[str] | None = None,
) -> Path:
    """Write ``shape`` to an IGES 5.3 file in BRep mode (MSBO solids/shells), atomically.

    Parameters
    ----------
    shape : TopoDS_Shape
        Shape to write.
    path : str or Path
        Target file; its folder must exist.
    units : str
        Length unit of the coordinates, declared in the global section without scaling.
    name : str, optional
        Product id and part label; the global section's file name is the target's name.
        Default the file name without suffix.
    author, organization : str, optional
        Global section author and organisation (empty when not given).
    face_names : sequence of str, optional
        One name per face in ``TopExp_Explorer`` order (name properties, entity 406).

    Returns
    -------
    Path
        The written path.
    """
    unit = _check_units(units)
    if shape is None or shape.IsNull():
        raise InputError("cannot write a null shape")
    target = Path(path)
    doc = named_document(shape, name or target.stem, face_names)
    IGESControl_Controller.Init_s()
    # BRep mode keeps faces joined by shared edges; the default (0) writes loose trimmed
    # surfaces, which a reader has to re-sew.
    _set_static("write.iges.brep.mode", 1)
    _set_static("xstep.cascade.unit", unit)
    _set_static("write.iges.unit", unit)
    with atomic_path(target) as tmp:
        writer = IGESCAFControl_Writer()
        writer.SetNameMode(True)
        # The IGES writer ignores xstep.cascade.unit and assumes the shape is in mm, so
        # it would scale coordinates into the file unit; declaring the shape's unit on the
        # model keeps the numbers as they are.
        model = writer.Model()
        section = model.GlobalSection()
        section.SetCascadeUnit(_MM_PER_UNIT[unit])
        section.SetFileName(header_text(target.name))
        section.SetSendName(header_text(name or target.stem))
        section.SetAuthorName(header_text(author or ""))
        section.SetCompanyName(header_text(organization or ""))
        section.SetSystemId(header_text(_originating_system()))
        model.SetGlobalSection(section)
        if not writer.Transfer(doc):
            raise ExportError("OCCT could not translate the shape to IGES")
        if not writer.Write(str(tmp)) or not tmp.stat().st_size:
            raise ExportError(f"OCCT could not write {target}")
    return target


def _read(reader: Any, path: str | Path, kind: str) -> TopoDS_Shape:
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{kind} file {p} does not exist")
    status = reader.ReadFile(str(p))
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise InputError(f"could not read {kind} file {p} (status {status.name})")
    if reader.TransferRoots() == 0:
        raise InputError(f"{kind} file {p} holds no transferable shape")
    shape = reader.OneShape()
    if shape is None or shape.IsNull():
        raise InputError(f"{kind} file {p} holds no shape")
    return shape


def read_step(path: str | Path, units: str = "MM") -> TopoDS_Shape:
    """Read a STEP file into one shape (a compound when it holds several roots).

    Parameters
    ----------
    path : str or Path
        STEP file.
    units : str
        Unit to express the coordinates in; OCCT scales from the file's declared unit.
    """
    STEPControl_Controller.Init_s()
    _set_static("xstep.cascade.unit", _check_units(units))
    return _read(STEPControl_Reader(), path, "STEP")


def read_iges(path: str | Path, units: str = "MM") -> TopoDS_Shape:
    """Read an IGES file into one shape (see :func:`read_step`)."""
    IGESControl_Controller.Init_s()
    _set_static("xstep.cascade.unit", _check_units(units))
    return _read(IGESControl_Reader(), path, "IGES")


def as_topods(obj: object) -> TopoDS_Shape:
    """The OCP shape behind ``obj`` (see the module docstring for what is accepted).

    Raises
    ------
    InputError
        For anything else (a path, None, an array...), naming what was given.
    """
    if isinstance(obj, TopoDS_Shape):
        if obj.IsNull():
            raise InputError("cannot export a null shape")
        return obj
    wrapped = getattr(obj, "wrapped", None)
    if isinstance(wrapped, TopoDS_Shape):
        return as_topods(wrapped)
    shape = getattr(obj, "shape", None)
    if isinstance(shape, TopoDS_Shape):
        return as_topods(shape)
    vals = getattr(obj, "vals", None)
    if callable(vals):  # CadQuery Workplane
        return as_topods(list(vals()))
    if isinstance(obj, (list, tuple)) and obj:
        return _compound([as_topods(o) for o in obj])
    raise InputError(
        f"cannot export a {type(obj).__name__}: give a TopoDS_Shape, a build123d or CadQuery "
        "shape, a Workplane, a list of shapes, or a reconstruction result"
    )


def to_build123d(shape: object) -> build123d.Shape:
    """``shape`` (see :func:`as_topods`: an OCP shape, a CadQuery shape or ``Workplane``, a
    list, a reconstruction result) as the matching build123d class (``Solid``, ``Shell``,
    ``Face``, ``Compound``...)."""
    from build123d import Shape

    return Shape.cast(as_topods(shape))


def to_cadquery(shape: object) -> cadquery.Shape:
    """``shape`` (see :func:`as_topods`) as the matching CadQuery class (``Solid``,
    ``Shell``, ``Face``, ``Compound``...)."""
    from cadquery import Shape

    return Shape.cast(as_topods(shape))


__all__ = [
    "SewInfo",
    "as_topods",
    "make_face",
    "read_iges",
    "read_step",
    "sew",
    "to_build123d",
    "to_cadquery",
    "to_geom_surface",
    "volume",
    "write_iges",
    "write_step",
]
