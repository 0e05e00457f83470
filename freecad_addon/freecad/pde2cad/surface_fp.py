"""The "Surface from points" feature: a labelled cloud -> sewn B-spline shell or solid.

``execute`` runs the kernel-neutral :func:`pde2cad.reconstruct.fit_surfaces` and the FreeCAD
Part adapter :func:`pde2cad.fc.shape.build_shape`, then measures the result
(:func:`pde2cad.fc.shape.continuity_figures`) into read-only properties and the Report view.
"""

from __future__ import annotations

from typing import Any

import FreeCAD

from freecad.pde2cad.feature import Feature, ViewProvider, add
from freecad.pde2cad.sources import read_source

CONTINUITY = ["c1", "c0"]


class SurfaceFeature(Feature):
    """Proxy of a ``Part::FeaturePython`` whose ``Shape`` is the reconstructed shell/solid."""

    kind = "Surface"

    def properties(self, obj: Any) -> None:
        g = "Source"
        add(obj, "Link", "Source", g, "Points or Mesh object with the cloud")
        add(obj, "File", "SourceFile", g, "Cloud file (.ply, .xyz, .pts, .txt, .csv, .npy, .stl, .obj)")
        add(obj, "String", "Labels", g,
            "Labels: a property of the source object, a PLY vertex property, 'column4', "
            "or 'segments' (a mesh's segments)", "")
        add(obj, "File", "LabelsFile", g, "File with one segment label per point (.npy or text)")
        add(obj, "IntegerList", "LabelValues", g, "Segment label per point (set by the API)")
        add(obj, "Integer", "SamplePoints", g, "Points sampled on a mesh by area (0: its vertices)", 0)
        g = "Fit"
        if "Continuity" not in obj.PropertiesList:
            obj.addProperty("App::PropertyEnumeration", "Continuity", g, "c0: shared edges; c1: also tangent")
            obj.Continuity = CONTINUITY
        add(obj, "Integer", "Terms", g, "Deformation terms per patch (0: automatic)", 0)
        add(obj, "Float", "Tolerance", g, "Largest patch error to reach, model units (0: use Terms)", 0.0)
        add(obj, "Float", "CadTolerance", g, "B-spline conversion tolerance (0: 1e-4 x diagonal)", 0.0)
        g = "Continuity"
        add(obj, "Float", "MaxGap", g, "Largest gap across a shared edge", 0.0, True)
        add(obj, "Float", "MaxNormalAngle", g, "Largest normal angle across a shared edge, degrees", 0.0, True)
        add(obj, "Float", "WorstPatchError", g, "Largest fit error of any patch to its points", 0.0, True)
        add(obj, "IntegerList", "C0Fallback", g, "Segments kept C0 under c1", [], True)
        g = "Result"
        add(obj, "Integer", "FaceCount", g, "Faces of the shape", 0, True)
        add(obj, "Bool", "Closed", g, "The shell is closed (the shape is a solid)", False, True)
        add(obj, "Float", "Volume", g, "Volume of the solid (0 when open)", 0.0, True)
        add(obj, "Float", "Area", g, "Surface area", 0.0, True)

    def build(self, obj: Any) -> Any:
        """1. Read the cloud; 2. fit the surfaces; 3. sew them with Part; 4. measure."""
        from pde2cad.fc.shape import build_shape, continuity_figures
        from pde2cad.reconstruct import fit_surfaces

        points, labels = read_source(obj)
        terms: Any = int(obj.Terms) if obj.Terms > 0 else "auto"
        model = fit_surfaces(
            points, labels, m=terms, n=terms, continuity=str(obj.Continuity),
            tolerance=float(obj.Tolerance) or None, cad_tolerance=float(obj.CadTolerance) or None,
            progress=lambda stage, done, total: FreeCAD.Console.PrintLog(
                f"pde2cad {obj.Label}: {stage} {done}/{total}\n"),
        )
        shape, _, info = build_shape(model)
        fig = continuity_figures(model, shape)
        obj.MaxGap, obj.MaxNormalAngle = fig["max_gap"], fig["max_angle_deg"]
        obj.WorstPatchError, obj.C0Fallback = fig["worst_patch_error"], fig["c0_fallback"]
        obj.FaceCount, obj.Closed = len(shape.Faces), bool(info.is_solid)
        obj.Volume, obj.Area = (float(shape.Volume) if info.is_solid else 0.0), float(shape.Area)
        obj.Status = (
            f"{shape.ShapeType}: {len(shape.Faces)} faces from {len(points)} points, "
            f"{fig['free_edges']} free edges, max gap {fig['max_gap']:.3g}, max normal angle "
            f"{fig['max_angle_deg']:.3g} deg, worst patch error {fig['worst_patch_error']:.3g}"
            + (f", C0 fallback {fig['c0_fallback']}" if fig["c0_fallback"] else "")
        )
        FreeCAD.Console.PrintMessage(f"pde2cad {obj.Label}: {obj.Status}\n")
        return shape


class SurfaceViewProvider(ViewProvider):
    icon_name = "surface"
