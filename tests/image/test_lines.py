"""Straight runs become line segments (issue 11, item 2): one segment each, exact edges."""

from __future__ import annotations

import ezdxf
import numpy as np

from pde2cad.image.evaluate import outline_error, parse_svg_paths
from pde2cad.image.vectorize import vectorize


def _plate() -> np.ndarray:
    """A plate with a straight top edge on row 20 and a round notch in its bottom edge."""
    m = np.zeros((120, 200), bool)
    m[20:100, 20:180] = True
    y, x = np.mgrid[0:120, 0:200] + 0.5
    m[np.hypot(x - 100, y - 100) < 30] = False
    return m


def test_rectangle_is_four_lines_on_the_pixel_edges():
    m = np.zeros((100, 140), bool)
    m[20:80, 15:125] = True
    d = vectorize(m)
    loop = d.loops[0]
    assert loop.n_curves == 4 and loop.is_line == [True] * 4
    corners = np.sort(loop.curves[:, 0], axis=0)
    assert np.allclose(sorted(map(tuple, loop.curves[:, 0])), [(15, 20), (15, 80), (125, 20), (125, 80)], atol=0.3)
    assert corners.shape == (4, 2)


def test_straight_edge_of_a_plate_stays_on_its_row(tmp_path):
    m = _plate()
    d = vectorize(m, symmetry=False)
    loop = d.loops[0]
    assert loop.n_lines >= 3  # top, left, right (the bottom is split by the notch)
    top = [c for c, flag in zip(loop.curves, loop.is_line) if flag and abs(c[0, 1] - c[3, 1]) < 1e-9 and c[0, 1] < 60]
    assert top and all(abs(c[0, 1] - 20.0) < 0.05 for c in top)  # no wandering off row 20
    err = outline_error(m, [lp.curves for lp in d.loops])
    assert err["max_boundary_to_curve"] <= 1.0 and err["max_curve_to_boundary"] <= 1.05


def test_svg_writes_lines_as_L_and_dxf_as_line_edges(tmp_path):
    m = np.zeros((60, 80), bool)
    m[10:50, 10:70] = True
    d = vectorize(m)
    svg, dxf = tmp_path / "r.svg", tmp_path / "r.dxf"
    d.write_svg(svg)
    d.write_dxf(dxf)
    text = svg.read_text()
    assert text.count(" L ") == 4 and " C " not in text
    curves, segments = parse_svg_paths(text)
    assert segments == 4
    ents = ezdxf.readfile(dxf).modelspace().query("LWPOLYLINE")
    assert len(ents) == 1 and len(list(ents[0].vertices())) == 4
