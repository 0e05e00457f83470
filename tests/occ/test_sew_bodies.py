"""Sewing several closed shells: separate bodies become solids, a shell inside another a void."""

from __future__ import annotations

import pytest

pytest.importorskip("OCP")

from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox  # noqa: E402
from OCP.gp import gp_Pnt  # noqa: E402
from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID  # noqa: E402
from OCP.TopoDS import TopoDS  # noqa: E402

from pde2cad.occ.shape import _subshapes, sew, volume  # noqa: E402


def _faces(shape: object) -> list:
    return [TopoDS.Face_s(f) for f in _subshapes(shape, TopAbs_FACE)]


def _box(corner: float, size: float, x: float = 0.0) -> list:
    """Faces of a cube (sewing joins their edges; a primitive sphere is one seamed face)."""
    return _faces(BRepPrimAPI_MakeBox(gp_Pnt(x + corner, corner, corner), size, size, size)
                  .Shape())


def test_two_bodies_apart_give_two_solids() -> None:
    shape, info = sew(_box(0.0, 1.0) + _box(0.0, 2.0, x=5.0))
    solids = _subshapes(shape, TopAbs_SOLID)
    assert info.is_closed and info.is_solid and info.valid and info.n_shells == 2
    assert sorted(volume(s) for s in solids) == pytest.approx([1.0, 8.0], rel=1e-9)


def test_box_inside_a_box_is_a_void() -> None:
    """A cube of side 1 inside a cube of side 4: one solid of volume 64 - 1 (not two
    overlapping solids)."""
    shape, info = sew(_box(-2.0, 4.0) + _box(-0.5, 1.0))
    assert info.is_solid and info.valid and info.n_shells == 2
    assert len(_subshapes(shape, TopAbs_SOLID)) == 1
    assert volume(shape) == pytest.approx(63.0, rel=1e-9)


def test_box_in_a_hollow_box_is_a_third_body() -> None:
    shape, info = sew(_box(-3.0, 6.0) + _box(-2.0, 4.0) + _box(-0.5, 1.0))
    solids = _subshapes(shape, TopAbs_SOLID)
    assert info.is_solid and info.valid and len(solids) == 2
    assert sorted(volume(s) for s in solids) == pytest.approx([1.0, 216.0 - 64.0], rel=1e-9)
