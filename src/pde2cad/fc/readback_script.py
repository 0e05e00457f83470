"""Read a STEP/IGES file with FreeCAD and measure it; prints one JSON object on stdout.

Runs in FreeCAD's own Python (never in the process that imported OCP: the two bundle
different OpenCASCADE builds)::

    /usr/bin/python3 readback_script.py FILE [SAMPLES]

Only FreeCAD, Part and the standard library are used (no pde2cad import), so it runs with
Debian's FreeCAD 0.20 as installed.
"""

from __future__ import annotations

import json
import math
import sys

FREECAD_LIB = "/usr/lib/freecad-python3/lib"


def _face_point(face, point):  # type: ignore[no-untyped-def]
    """Closest point on the face's surface to ``point`` and the face's outward normal there."""
    u, v = face.Surface.parameter(point)
    return face.Surface.value(u, v), face.normalAt(u, v)


def measure(path: str, samples: int = 20) -> dict:
    sys.path.append(FREECAD_LIB)
    import FreeCAD  # noqa: F401  (initialises the application)
    import Part

    shape = Part.Shape()
    shape.read(path)
    faces = shape.Faces
    owners: dict[int, list[int]] = {}
    edges = []
    for i, face in enumerate(faces):
        for edge in face.Edges:
            for k, known in enumerate(edges):
                if known.isSame(edge):
                    owners[k].append(i)
                    break
            else:
                owners[len(edges)] = [i]
                edges.append(edge)
    max_gap = max_angle = 0.0
    shared = free = 0
    for k, edge in enumerate(edges):
        who = sorted(set(owners[k]))
        if edge.Degenerated:
            continue
        if len(who) == 1:
            free += 1
            continue
        shared += 1
        fa, fb = faces[who[0]], faces[who[1]]
        first, last = edge.ParameterRange
        for j in range(samples):
            point = edge.valueAt(first + (last - first) * j / (samples - 1))
            pa, na = _face_point(fa, point)
            pb, nb = _face_point(fb, point)
            max_gap = max(max_gap, (pa - pb).Length)
            cross = na.cross(nb).Length
            max_angle = max(max_angle, math.degrees(math.atan2(cross, na.dot(nb))))
    return {
        "reader": "FreeCAD " + ".".join(FreeCAD.Version()[:3]),
        "valid": bool(shape.isValid()),
        "n_faces": len(faces),
        "n_shells": len(shape.Shells),
        "n_solids": len(shape.Solids),
        "closed": bool(shape.Shells) and all(s.isClosed() for s in shape.Shells) and free == 0,
        "shared_edges": shared,
        "free_edges": free,
        "max_gap": max_gap,
        "max_angle_deg": max_angle,
        "volume": float(shape.Volume) if shape.Solids else None,
    }


if __name__ == "__main__":
    result = measure(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 20)
    sys.stdout.write("\nPDE2CAD-JSON " + json.dumps(result) + "\n")
