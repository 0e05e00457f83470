"""Scriptable API of the workbench, for macros and tests (no GUI needed)::

    import FreeCAD
    from freecad.pde2cad import api

    doc = FreeCAD.newDocument()
    surf = api.make_surface(doc, "torus.ply", labels="scalar_label", continuity="c1")
    print(surf.Shape.Volume, surf.MaxGap, surf.MaxNormalAngle)
    out = api.make_outline(doc, "part.png", tolerance=1.0, dpi=300, plane="XY")
    api.export([surf], "torus.step"); api.export([out], "part.dxf")

Each ``make_*`` returns the feature after ``doc.recompute()``; a feature whose input was bad
is returned invalid (``obj.isValid()`` False) with the reason in ``obj.Status`` and the
Report view.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

import FreeCAD
import Part
from freecad.pde2cad.outline_fp import OutlineFeature, OutlineViewProvider
from freecad.pde2cad.surface_fp import SurfaceFeature, SurfaceViewProvider
from pde2cad.errors import ExportError, InputError


def _new_feature(doc: Any, name: str, proxy: Any, view: Any) -> Any:
    obj = doc.addObject("Part::FeaturePython", name)
    proxy(obj)
    if FreeCAD.GuiUp:
        view(obj.ViewObject)
    return obj


def _set_labels(obj: Any, labels: Any) -> None:
    """``labels``: None, a property/PLY-property name (or "column4"/"segments"), a label file
    path, or an array of one label per point."""
    if labels is None:
        return
    if isinstance(labels, Path) or (isinstance(labels, str) and Path(labels).suffix.lower()
                                    in (".npy", ".txt", ".csv", ".labels")):
        obj.LabelsFile = str(labels)
    elif isinstance(labels, str):
        obj.Labels = labels
    else:
        values = np.asarray(labels)
        if values.dtype.kind == "f" and not np.all(values == np.round(values)):
            raise InputError("labels must be whole numbers, one per point")
        obj.LabelValues = [int(v) for v in values.reshape(-1)]


def _recompute(doc: Any, obj: Any) -> Any:
    """Recompute the document and return ``obj`` (invalid, with its Status, on bad input)."""
    doc.recompute()
    return obj


def make_surface(doc: Any, source: Any, labels: Any = None, continuity: str = "c1",
                 **options: Any) -> Any:
    """A "Surface from points" feature, recomputed.

    Parameters
    ----------
    doc : App.Document
    source : Points/Mesh object, or str/Path of a cloud file
    labels : None, str, Path or (N,) int array
        A property of the source object (or PLY vertex property, ``"column4"``,
        ``"segments"`` of a mesh), a label file, or one label per point.
    continuity : {"c1", "c0"}
    **options
        ``terms`` (0: automatic), ``tolerance``, ``cad_tolerance``, ``sample_points``
        (mesh area samples), ``name``.

    Returns
    -------
    Part::FeaturePython
        ``Shape`` the sewn shell or solid; ``MaxGap``, ``MaxNormalAngle``,
        ``WorstPatchError``, ``Volume``, ``Area``, ``Status``.
    """
    obj = _new_feature(doc, options.pop("name", "Surface"), SurfaceFeature, SurfaceViewProvider)
    if isinstance(source, (str, Path)):
        obj.SourceFile = str(source)
    else:
        obj.Source = source
    _set_labels(obj, labels)
    if continuity not in ("c0", "c1"):
        raise InputError(f"continuity must be 'c0' or 'c1', got {continuity!r}")
    obj.Continuity = continuity
    for key, prop in (("terms", "Terms"), ("tolerance", "Tolerance"),
                      ("cad_tolerance", "CadTolerance"), ("sample_points", "SamplePoints")):
        if options.get(key) is not None:
            setattr(obj, prop, options.pop(key))
    if options:
        raise InputError(f"unknown option(s) {', '.join(options)} for make_surface")
    return _recompute(doc, obj)


def make_outline(doc: Any, image_path: str | Path, tolerance: float = 1.0, dpi: float | None = None,
                 mm_per_px: float | None = None, plane: str = "XY", sketch: bool = True,
                 **options: Any) -> Any:
    """A "Sketch from image" feature (and its sketch), recomputed.

    Parameters
    ----------
    doc : App.Document
    image_path : str or Path
    tolerance : float
        Pixels.
    dpi, mm_per_px : float, optional
        Scale (at most one); or ``known_length=(a, b, mm)`` in ``options`` with ``a``, ``b``
        image points (x, y) in pixels. Default: 1 px = 1 mm.
    plane : {"XY", "XZ", "YZ"}
    sketch : bool
        Also make a Sketcher sketch the feature keeps up to date.
    **options
        ``threshold``, ``invert``, ``symmetry``, ``g1``, ``known_length``, ``name``.

    Returns
    -------
    Part::FeaturePython
        ``Shape`` a compound of faces; ``SketchName`` names the sketch.
    """
    obj = _new_feature(doc, options.pop("name", "Outline"), OutlineFeature, OutlineViewProvider)
    obj.ImageFile, obj.Tolerance = str(image_path), float(tolerance)
    if plane not in ("XY", "XZ", "YZ"):
        raise InputError(f"plane must be XY, XZ or YZ, got {plane!r}")
    obj.Plane = plane
    _set_scale(obj, dpi, mm_per_px, options.pop("known_length", None))
    for key, prop in (("threshold", "Threshold"), ("invert", "Invert"),
                      ("symmetry", "Symmetry"), ("g1", "G1")):
        if options.get(key) is not None:
            setattr(obj, prop, options.pop(key))
    if options:
        raise InputError(f"unknown option(s) {', '.join(options)} for make_outline")
    if sketch:
        obj.SketchName = doc.addObject("Sketcher::SketchObject", obj.Name + "Sketch").Name
    doc.recompute()
    # The feature refilled its sketch during that recompute; solve the sketch's own shape.
    return _recompute(doc, obj)


def _set_scale(obj: Any, dpi: float | None, mm_per_px: float | None, known: Any) -> None:
    given = [x is not None for x in (dpi, mm_per_px, known)]
    if sum(given) > 1:
        raise InputError("give one of dpi, mm_per_px or known_length, not several")
    if dpi is not None:
        obj.ScaleMode, obj.Dpi = "DPI", float(dpi)
    elif mm_per_px is not None:
        obj.ScaleMode, obj.MmPerPixel = "MmPerPixel", float(mm_per_px)
    elif known is not None:
        a, b, length = known
        obj.ScaleMode, obj.KnownLength = "KnownLength", float(length)
        obj.KnownPointA = FreeCAD.Vector(float(a[0]), float(a[1]), 0)
        obj.KnownPointB = FreeCAD.Vector(float(b[0]), float(b[1]), 0)


def is_surface(obj: Any) -> bool:
    return isinstance(getattr(obj, "Proxy", None), SurfaceFeature)


def is_outline(obj: Any) -> bool:
    return isinstance(getattr(obj, "Proxy", None), OutlineFeature)


def export(objects: list[Any], path: str | Path) -> Path:
    """Write surface features to STEP/IGES (FreeCAD Part's writer) or one outline feature to
    DXF/SVG (the project's writers, :mod:`pde2cad.io`), atomically.

    Raises
    ------
    InputError
        Unknown suffix, or features of the wrong kind / invalid ones.
    ExportError
        The file cannot be written (or ezdxf is missing for DXF).
    """
    from pde2cad.io.atomic import atomic_path

    target = Path(path)
    suffix = target.suffix.lower()
    if suffix in (".step", ".stp", ".iges", ".igs"):
        shapes = [o.Shape for o in _checked(objects, is_surface, "surface", many=True)]
        with atomic_path(target) as tmp:
            compound = shapes[0] if len(shapes) == 1 else Part.Compound(shapes)
            (compound.exportStep if suffix in (".step", ".stp") else compound.exportIges)(str(tmp))
        return target
    if suffix in (".dxf", ".svg"):
        (obj,) = _checked(objects, is_outline, "outline", many=False)
        drawing = getattr(obj.Proxy, "last_drawing", None) or obj.Proxy.drawing(obj)
        if suffix == ".dxf":
            from pde2cad.io.dxf import write_dxf

            write_dxf(drawing, target)
        else:
            drawing.write_svg(target)
        return target
    raise InputError(f"cannot export to {suffix!r}; use .step/.stp/.iges/.igs or .dxf/.svg")


def _checked(objects: list[Any], test: Any, kind: str, many: bool) -> list[Any]:
    chosen = [o for o in objects if test(o)]
    if not chosen or len(chosen) != len(objects):
        raise InputError(f"select {kind} features of the pde2cad workbench to export this format")
    if not many and len(chosen) > 1:
        raise InputError(f"select one {kind} feature per file")
    bad = [o.Label for o in chosen if not o.isValid() or o.Shape.isNull()]
    if bad:
        raise ExportError(f"{', '.join(bad)}: not recomputed successfully; fix the input first")
    return chosen
