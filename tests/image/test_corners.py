"""Corner detection on pixel-boundary loops."""

from __future__ import annotations

import numpy as np

from pde2cad.image.contours import trace_loops
from pde2cad.image.corners import detect_corners


def _disc(r, size=None):
    size = size or int(2 * r + 10)
    y, x = np.mgrid[0:size, 0:size] + 0.5
    return (x - size / 2) ** 2 + (y - size / 2) ** 2 <= r * r


def test_rectangle_has_its_four_corners():
    mask = np.zeros((40, 60), bool)
    mask[5:30, 10:50] = True
    pts = trace_loops(mask)[0].points
    idx = detect_corners(pts)
    got = {tuple(p) for p in pts[idx].astype(int)}
    assert got == {(10, 5), (50, 5), (50, 30), (10, 30)}


def test_discs_have_no_corners():
    # Below ~2.5x the corner scale (r < 10 px) a digital disc is an octagon-like polygon
    # whose turns are as concentrated as corners; at 1 px tolerance that is invisible.
    for r in (12, 20, 60, 150):
        pts = trace_loops(_disc(r))[0].points
        assert len(detect_corners(pts)) == 0, r


def test_triangle_has_three_corners_near_its_vertices():
    size = 120
    y, x = np.mgrid[0:size, 0:size] + 0.5
    a, b, c = np.array([10, 100]), np.array([110, 100]), np.array([40, 10])

    def side(p, q):
        return (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0])

    mask = (side(a, b) <= 0) & (side(b, c) <= 0) & (side(c, a) <= 0)
    if not mask.any():
        mask = (side(a, b) >= 0) & (side(b, c) >= 0) & (side(c, a) >= 0)
    pts = trace_loops(mask)[0].points
    idx = detect_corners(pts)
    assert len(idx) == 3
    for v in (a, b, c):
        assert np.min(np.linalg.norm(pts[idx] - v, axis=1)) < 3.0
