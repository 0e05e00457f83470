"""Hand-made Bézier outlines shared by the SVG and DXF writer tests."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

_K = 4.0 / 3.0 * np.tan(np.pi / 8.0)


def circle_curves(cx: float, cy: float, r: float) -> NDArray[np.float64]:
    """A circle as 4 cubic Béziers (4, 4, 2)."""
    out = []
    for q in range(4):
        a0, a1 = q * np.pi / 2.0, (q + 1) * np.pi / 2.0
        p0, p3 = np.array([np.cos(a0), np.sin(a0)]), np.array([np.cos(a1), np.sin(a1)])
        t0, t1 = np.array([-np.sin(a0), np.cos(a0)]), np.array([-np.sin(a1), np.cos(a1)])
        out.append(np.array([p0, p0 + _K * t0, p3 - _K * t1, p3]) * r + [cx, cy])
    return np.array(out)


def square_curves(x0: float, y0: float, x1: float, y1: float) -> NDArray[np.float64]:
    """An axis-aligned rectangle as 4 straight cubic Béziers (4, 4, 2)."""
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    out = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        out.append(np.array([a, a + (b - a) / 3.0, a + 2.0 * (b - a) / 3.0, b]))
    return np.array(out)
