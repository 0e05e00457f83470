"""pde2cad workbench for FreeCAD (namespace package ``freecad.pde2cad``).

The addon is ``freecad.pde2cad``; the algorithms are the separate core package ``pde2cad``
(numpy/scipy only). Importing this package makes the core importable: the repository's
``src/`` next to the addon (found through the symlink ``./setup.sh`` makes in
``~/.local/share/FreeCAD/Mod/pde2cad``) or ``$PDE2CAD_SRC`` is put first on ``sys.path``;
otherwise an installed ``pde2cad`` (``pip install pde2cad`` into FreeCAD's Python) is used.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

__version__ = "0.1.0"
ICONS = Path(__file__).resolve().parent / "resources" / "icons"


def _core_candidates() -> list[Path]:
    """Folders that may hold the core package ``pde2cad``, most specific first."""
    found = [Path(os.environ["PDE2CAD_SRC"])] if os.environ.get("PDE2CAD_SRC") else []
    # freecad_addon/freecad/pde2cad/__init__.py -> the repository's src/ (symlinks resolved).
    found.append(Path(__file__).resolve().parents[3] / "src")
    return found


def ensure_core() -> str:
    """Make ``import pde2cad`` (the core) work; return the folder it is imported from.

    Raises
    ------
    ImportError
        No core found: the message says how to install it.
    """
    for folder in _core_candidates():
        if (folder / "pde2cad" / "__init__.py").is_file():
            if str(folder) not in sys.path:
                sys.path.insert(0, str(folder))
            break
    spec = importlib.util.find_spec("pde2cad")
    if spec is None or spec.origin is None:
        raise ImportError(
            "the pde2cad core is not importable in FreeCAD's Python: run ./setup.sh in the "
            "pde2cad repository, set PDE2CAD_SRC to its src/ folder, or pip install pde2cad"
        )
    return str(Path(spec.origin).parents[1])


def icon(name: str) -> str:
    """Path of an icon of the workbench (``name`` without ``.svg``)."""
    return str(ICONS / f"{name}.svg")


ensure_core()
