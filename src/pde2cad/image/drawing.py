"""The result of vectorizing an image: loops of cubic Bézier curves, grouped into shapes.

Coordinates are image pixels: x to the right, y downwards, pixel (row i, col j) is the unit
square [j, j+1] x [i, i+1] (the SVG convention). Writers convert to mm and flip y for DXF.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass
class OutlineLoop:
    """One closed boundary loop fitted with cubic Béziers.

    Attributes
    ----------
    curves : (K, 4, 2) float
        Control points of K cubic Béziers; curve k ends where curve k+1 starts and the last
        ends where the first starts (the loop is closed exactly).
    is_hole : bool
        True for the boundary of a hole in a shape.
    shape : int
        Index of the shape (foreground connected component) the loop bounds.
    depth : int
        Nesting depth: 0 for the outer loop of a top-level shape, 1 for its holes, 2 for the
        outer loop of a shape inside such a hole, and so on.
    max_error, mean_error : float
        Distance in pixels from the loop's pixel-boundary vertices to the curves.
    parameterizations : list of str
        The parameterization chosen per curve ("uniform", "chord", "centripetal", ...).
    corners : int
        Number of corners (sharp joins) on the loop.
    symmetry : str or None
        "mirror" or "rotation:k" when the loop was fitted on its fundamental part only.
    fitted_curves : int
        Independent curves: those of the fitted (fundamental) part for a symmetric loop, the
        rest being its mirrored/rotated copies (the thesis's count, Section 3.1); otherwise
        equal to the number of curves.
    is_line : list of bool
        Per curve: True for a straight line segment (its cubic is the degree-elevated line,
        so readers that ignore the flag still draw it exactly). Empty means all False.
    """

    curves: NDArray[np.float64]
    is_hole: bool
    shape: int
    depth: int
    max_error: float = 0.0
    mean_error: float = 0.0
    parameterizations: list[str] = field(default_factory=list)
    corners: int = 0
    symmetry: str | None = None
    fitted_curves: int = -1
    is_line: list[bool] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.fitted_curves < 0:
            self.fitted_curves = int(len(self.curves))
        if not self.is_line:
            self.is_line = [False] * len(self.curves)

    @property
    def n_lines(self) -> int:
        return int(sum(self.is_line))

    @property
    def n_curves(self) -> int:
        return int(len(self.curves))


@dataclass
class Drawing:
    """A vectorized image: its loops, the image size and the fit settings.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    loops : list of OutlineLoop
        All loops; ``shapes()`` groups them (outer loop first, then its holes).
    tolerance : float
        The tolerance in pixels the curves were fitted to.
    mm_per_px : float or None
        Physical scale, when the user gave ``--dpi`` or ``--scale``.
    time_s : float
        Wall time of the trace in seconds.
    specks : int
        Loops dropped by despeckling (specks removed and small holes filled).
    """

    width: int
    height: int
    loops: list[OutlineLoop]
    tolerance: float
    mm_per_px: float | None = None
    time_s: float = 0.0
    specks: int = 0

    @property
    def n_curves(self) -> int:
        return int(sum(loop.n_curves for loop in self.loops))

    @property
    def n_fitted_curves(self) -> int:
        """Independent curves (symmetric copies not counted), the thesis's measure."""
        return int(sum(loop.fitted_curves for loop in self.loops))

    @property
    def max_error(self) -> float:
        return max((loop.max_error for loop in self.loops), default=0.0)

    @property
    def mean_error(self) -> float:
        counts = [loop.n_curves for loop in self.loops]
        if not counts or sum(counts) == 0:
            return 0.0
        return float(np.average([loop.mean_error for loop in self.loops], weights=counts))

    def validate(self) -> None:
        """Raise InputError when the drawing cannot be written (writers call this first)."""
        from pde2cad.errors import InputError

        if self.width <= 0 or self.height <= 0:
            raise InputError(f"drawing size must be positive, got {self.width} x {self.height} px")
        if self.mm_per_px is not None and not (np.isfinite(self.mm_per_px) and self.mm_per_px > 0):
            raise InputError(f"mm_per_px must be a positive number or None, got {self.mm_per_px}")
        for loop in self.loops:
            c = np.asarray(loop.curves, dtype=float)
            if c.size and (c.ndim != 3 or c.shape[1:] != (4, 2)):
                raise InputError(f"loop curves must have shape (K, 4, 2), got {c.shape}")
            if not np.all(np.isfinite(c)):
                raise InputError(
                    f"loop of shape {loop.shape} has NaN or inf control points; refit the image"
                )

    def shapes(self) -> list[list[OutlineLoop]]:
        """Loops grouped per shape, each group with its outer loop first, then its holes."""
        groups: dict[int, list[OutlineLoop]] = {}
        for loop in self.loops:
            groups.setdefault(loop.shape, []).append(loop)
        return [sorted(g, key=lambda lp: lp.is_hole) for _, g in sorted(groups.items())]

    def write_svg(self, path: str | Path) -> None:
        """Write an SVG file (one path per shape, even-odd fill); see :mod:`pde2cad.io.svg`."""
        from pde2cad.io.svg import write_svg

        write_svg(self, path)

    def write_dxf(self, path: str | Path, curves: str = "spline", *, version: str = "R2010",
                  offset: float = 0.0) -> list[str]:
        """Write a DXF file; ``curves`` is "spline", "polyline" or "arcs", ``version`` "R12",
        "R2000" or "R2010", ``offset`` a kerf distance (see :func:`pde2cad.io.dxf.write_dxf`).
        Returns the writer's notes (loops an offset closed)."""
        from pde2cad.io.dxf import write_dxf

        return write_dxf(self, path, curves=curves, version=version, offset=offset)

    def to_build123d(self) -> list[Any]:
        """One build123d ``Face`` per shape (outer loop with its holes) in the XY plane, in mm
        when ``mm_per_px`` is set, ready for ``build123d.extrude``; needs OCP and build123d.
        See :mod:`pde2cad.occ.drawing`."""
        from pde2cad.occ.drawing import drawing_to_build123d

        return drawing_to_build123d(self)

    def to_cadquery(self) -> list[Any]:
        """One CadQuery ``Face`` per shape, as :meth:`to_build123d`."""
        from pde2cad.occ.drawing import drawing_to_cadquery

        return drawing_to_cadquery(self)

    def report(self) -> dict[str, Any]:
        """A JSON-ready summary: loops, curves per loop, errors, parameterizations, symmetry."""
        return {
            "width": self.width,
            "height": self.height,
            "tolerance_px": self.tolerance,
            "mm_per_px": self.mm_per_px,
            "shapes": len(self.shapes()),
            "loops": len(self.loops),
            "curves": self.n_curves,
            "lines": int(sum(lp.n_lines for lp in self.loops)),
            "fitted_curves": self.n_fitted_curves,
            "max_error_px": self.max_error,
            "mean_error_px": self.mean_error,
            "time_s": self.time_s,
            "specks_dropped": self.specks,
            "loop_details": [
                {
                    "shape": lp.shape,
                    "is_hole": lp.is_hole,
                    "depth": lp.depth,
                    "curves": lp.n_curves,
                    "lines": lp.n_lines,
                    "fitted_curves": lp.fitted_curves,
                    "corners": lp.corners,
                    "max_error_px": lp.max_error,
                    "mean_error_px": lp.mean_error,
                    "parameterizations": lp.parameterizations,
                    "symmetry": lp.symmetry,
                }
                for lp in self.loops
            ],
        }
