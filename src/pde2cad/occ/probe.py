"""Probe points of the faces of a shape, for telling which read-back face is which.

A STEP or IGES round trip may reorder faces, so a face index from
:func:`~pde2cad.occ.continuity.measure` cannot be mapped back to a segment label by position.
:func:`face_centres` gives one surface point per face, in the same ``TopExp`` map order that
:func:`~pde2cad.occ.continuity.measure` numbers faces by; the caller matches those points to
its own surfaces.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepTools import BRepTools
from OCP.TopAbs import TopAbs_FACE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from pde2cad.errors import InputError


def face_centres(shape: TopoDS_Shape) -> NDArray[np.float64]:
    """The point at the centre of each face's parameter range.

    Parameters
    ----------
    shape : TopoDS_Shape
        Face, shell, solid or compound.

    Returns
    -------
    (F, 3) float
        Row ``i`` is the surface point at the middle of face ``i``'s UV bounds, faces in
        ``TopExp.MapShapes`` order (the face indices of ``measure``). The face location is
        applied (``BRepAdaptor_Surface`` works in global coordinates).

    Notes
    -----
    The UV bounds of a face are those of its trimming loops; for the untrimmed four-sided
    faces pde2cad writes they are the whole surface domain, whose middle a linear
    reparameterisation (as exchange formats may apply) maps to the same 3D point.
    """
    if shape is None or shape.IsNull():
        raise InputError("cannot probe the faces of a null shape")
    face_map = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_FACE, face_map)
    out = np.empty((face_map.Extent(), 3))
    for i in range(face_map.Extent()):
        face = TopoDS.Face_s(face_map.FindKey(i + 1))
        umin, umax, vmin, vmax = BRepTools.UVBounds_s(face)
        p = BRepAdaptor_Surface(face, True).Value(0.5 * (umin + umax), 0.5 * (vmin + vmax))
        out[i] = (p.X(), p.Y(), p.Z())
    return out


__all__ = ["face_centres"]
