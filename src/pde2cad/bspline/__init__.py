"""B-spline curves and surfaces, and exact / toleranced conversion of the patches to them."""

from __future__ import annotations

from pde2cad.bspline.convert import (
    add_surfaces,
    coons_to_bspline,
    curve_to_bspline,
    deformation_to_bspline,
    patch_to_bspline,
)
from pde2cad.bspline.data import SIDES, BSplineCurve, BSplineSurface
from pde2cad.bspline.reduce import reduce_curve, reduce_surface, remove_knot

__all__ = [
    "SIDES",
    "BSplineCurve",
    "BSplineSurface",
    "add_surfaces",
    "coons_to_bspline",
    "curve_to_bspline",
    "deformation_to_bspline",
    "patch_to_bspline",
    "reduce_curve",
    "reduce_surface",
    "remove_knot",
]
