"""Names in exchange files: the part, its faces, who wrote it and with what.

Without this, OCCT writes its own defaults into every file ("Open CASCADE STEP translator"
as the part name, "Author", "Filename.iges"), and a user cannot tell files apart or trace a
face back to the segment it came from. The shape goes through an XCAF document (OCCT's
assembly/attribute model), where the part and each face carry a ``TDataStd_Name``; the
STEP/IGES CAF writers turn those into the ``PRODUCT`` name and the ``ADVANCED_FACE`` names
(STEP), the part label and name properties of the faces (IGES, entity 406 form 15).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.TCollection import TCollection_ExtendedString, TCollection_HAsciiString
from OCP.TDataStd import TDataStd_Name
from OCP.TDocStd import TDocStd_Document
from OCP.TopAbs import TopAbs_FACE
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Face, TopoDS_Shape
from OCP.XCAFDoc import XCAFDoc_DocumentTool

from pde2cad.errors import InputError


def faces_of(shape: TopoDS_Shape) -> list[TopoDS_Face]:
    """The faces of ``shape`` in ``TopExp_Explorer`` order (the order ``face_names`` use)."""
    out = []
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        out.append(TopoDS.Face_s(explorer.Current()))
        explorer.Next()
    return out


def named_document(
    shape: TopoDS_Shape, name: str, face_names: Sequence[str] | None = None
) -> TDocStd_Document:
    """An XCAF document holding ``shape`` named ``name``, its faces named ``face_names``.

    Parameters
    ----------
    shape : TopoDS_Shape
    name : str
        Part (product) name.
    face_names : sequence of str, optional
        One name per face in :func:`faces_of` order; an empty string leaves a face unnamed.

    Raises
    ------
    InputError
        When ``face_names`` does not have one entry per face.
    """
    doc = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
    label = tool.AddShape(shape, False)
    TDataStd_Name.Set_s(label, TCollection_ExtendedString(clean_name(name)))
    if face_names is not None:
        faces = faces_of(shape)
        names = [str(n) for n in face_names]
        if len(names) != len(faces):
            raise InputError(
                f"face_names has {len(names)} names but the shape has {len(faces)} faces; "
                "give one name per face in TopExp_Explorer order"
            )
        for face, face_name in zip(faces, names):
            if face_name:
                sub = tool.AddSubShape(label, face)
                if not sub.IsNull():
                    TDataStd_Name.Set_s(sub, TCollection_ExtendedString(clean_name(face_name)))
    return doc


def clean_name(text: str) -> str:
    """``text`` as a name every reader takes: ASCII (others become ``?``), no quotes (STEP's
    string delimiter; OCCT does not escape it)."""
    return str(text).encode("ascii", "replace").decode("ascii").replace("'", "_")


def header_text(text: str) -> TCollection_HAsciiString:
    """:func:`clean_name` as the string type of the exchange headers."""
    return TCollection_HAsciiString(clean_name(text))


def segment_face_names(
    shape: TopoDS_Shape, surfaces: Mapping[int, Any], prefix: str = "segment_"
) -> list[str]:
    """Name each face of ``shape`` after the segment whose surface it lies on.

    1. Each segment's surface is evaluated at the middle of its parameter domain.
    2. Each face's own surface is evaluated at the middle of its domain; sewing keeps the
       surfaces, so the two points coincide for the face made from that segment.
    3. Every face takes the segment with the nearest point, if that point is within 1e-6 of
       the shape's size (a face from elsewhere stays unnamed, ``""``).

    Parameters
    ----------
    shape : TopoDS_Shape
    surfaces : mapping of int to BSplineSurface
        Segment label -> surface (``knots_u``, ``knots_v``, ``evaluate``), as in
        :class:`~pde2cad.reconstruct.Reconstruction`.
    prefix : str
        Text before the label.
    """
    labels = list(surfaces)
    if not labels:
        return [""] * len(faces_of(shape))
    mids = np.array([
        np.asarray(s.evaluate(0.5 * (s.knots_u[0] + s.knots_u[-1]),
                              0.5 * (s.knots_v[0] + s.knots_v[-1]))).reshape(3)
        for s in surfaces.values()
    ])
    size = max(float(np.linalg.norm(mids.max(axis=0) - mids.min(axis=0))), 1e-300)
    names = []
    for face in faces_of(shape):
        geom = BRep_Tool.Surface_s(face)
        u1, u2, v1, v2 = geom.Bounds()
        p = geom.Value(0.5 * (u1 + u2), 0.5 * (v1 + v2))
        dist = np.linalg.norm(mids - [p.X(), p.Y(), p.Z()], axis=1)
        k = int(dist.argmin())
        names.append(f"{prefix}{labels[k]}" if dist[k] <= 1e-6 * size else "")
    return names


__all__ = ["faces_of", "named_document", "segment_face_names"]
