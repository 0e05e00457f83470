"""OpenCASCADE (OCP) adapter: B-spline surfaces to faces, sewn shells and solids, STEP/IGES.

This package is the only place in pde2cad that imports OCP (``cadquery-ocp``); the core
modules stay kernel-neutral and hand over :class:`~pde2cad.bspline.data.BSplineSurface`
objects (anything with ``poles``, ``knots_u``, ``knots_v``, ``degree_u``, ``degree_v``).
Importing it without OCP installed raises :class:`ImportError`; install ``pde2cad[cad]``.
"""

from __future__ import annotations

from pde2cad.occ.continuity import measure
from pde2cad.occ.drawing import drawing_faces
from pde2cad.occ.export import export_iges, export_step
from pde2cad.occ.naming import segment_face_names
from pde2cad.occ.shape import (
    SewInfo,
    as_topods,
    make_face,
    read_iges,
    read_step,
    sew,
    to_build123d,
    to_cadquery,
    to_geom_surface,
    volume,
    write_iges,
    write_step,
)

__all__ = [
    "SewInfo",
    "as_topods",
    "drawing_faces",
    "export_iges",
    "export_step",
    "make_face",
    "measure",
    "read_iges",
    "read_step",
    "segment_face_names",
    "sew",
    "to_build123d",
    "to_cadquery",
    "to_geom_surface",
    "volume",
    "write_iges",
    "write_step",
]
