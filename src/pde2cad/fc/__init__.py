"""FreeCAD adapter: read our STEP/IGES back with FreeCAD 0.20 and measure it there.

FreeCAD and OCP carry different OpenCASCADE builds and must never share a process, so the
measuring runs in FreeCAD's own Python (``/usr/bin/python3`` with Debian's
``freecad-python3``; ``PDE2CAD_FREECAD_PYTHON`` overrides it) as a subprocess, with the
standalone :mod:`pde2cad.fc.readback_script`. This is how a FreeCAD user will see the file:
validity, shells, solids, free edges, and the gap and normal angle across every shared edge
as FreeCAD's own geometry evaluates them.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any

from pde2cad.errors import ExportError, InputError

#: FreeCAD's Python interpreter (Debian's FreeCAD 0.20 is built for the system python3).
DEFAULT_PYTHON = "/usr/bin/python3"
SCRIPT = Path(__file__).resolve().parent / "readback_script.py"
_MARK = "PDE2CAD-JSON "


def freecad_python() -> str | None:
    """The interpreter that can ``import FreeCAD``, or None when FreeCAD is not installed."""
    python = os.environ.get("PDE2CAD_FREECAD_PYTHON", DEFAULT_PYTHON)
    if not Path(python).exists() or not Path("/usr/lib/freecad-python3/lib").is_dir():
        return None
    return python


def read_back(path: str | Path, samples: int = 20, timeout: float = 600.0) -> dict[str, Any]:
    """Read a STEP or IGES file with FreeCAD and measure it.

    Parameters
    ----------
    path : str or Path
    samples : int
        Points per shared edge for the gap and the normal angle.
    timeout : float
        Seconds before the FreeCAD process is given up.

    Returns
    -------
    dict
        ``{"reader", "valid", "n_faces", "n_shells", "n_solids", "closed", "shared_edges",
        "free_edges", "max_gap", "max_angle_deg", "volume"}`` (volume None without a solid).

    Raises
    ------
    InputError
        The file does not exist.
    ExportError
        FreeCAD is not installed (``apt-get install freecad-python3``) or failed to read it.
    """
    file = Path(path)
    if not file.is_file():
        raise InputError(f"{file}: no such file to read back with FreeCAD")
    python = freecad_python()
    if python is None:
        raise ExportError(
            "FreeCAD is not installed: run `apt-get install freecad-python3` (Debian's FreeCAD "
            "0.20) or set PDE2CAD_FREECAD_PYTHON to the Python that can import FreeCAD"
        )
    proc = subprocess.run(
        [python, str(SCRIPT), str(file.resolve()), str(int(samples))],
        capture_output=True, text=True, timeout=timeout, check=False,
    )
    for line in proc.stdout.splitlines():
        if line.startswith(_MARK):
            return dict(json.loads(line[len(_MARK):]))
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
    raise ExportError(f"FreeCAD could not read {file}: {' | '.join(tail) or 'no output'}")


__all__ = ["freecad_python", "read_back"]
