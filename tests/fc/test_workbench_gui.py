"""The workbench in the real FreeCAD GUI under Xvfb: it activates, its commands are
registered with menu and toolbar, they run on samples (and refuse a wrong selection), and
a screenshot of the result is written and is not blank."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]


def test_workbench_runs_in_the_gui(freecad_gui, tmp_path: Path) -> None:  # noqa: ANN001
    shot = tmp_path / "pde2cad_gui.png"
    out = freecad_gui("""
        import FreeCAD, FreeCADGui as Gui
        from PySide import QtGui
        Gui.activateWorkbench("Pde2CadWorkbench")
        out["workbench"] = Gui.activeWorkbench().name()
        out["commands"] = sorted(c for c in Gui.listCommands() if c.startswith("Pde2Cad_"))
        bars = Gui.getMainWindow().findChildren(QtGui.QToolBar)
        out["toolbar"] = [len(b.actions()) for b in bars if b.windowTitle() == "pde2cad"]
        out["menu"] = [m.title() for m in Gui.getMainWindow().menuBar().findChildren(QtGui.QMenu)
                       if m.title() == "pde2cad"]
        from freecad.pde2cad import commands
        doc = FreeCAD.newDocument("gui")
        box = doc.addObject("Part::Box", "Box")
        doc.recompute()
        Gui.Selection.clearSelection()
        Gui.Selection.addSelection(box)
        out["refuse"] = [commands.SurfaceFromPoints().IsActive(), commands.Export().IsActive(),
                         commands.SurfaceFromPoints().Activated() is None]
        Gui.Selection.clearSelection()
        s = commands.SurfaceFromPoints().Activated(ARGS["cloud"])
        o = commands.SketchFromImage().Activated(ARGS["image"])
        o.ScaleMode, o.MmPerPixel = "MmPerPixel", 0.02
        o.Placement.Base = FreeCAD.Vector(1.5, -1.0, 0)
        doc.recompute()
        out["surface"] = [s.isValid(), s.Shape.isValid(), s.Shape.ShapeType, len(s.Shape.Faces)]
        out["outline"] = [o.isValid(), o.Shape.isValid(), len(o.Shape.Faces), doc.getObject(o.SketchName).isValid()]
        out["undo"] = doc.UndoNames
        Gui.Selection.addSelection(s)
        out["export"] = str(commands.Export().Activated(ARGS["step"]))
        Gui.Selection.clearSelection()
        box.ViewObject.Visibility = False
        view = Gui.ActiveDocument.ActiveView
        view.viewIsometric()
        view.fitAll()
        Gui.updateGui()
        view.saveImage(ARGS["shot"], 800, 600, "White")
    """, gui=True, cloud=str(ROOT / "examples" / "clouds" / "sphere6.ply"),
        image=str(ROOT / "examples" / "images" / "glyph_B.png"), shot=str(shot),
        step=str(tmp_path / "gui_sphere.step"))
    assert out["workbench"] == "Pde2CadWorkbench"
    assert out["commands"] == ["Pde2Cad_Export", "Pde2Cad_SketchFromImage", "Pde2Cad_SurfaceFromPoints"]
    assert out["toolbar"] == [3] and out["menu"] == ["pde2cad"]
    assert out["refuse"] == [False, False, True]  # a Part box is no cloud, nor exportable
    assert out["surface"] == [True, True, "Solid", 6]
    assert out["outline"][:2] == [True, True] and out["outline"][3]
    assert {"Surface from points", "Sketch from image"} <= set(out["undo"])
    assert Path(out["export"]).stat().st_size > 10_000
    pixels = np.asarray(Image.open(shot).convert("RGB"), dtype=int)
    assert pixels.shape == (600, 800, 3)
    coloured = (np.abs(pixels - 255).sum(axis=2) > 60).mean()
    assert coloured > 0.05, f"screenshot nearly blank ({coloured:.3f} of the pixels drawn)"
