"""The "Sketch from image" feature: a binary image -> Part faces ready for Pad/Extrude, and a
Sketcher sketch of the same outline.

``execute`` runs :func:`pde2cad.vectorize` and the FreeCAD adapter :mod:`pde2cad.fc.outline`.
The scale (mm per pixel) comes from the image's DPI, a given mm per pixel, or a known length
between two image points (the way to trace a photo of a part next to a ruler).
"""

from __future__ import annotations

import math
from typing import Any

import FreeCAD

from freecad.pde2cad.feature import Feature, ViewProvider, add
from pde2cad.errors import InputError

SCALE_MODES = ["Pixels", "DPI", "MmPerPixel", "KnownLength"]
PLANES = ["XY", "XZ", "YZ"]


def _enum(obj: Any, name: str, group: str, doc: str, values: list[str], value: str) -> None:
    if name not in obj.PropertiesList:
        obj.addProperty("App::PropertyEnumeration", name, group, doc)
        setattr(obj, name, values)
        setattr(obj, name, value)


def mm_per_px(obj: Any) -> float:
    """The feature's scale in mm per pixel (1 in ``Pixels`` mode: one pixel is one mm).

    Raises
    ------
    InputError
        A non-positive DPI, mm per pixel or known length, or two equal known points.
    """
    mode = str(obj.ScaleMode)
    if mode == "DPI":
        if not obj.Dpi > 0:
            raise InputError(f"Dpi must be > 0, got {obj.Dpi}")
        return 25.4 / float(obj.Dpi)
    if mode == "MmPerPixel":
        if not obj.MmPerPixel > 0:
            raise InputError(f"MmPerPixel must be > 0, got {obj.MmPerPixel}")
        return float(obj.MmPerPixel)
    if mode == "KnownLength":
        a, b = obj.KnownPointA, obj.KnownPointB
        pixels = math.hypot(b.x - a.x, b.y - a.y)
        if not (pixels > 0 and obj.KnownLength > 0):
            raise InputError(
                "KnownLength needs two different image points (KnownPointA/B, pixels) and "
                f"their distance in mm > 0; got {pixels:g} px and {obj.KnownLength:g} mm"
            )
        return float(obj.KnownLength) / pixels
    return 1.0


class OutlineFeature(Feature):
    """Proxy of a ``Part::FeaturePython`` whose ``Shape`` is a compound of outline faces."""

    kind = "Outline"

    def properties(self, obj: Any) -> None:
        g = "Image"
        add(obj, "File", "ImageFile", g, "Binary image (PNG, BMP, PBM/PGM, JPEG, TIFF)")
        add(obj, "Float", "Tolerance", g, "Largest distance of the curves to the pixel boundary, px", 1.0)
        add(obj, "Float", "Threshold", g, "Grey level 0..255 of the foreground cut (-1: Otsu)", -1.0)
        add(obj, "Bool", "Invert", g, "Light shapes on a dark background", False)
        add(obj, "Bool", "Symmetry", g, "Fit symmetric loops on their fundamental part", True)
        add(obj, "Bool", "G1", g, "Tangent joins where a break point is not a corner", True)
        g = "Scale"
        _enum(obj, "ScaleMode", g, "Pixels (1 px = 1 mm), DPI, MmPerPixel or KnownLength", SCALE_MODES, "Pixels")
        add(obj, "Float", "Dpi", g, "Dots per inch of the image (ScaleMode DPI)", 0.0)
        add(obj, "Float", "MmPerPixel", g, "Millimetres per pixel (ScaleMode MmPerPixel)", 0.0)
        add(obj, "Vector", "KnownPointA", g, "First image point, pixels (x right, y down)")
        add(obj, "Vector", "KnownPointB", g, "Second image point, pixels")
        add(obj, "Float", "KnownLength", g, "Distance of the two points in mm (ScaleMode KnownLength)", 0.0)
        g = "Placement"
        _enum(obj, "Plane", g, "Plane of the outline and its sketch", PLANES, "XY")
        add(obj, "String", "SketchName", g, "Name of the sketch this feature keeps up to date", "")
        g = "Result"
        add(obj, "Integer", "Loops", g, "Closed loops", 0, True)
        add(obj, "Integer", "Curves", g, "Bézier pieces", 0, True)
        add(obj, "Float", "MaxError", g, "Largest distance to the pixel boundary, px", 0.0, True)
        add(obj, "Float", "Scale", g, "Millimetres per pixel used", 0.0, True)

    def drawing(self, obj: Any) -> Any:
        """The vectorized image under the feature's settings."""
        from pde2cad.image.vectorize import vectorize

        if not obj.ImageFile:
            raise InputError("no image: set ImageFile")
        return vectorize(
            obj.ImageFile, float(obj.Tolerance),
            threshold=float(obj.Threshold) if obj.Threshold >= 0 else None,
            invert=bool(obj.Invert), symmetry=bool(obj.Symmetry), g1=bool(obj.G1),
            scale=mm_per_px(obj) if obj.ScaleMode != "Pixels" else None,
        )

    def build(self, obj: Any) -> Any:
        """1. Vectorize; 2. faces in mm on the plane; 3. refill the sketch, if any."""
        from pde2cad.fc.outline import fill_sketch, outline_shape, plane_placement

        scale = mm_per_px(obj)
        drawing = self.drawing(obj)
        self.last_drawing = drawing
        shape = outline_shape(drawing, scale)
        # A Part feature's Placement property places its Shape (it wins over the shape's own).
        obj.Placement = plane_placement(str(obj.Plane))
        obj.Loops, obj.Curves = len(drawing.loops), drawing.n_curves
        obj.MaxError, obj.Scale = float(drawing.max_error), scale
        sketch = obj.Document.getObject(obj.SketchName) if obj.SketchName else None
        counts = {}
        if sketch is not None:
            counts = fill_sketch(sketch, drawing, scale)
            sketch.Placement = obj.Placement
            if counts["solver"] != 0:
                raise InputError(f"the sketch solver reports {counts['solver']} on the outline")
        valid = "" if shape.isValid() else "; the faces are NOT valid (curves cross)"
        if len(shape.Faces) > 1:
            valid += (f"; {len(shape.Faces)} separate shapes: Part Extrude them (a PartDesign "
                      "Pad makes one solid per body)")
        obj.Status = (
            f"{len(drawing.loops)} loops, {drawing.n_curves} curves, max error "
            f"{drawing.max_error:.3g} px, {scale:.4g} mm/px, {len(shape.Faces)} faces"
            + (f"; sketch {sketch.Label}: {counts['lines']} lines, {counts['bsplines']} "
               f"B-splines, {counts['coincident']} coincident, {counts['tangent']} tangent"
               if sketch is not None else "") + valid
        )
        report = FreeCAD.Console.PrintWarning if not shape.isValid() else FreeCAD.Console.PrintMessage
        report(f"pde2cad {obj.Label}: {obj.Status}\n")
        return shape


class OutlineViewProvider(ViewProvider):
    icon_name = "sketch"
