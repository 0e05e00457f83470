"""The pde2cad workbench (FreeCAD imports ``freecad.pde2cad.init_gui`` at GUI start)."""

from __future__ import annotations

import FreeCADGui as Gui

from freecad.pde2cad import icon


class Pde2CadWorkbench(Gui.Workbench):
    """Scan to surface, image to sketch."""

    MenuText = "pde2cad"
    ToolTip = "Point clouds to sewn B-spline surfaces, images to constrained sketches"
    Icon = icon("pde2cad")

    def Initialize(self) -> None:  # noqa: N802 - FreeCAD's name
        from freecad.pde2cad import commands

        names = commands.register()
        self.appendToolbar("pde2cad", names)
        self.appendMenu("pde2cad", names)

    def GetClassName(self) -> str:  # noqa: N802
        return "Gui::PythonWorkbench"


Gui.addWorkbench(Pde2CadWorkbench())
