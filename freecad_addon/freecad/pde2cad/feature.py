"""What the workbench's parametric features share: typed properties, a guarded ``execute``
(bad input -> a Report-view message and an invalid feature, never a traceback dialog) and
persistence of the Python proxies."""

from __future__ import annotations

from typing import Any

import FreeCAD
import Part

from pde2cad.errors import Pde2CadError


class FeatureFailed(RuntimeError):
    """Raised from ``execute`` after the message went to the Report view: FreeCAD then marks
    the feature invalid (``obj.isValid()`` is False) and shows the message on it."""


def add(obj: Any, kind: str, name: str, group: str, doc: str, value: Any = None,
        read_only: bool = False) -> None:
    """Add property ``name`` (``App::Property<kind>``) with ``value`` unless it exists (a
    restored document keeps its values)."""
    if name in obj.PropertiesList:
        return
    obj.addProperty(f"App::Property{kind}", name, group, doc, 0, read_only)
    if value is not None:
        setattr(obj, name, value)


class Feature:
    """Base proxy of a ``Part::FeaturePython``: subclasses define ``properties(obj)`` and
    ``build(obj) -> Part.Shape``."""

    kind = "Feature"

    def __init__(self, obj: Any) -> None:
        obj.Proxy = self
        self.properties(obj)
        add(obj, "String", "Status", "Result", "Outcome of the last recompute", "", True)

    def properties(self, obj: Any) -> None:
        raise NotImplementedError

    def build(self, obj: Any) -> Any:
        raise NotImplementedError

    def execute(self, obj: Any) -> None:
        """Recompute: ``build`` the shape; on failure say why in the Report view and in
        ``Status``, clear the shape and mark the feature invalid."""
        try:
            shape = self.build(obj)
        except Exception as exc:  # noqa: BLE001 - every failure becomes a message, never a crash
            detail = str(exc) if isinstance(exc, (Pde2CadError, OSError)) else f"{type(exc).__name__}: {exc}"
            obj.Status = f"failed: {detail}"
            obj.Shape = Part.Shape()
            FreeCAD.Console.PrintError(f"pde2cad {obj.Label}: {detail}\n")
            raise FeatureFailed(detail) from None
        obj.Shape = shape

    def onDocumentRestored(self, obj: Any) -> None:  # noqa: N802 - FreeCAD's name
        self.properties(obj)

    def __getstate__(self) -> None:
        return None

    def __setstate__(self, state: Any) -> None:
        return None

    dumps = __getstate__
    loads = __setstate__


class ViewProvider:
    """Proxy of the view provider: the feature's icon; the document stores nothing of it."""

    icon_name = "pde2cad"

    def __init__(self, vobj: Any) -> None:
        vobj.Proxy = self

    def getIcon(self) -> str:  # noqa: N802 - FreeCAD's name
        from freecad.pde2cad import icon

        return icon(self.icon_name)

    def attach(self, vobj: Any) -> None:
        self.Object = vobj.Object

    def __getstate__(self) -> None:
        return None

    def __setstate__(self, state: Any) -> None:
        return None

    dumps = __getstate__
    loads = __setstate__
