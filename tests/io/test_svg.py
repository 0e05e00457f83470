"""SVG export: structure, exact control points, units, atomic writing."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad.errors import ExportError, InputError
from pde2cad.image.drawing import Drawing, OutlineLoop
from pde2cad.io.svg import format_number, svg_string, write_svg

SVG_NS = "{http://www.w3.org/2000/svg}"
from drawing_shapes import circle_curves, square_curves  # noqa: E402


def make_drawing(mm_per_px: float | None = None) -> Drawing:
    """Two shapes: a circle (shape 0) and a square with a square hole (shape 1)."""
    loops = [
        OutlineLoop(circle_curves(30.123456, 40.5, 20.0), is_hole=False, shape=0, depth=0),
        OutlineLoop(square_curves(60, 10, 180, 130), is_hole=False, shape=1, depth=0),
        OutlineLoop(square_curves(90, 40, 150, 100)[::-1, ::-1], is_hole=True, shape=1, depth=1),
    ]
    return Drawing(width=200, height=150, loops=loops, tolerance=0.5, mm_per_px=mm_per_px)


def parse_path(d: str) -> list[NDArray[np.float64]]:
    """Loops (K, 4, 2) from ``M x y C ... Z`` path data with one C per cubic."""
    loops = []
    for sub in re.findall(r"M([^MZ]*)Z", d):
        head, *cs = sub.split("C")
        start = np.array(head.split(), dtype=float)
        curves = []
        for c in cs:
            pts = np.array(c.split(), dtype=float).reshape(3, 2)
            curves.append(np.vstack([start, pts]))
            start = pts[-1]
        loops.append(np.array(curves))
    return loops


def test_structure_and_exact_coordinates() -> None:
    dr = make_drawing()
    root = ET.fromstring(svg_string(dr))
    assert root.tag == f"{SVG_NS}svg"
    assert root.get("viewBox") == "0 0 200 150"
    assert root.get("width") == "200" and root.get("height") == "150"
    paths = root.findall(f"{SVG_NS}path")
    shapes = dr.shapes()
    assert len(paths) == len(shapes) == 2
    for path, shape in zip(paths, shapes):
        assert path.get("fill-rule") == "evenodd"
        assert path.get("fill") == "#000000"
        assert path.get("stroke") == "none"
        d = path.get("d")
        assert d.count("C") == sum(lp.n_curves for lp in shape)
        assert d.count("M") == d.count("Z") == len(shape)
        parsed = parse_path(d)
        assert len(parsed) == len(shape)
        for got, loop in zip(parsed, shape):
            assert got.shape == loop.curves.shape
            # 4 decimals: round-off at most 5e-5 per coordinate.
            assert np.max(np.abs(got - loop.curves)) <= 5e-5 + 1e-12


def test_outer_loop_written_before_hole() -> None:
    dr = make_drawing()
    d = ET.fromstring(svg_string(dr)).findall(f"{SVG_NS}path")[1].get("d")
    outer, hole = parse_path(d)
    assert np.allclose(outer, dr.loops[1].curves, atol=5e-5)
    assert np.allclose(hole, dr.loops[2].curves, atol=5e-5)


def test_mm_size_keeps_pixel_viewbox() -> None:
    dr = make_drawing(mm_per_px=25.4 / 96.0)
    root = ET.fromstring(svg_string(dr))
    assert root.get("width") == "52.9167mm"  # 200 px at 96 dpi
    assert root.get("height") == "39.6875mm"
    assert root.get("viewBox") == "0 0 200 150"
    d = root.findall(f"{SVG_NS}path")[0].get("d")
    assert np.allclose(parse_path(d)[0], dr.loops[0].curves, atol=5e-5)


def test_format_number() -> None:
    assert format_number(12.5) == "12.5"
    assert format_number(3.0) == "3"
    assert format_number(-0.00001) == "0"
    assert format_number(1.234567) == "1.2346"
    assert format_number(-7.25) == "-7.25"


def test_stroke_option() -> None:
    root = ET.fromstring(svg_string(make_drawing(), fill="none", stroke="#ff0000"))
    p = root.findall(f"{SVG_NS}path")[0]
    assert p.get("fill") == "none" and p.get("stroke") == "#ff0000"


def test_write_svg_file(tmp_path: Path) -> None:
    dr = make_drawing()
    out = tmp_path / "out.svg"
    write_svg(dr, out)
    assert out.read_text(encoding="utf-8") == svg_string(dr)
    assert [p.name for p in tmp_path.iterdir()] == ["out.svg"]  # no temp file left over
    dr.write_svg(tmp_path / "again.svg")  # the Drawing convenience method
    assert (tmp_path / "again.svg").read_text(encoding="utf-8") == svg_string(dr)


def test_empty_drawing_is_valid_svg() -> None:
    root = ET.fromstring(svg_string(Drawing(10, 10, [], tolerance=0.5)))
    assert root.findall(f"{SVG_NS}path") == []


def test_missing_folder_raises_export_error(tmp_path: Path) -> None:
    target = tmp_path / "missing" / "out.svg"
    with pytest.raises(ExportError, match="does not exist"):
        write_svg(make_drawing(), target)
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "out.svg"
    target.write_text("old", encoding="utf-8")

    def boom(self: Path, *args: object, **kwargs: object) -> int:
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_text", boom)
    with pytest.raises(ExportError, match="disk full"):
        write_svg(make_drawing(), target)
    monkeypatch.undo()
    assert target.read_text(encoding="utf-8") == "old"  # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["out.svg"]


def test_nan_rejected() -> None:
    dr = make_drawing()
    dr.loops[0].curves[1, 2, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        svg_string(dr)
