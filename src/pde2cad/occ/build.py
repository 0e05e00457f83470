"""OCP adapter of the reconstruction: a :class:`~pde2cad.reconstruct.SurfaceModel` to a sewn
shape.

The FreeCAD counterpart is ``pde2cad.fc.shape.build_shape`` (same model in, a ``Part`` shape
out); both sew at ``model.sew_tolerance``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from OCP.gp import gp_Trsf, gp_Vec
from OCP.Message import Message, Message_Gravity
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS_Face, TopoDS_Shape

from pde2cad.occ.shape import SewInfo, make_face, sew

if TYPE_CHECKING:
    from pde2cad.reconstruct import SurfaceModel


def _placement(model: SurfaceModel) -> NDArray[np.float64]:
    """The translation the faces are built relative to: the cloud's centre when it sits
    farther than its own size from the origin, else zero.

    STEP and IGES print reals with about 13 significant digits: poles written at 1e7 lose
    1e-6 of a metre-sized part, and the two faces of a shared edge round differently (gaps
    of 1e-6 D read back). Poles relative to the centre keep every digit that matters, and
    the one placement shared by all faces rounds the same way for every face.
    """
    centre = np.zeros(3) if model.frame is None else np.asarray(model.frame.centre, float)
    return centre if np.linalg.norm(centre) > model.diagonal else np.zeros(3)


def build_shape(model: SurfaceModel) -> tuple[TopoDS_Shape, list[TopoDS_Face], SewInfo]:
    """Faces of the model's surfaces, sewn into a shell (a solid when closed).

    1. One face per surface, bounded by its full parameter rectangle, in ``model.labels``
       order, with poles relative to :func:`_placement` (zero unless the cloud sits far
       from the origin).
    2. Sew them at ``model.sew_tolerance`` (shared edges are identical curves).
    3. Place the shape (and the faces) back by that translation, as a location: the file
       writes local poles plus one placement.

    Parameters
    ----------
    model : SurfaceModel

    Returns
    -------
    shape : TopoDS_Shape
        The sewn shell, or solid when the shell is closed.
    faces : list of TopoDS_Face
        One face per segment, in ``model.labels`` order.
    sew_info : SewInfo
    """
    offset = _placement(model)
    faces = [
        make_face(dataclasses.replace(model.surfaces[label],
                                      poles=model.surfaces[label].poles - offset))
        for label in model.labels
    ]
    shape, info = sew(faces, tolerance=model.sew_tolerance)
    if not offset.any():
        return shape, faces, info
    trsf = gp_Trsf()
    trsf.SetTranslation(gp_Vec(*map(float, offset)))
    place = TopLoc_Location(trsf)
    return shape.Moved(place), [f.Moved(place) for f in faces], info


@contextmanager
def quiet_messages() -> Iterator[None]:
    """Silence OCCT's messages (its transfer statistics go to stdout) inside the block."""
    printers = list(Message.DefaultMessenger_s().Printers())
    levels = [p.GetTraceLevel() for p in printers]
    for p in printers:
        p.SetTraceLevel(Message_Gravity.Message_Fail)
    try:
        yield
    finally:
        for p, level in zip(printers, levels, strict=True):
            p.SetTraceLevel(level)


__all__ = ["build_shape", "quiet_messages"]
