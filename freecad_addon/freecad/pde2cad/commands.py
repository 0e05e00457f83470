"""GUI commands of the workbench: Surface from points, Sketch from image, Export.

Each command has an icon and a tooltip, is active only when the selection suits it, and
wraps its document change in an undo transaction. Problems (nothing selected, a wrong
object, an unreadable file) go to the Report view; no command raises into the GUI.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import FreeCAD
import FreeCADGui

from freecad.pde2cad import api, icon
from freecad.pde2cad.sources import is_mesh, is_points

CLOUD_FILTER = "Point clouds (*.ply *.xyz *.pts *.txt *.csv *.npy *.stl *.obj)"
IMAGE_FILTER = "Images (*.png *.bmp *.pbm *.pgm *.jpg *.jpeg *.tif *.tiff)"
EXPORT_FILTER = "STEP (*.step *.stp);;IGES (*.iges *.igs);;DXF (*.dxf);;SVG (*.svg)"


def _ask_file(title: str, filters: str, save: bool = False) -> str:
    from PySide import QtGui

    dialog = QtGui.QFileDialog.getSaveFileName if save else QtGui.QFileDialog.getOpenFileName
    name = dialog(FreeCADGui.getMainWindow(), title, "", filters)
    return name[0] if isinstance(name, tuple) else str(name)


def _transaction(doc: Any, title: str, work: Any) -> Any:
    """Run ``work()`` inside an undo transaction; report (not raise) what goes wrong."""
    doc.openTransaction(title)
    try:
        result = work()
    except Exception as exc:  # noqa: BLE001 - a command never raises into the GUI
        doc.abortTransaction()
        FreeCAD.Console.PrintError(f"pde2cad {title}: {exc}\n")
        return None
    doc.commitTransaction()
    return result


class SurfaceFromPoints:
    """A surface feature from the selected Points/Mesh object, or from a cloud file."""

    def GetResources(self) -> dict[str, str]:  # noqa: N802 - FreeCAD's name
        return {
            "Pixmap": icon("surface"),
            "MenuText": "Surface from points",
            "ToolTip": "Fit sewn B-spline patches (C1) to the selected labelled Points or Mesh "
                       "object, or to a cloud file when nothing is selected",
        }

    def IsActive(self) -> bool:  # noqa: N802
        if FreeCAD.ActiveDocument is None:
            return False
        sel = FreeCADGui.Selection.getSelection()
        return not sel or (len(sel) == 1 and (is_points(sel[0]) or is_mesh(sel[0])))

    def Activated(self, source: Any = None) -> Any:  # noqa: N802
        doc = FreeCAD.ActiveDocument
        if doc is None:
            FreeCAD.Console.PrintError("pde2cad: open or create a document first\n")
            return None
        if source is None:
            sel = FreeCADGui.Selection.getSelection()
            if sel and not (is_points(sel[0]) or is_mesh(sel[0])):
                FreeCAD.Console.PrintError(
                    f"pde2cad: {sel[0].Label} is not a Points or Mesh object; select one\n")
                return None
            source = sel[0] if sel else _ask_file("Point cloud", CLOUD_FILTER)
        if not source:
            FreeCAD.Console.PrintError("pde2cad: no point cloud selected\n")
            return None
        labels = "segments" if is_mesh(source) else _guess_labels(source)
        return _transaction(doc, "Surface from points",
                            lambda: api.make_surface(doc, source, labels=labels))


def _guess_labels(source: Any) -> Any:
    """The label source a user most likely means: a ``Labels`` property of the object, or
    the usual PLY label properties of a file."""
    if not isinstance(source, str):
        return "Labels" if "Labels" in source.PropertiesList else None
    if source.lower().endswith(".ply"):
        from pde2cad.io.clouds import _ply_header

        names = [p for _, _, props in _ply_header(Path(source))[1] for p, _ in props]
        for name in ("label", "scalar_label", "scalar_Label", "segment"):
            if name in names:
                return name
    return "column4" if source.lower().endswith((".npy", ".xyz", ".txt", ".csv")) else None


class SketchFromImage:
    """An outline feature and its sketch from an image file."""

    def GetResources(self) -> dict[str, str]:  # noqa: N802
        return {
            "Pixmap": icon("sketch"),
            "MenuText": "Sketch from image",
            "ToolTip": "Vectorize a binary image into Bézier/B-spline outlines: faces ready "
                       "for Pad and a constrained sketch on the XY plane (scale in the "
                       "feature's Scale properties: DPI, mm per pixel or a known length)",
        }

    def IsActive(self) -> bool:  # noqa: N802
        return FreeCAD.ActiveDocument is not None

    def Activated(self, path: str | None = None) -> Any:  # noqa: N802
        doc = FreeCAD.ActiveDocument
        image = path or _ask_file("Image", IMAGE_FILTER)
        if not image:
            FreeCAD.Console.PrintError("pde2cad: no image chosen\n")
            return None
        return _transaction(doc, "Sketch from image", lambda: api.make_outline(doc, image))


class Export:
    """Export the selected surface features (STEP/IGES) or outline feature (DXF/SVG)."""

    def GetResources(self) -> dict[str, str]:  # noqa: N802
        return {
            "Pixmap": icon("export"),
            "MenuText": "Export",
            "ToolTip": "Write the selected surface features to STEP/IGES, or the selected "
                       "outline feature to DXF/SVG",
        }

    def IsActive(self) -> bool:  # noqa: N802
        sel = FreeCADGui.Selection.getSelection()
        return bool(sel) and (all(api.is_surface(o) for o in sel)
                              or (len(sel) == 1 and api.is_outline(sel[0])))

    def Activated(self, path: str | None = None) -> Any:  # noqa: N802
        sel = FreeCADGui.Selection.getSelection()
        target = path or _ask_file("Export", EXPORT_FILTER, save=True)
        if not target:
            return None
        try:
            written = api.export(sel, target)
        except Exception as exc:  # noqa: BLE001 - report, never raise into the GUI
            FreeCAD.Console.PrintError(f"pde2cad export: {exc}\n")
            return None
        FreeCAD.Console.PrintMessage(f"pde2cad: wrote {written}\n")
        return written


COMMANDS = {
    "Pde2Cad_SurfaceFromPoints": SurfaceFromPoints,
    "Pde2Cad_SketchFromImage": SketchFromImage,
    "Pde2Cad_Export": Export,
}


def register() -> list[str]:
    """Add the commands to FreeCAD's GUI; returns their names."""
    for name, command in COMMANDS.items():
        FreeCADGui.addCommand(name, command())
    return list(COMMANDS)
