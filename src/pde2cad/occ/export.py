"""build123d-style exchange functions that take whatever a script holds.

:func:`export_step` and :func:`export_iges` accept a raw ``TopoDS_Shape``, a build123d or
CadQuery shape (anything with ``.wrapped``), a CadQuery ``Workplane`` (its values), a list of
those (written as one compound), or a reconstruction result (its ``.shape``; its faces are
then named after their segments).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from OCP.TopoDS import TopoDS_Shape

from pde2cad.occ.naming import segment_face_names
from pde2cad.occ.shape import as_topods, write_iges, write_step


def _face_names(obj: object, shape: TopoDS_Shape) -> list[str] | None:
    surfaces = getattr(obj, "surfaces", None)
    return segment_face_names(shape, surfaces) if isinstance(surfaces, dict) else None


def export_step(
    shape: object,
    path: str | Path,
    *,
    schema: str = "AP214",
    units: str = "MM",
    name: str | None = None,
    author: str | None = None,
    organization: str | None = None,
    face_names: Sequence[str] | None = None,
) -> Path:
    """Write ``shape`` (a shape, a list of shapes or a reconstruction) to STEP.

    Faces of a reconstruction are named ``segment_<label>`` unless ``face_names`` is given;
    the other arguments are those of :func:`~pde2cad.occ.shape.write_step`.
    """
    topo = as_topods(shape)
    names = face_names if face_names is not None else _face_names(shape, topo)
    return write_step(
        topo, path, schema=schema, units=units, name=name, author=author,
        organization=organization, face_names=names,
    )


def export_iges(
    shape: object,
    path: str | Path,
    *,
    units: str = "MM",
    name: str | None = None,
    author: str | None = None,
    organization: str | None = None,
    face_names: Sequence[str] | None = None,
) -> Path:
    """Write ``shape`` to IGES 5.3 (BRep); see :func:`export_step` and
    :func:`~pde2cad.occ.shape.write_iges`."""
    topo = as_topods(shape)
    names = face_names if face_names is not None else _face_names(shape, topo)
    return write_iges(
        topo, path, units, name=name, author=author, organization=organization,
        face_names=names,
    )


__all__ = ["export_iges", "export_step"]
