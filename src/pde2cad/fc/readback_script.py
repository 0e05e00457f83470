"""Read a STEP/IGES file with FreeCAD and measure it; prints one JSON object on stdout.

Runs in FreeCAD's own Python (never in the process that imported OCP: the two bundle
different OpenCASCADE builds)::

    /usr/bin/python3 readback_script.py FILE [SAMPLES]

The gap and angle measurement is :func:`pde2cad.fc.shape.measure_continuity` (the package
is found next to this file, so it runs with Debian's FreeCAD 0.20 as installed).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

FREECAD_LIB = "/usr/lib/freecad-python3/lib"


def measure(path: str, samples: int = 20) -> dict:
    """Validity, topology, volume and the shared-edge gaps/angles of a STEP/IGES file."""
    sys.path.append(FREECAD_LIB)
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import FreeCAD
    import Part

    from pde2cad.fc.shape import measure_continuity

    shape = Part.Shape()
    shape.read(path)
    figures = measure_continuity(shape, samples)
    return {
        "reader": "FreeCAD " + ".".join(FreeCAD.Version()[:3]),
        "valid": bool(shape.isValid()),
        "n_faces": len(shape.Faces),
        "n_shells": len(shape.Shells),
        "n_solids": len(shape.Solids),
        "closed": bool(shape.Shells) and all(s.isClosed() for s in shape.Shells)
        and figures["free_edges"] == 0,
        "shared_edges": figures["shared_edges"],
        "free_edges": figures["free_edges"],
        "max_gap": figures["max_gap"],
        "max_angle_deg": figures["max_angle_deg"],
        "volume": float(shape.Volume) if shape.Solids else None,
    }


if __name__ == "__main__":
    result = measure(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 20)
    sys.stdout.write("\nPDE2CAD-JSON " + json.dumps(result) + "\n")
