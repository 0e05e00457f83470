"""OCP adapter of the reconstruction: a :class:`~pde2cad.reconstruct.SurfaceModel` to a sewn
shape.

The FreeCAD counterpart is ``pde2cad.fc.shape.build_shape`` (same model in, a ``Part`` shape
out); both sew at ``model.sew_tolerance``.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from OCP.Message import Message, Message_Gravity
from OCP.TopoDS import TopoDS_Face, TopoDS_Shape

from pde2cad.occ.shape import SewInfo, make_face, sew

if TYPE_CHECKING:
    from pde2cad.reconstruct import SurfaceModel


def build_shape(model: SurfaceModel) -> tuple[TopoDS_Shape, list[TopoDS_Face], SewInfo]:
    """Faces of the model's surfaces, sewn into a shell (a solid when closed).

    1. One face per surface, bounded by its full parameter rectangle, in ``model.labels``
       order.
    2. Sew them at ``model.sew_tolerance`` (shared edges are identical curves).

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
    faces = [make_face(model.surfaces[label]) for label in model.labels]
    shape, info = sew(faces, tolerance=model.sew_tolerance)
    return shape, faces, info


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
