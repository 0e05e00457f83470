"""DXF R2010 export of a :class:`~pde2cad.image.drawing.Drawing` (adapter around ezdxf).

Coordinates
    The image frame (x right, y down, pixels) is mapped to the DXF frame (y up) by
    ``x_dxf = x_px * s`` and ``y_dxf = (height - y_px) * s``. With ``drawing.mm_per_px``
    set, ``s = mm_per_px``, the coordinates are millimetres and the header says so
    (``$INSUNITS = 4``, ``$MEASUREMENT = 1``). Without a scale, ``s = 1``: one drawing unit
    is one pixel and the file is marked unitless (``$INSUNITS = 0``); the CAD user has to
    scale it on import.

Layers
    ``OUTER`` (colour 7, white/black) holds the outer loops of shapes (also shapes nested
    inside holes), ``HOLES`` (colour 1, red) the hole loops.

Curve modes
    ``"spline"``: each closed loop is ONE degree-3 SPLINE that is exactly the chain of cubic
    Béziers: control points p0, p1, p2, p3, p1', p2', p3', ... and a clamped knot vector with
    triple interior knots ``[0,0,0,0, 1,1,1, ..., K-1,K-1,K-1, K,K,K,K]``, so knot span k is
    Bézier k. The loop is closed geometrically (last control point == first control point);
    the SPLINE "closed" flag (70 bit 1) is NOT set, because readers take it to mean a
    periodic spline with wrapped control points, which this is not.

    ``"polyline"``: each loop is a closed LWPOLYLINE whose chord error is at most
    ``tolerance``.

    ``"arcs"``: each loop is a closed LWPOLYLINE of lines and circular arcs (bulges) from
    G1 biarcs within ``tolerance``: what laser/CNC controllers without spline support want.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves.arcs import bezier_to_arcs, bezier_to_polyline
from pde2cad.errors import ExportError, InputError
from pde2cad.image.drawing import Drawing
from pde2cad.io.atomic import atomic_path

if TYPE_CHECKING:
    from ezdxf.layouts import Modelspace

__all__ = ["write_dxf", "to_dxf_coords", "spline_data", "CURVE_MODES"]

CURVE_MODES = ("spline", "polyline", "arcs")
LAYER_OUTER = "OUTER"
LAYER_HOLES = "HOLES"
_COLOR_OUTER = 7
_COLOR_HOLES = 1
# Default tolerance of the flattened modes, as a fraction of the fit tolerance: the export
# error then stays an order of magnitude below the fitting error already accepted.
_DEFAULT_TOL_FRACTION = 0.1


def to_dxf_coords(
    curves: NDArray[np.float64], height: float, scale: float
) -> NDArray[np.float64]:
    """Map control points from the image frame to the DXF frame.

    Parameters
    ----------
    curves : (..., 2) float
        Pixel coordinates, x right, y down.
    height : float
        Image height in pixels.
    scale : float
        Drawing units per pixel (mm per px, or 1 for unitless output).

    Returns
    -------
    (..., 2) float
        ``(x * scale, (height - y) * scale)``.
    """
    c = np.asarray(curves, dtype=float)
    out = np.empty_like(c)
    out[..., 0] = c[..., 0] * scale
    out[..., 1] = (height - c[..., 1]) * scale
    return out


def spline_data(curves: NDArray[np.float64]) -> tuple[NDArray[np.float64], list[float]]:
    """Control points and knots of the degree-3 B-spline equal to a closed Bézier chain.

    Parameters
    ----------
    curves : (K, 4, 2) float
        Closed chain: curve k ends where curve k+1 starts, the last ends at the first start.

    Returns
    -------
    control_points : (3K + 1, 2) float
        p0 of curve 0, then p1, p2, p3 of every curve; the last point is set bit-for-bit
        equal to the first so the spline closes exactly.
    knots : list of float, length 3K + 5
        ``[0,0,0,0, 1,1,1, 2,2,2, ..., K,K,K,K]``.
    """
    c = np.asarray(curves, dtype=float)
    k = len(c)
    cps = np.concatenate([c[:1, 0], c[:, 1:].reshape(-1, 2)])
    cps[-1] = cps[0]
    # Triple interior knots make the B-spline only C0 at the joins, so each knot span is
    # exactly one Bézier segment (a knot of multiplicity = degree is a Bézier end point).
    knots = [0.0] * 4 + [float(i) for i in range(1, k) for _ in range(3)] + [float(k)] * 4
    return cps, knots


def _loop_polyline(curves: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """Vertices (n, 2) of the closed polyline through a chain, last vertex not repeated."""
    return np.concatenate([bezier_to_polyline(c, tol)[:-1] for c in curves])


def _loop_bulges(curves: NDArray[np.float64], tol: float) -> list[tuple[float, ...]]:
    """LWPOLYLINE vertices ``(x, y, start_width, end_width, bulge)`` for a closed chain."""
    verts: list[tuple[float, ...]] = []
    for c in curves:
        for seg in bezier_to_arcs(c, tol):
            verts.append((float(seg.start[0]), float(seg.start[1]), 0.0, 0.0, seg.bulge))
    return verts


def _add_loop(
    msp: Modelspace, curves: NDArray[np.float64], mode: str, tol: float, layer: str
) -> None:
    attribs: dict[str, Any] = {"layer": layer}
    if mode == "spline":
        cps, knots = spline_data(curves)
        spline = msp.add_spline(dxfattribs=attribs)
        spline.dxf.degree = 3
        spline.control_points = [(float(x), float(y), 0.0) for x, y in cps]
        spline.knots = knots
    elif mode == "polyline":
        pts = _loop_polyline(curves, tol)
        if len(pts) >= 2:
            msp.add_lwpolyline(pts.tolist(), format="xy", close=True, dxfattribs=attribs)
    else:
        verts = _loop_bulges(curves, tol)
        if len(verts) >= 2:
            msp.add_lwpolyline(verts, format="xyseb", close=True, dxfattribs=attribs)


def _add_line_loop(msp: Modelspace, curves: NDArray[np.float64], is_line: list[bool], layer: str) -> bool:
    """A loop of straight lines only is written as one closed LWPOLYLINE of exact line
    edges (in every mode); returns False for loops with curves."""
    if not is_line or not all(is_line):
        return False
    msp.add_lwpolyline(curves[:, 0].tolist(), format="xy", close=True, dxfattribs={"layer": layer})
    return True


def _validate(drawing: Drawing, curves: str, tolerance: float | None) -> None:
    if curves not in CURVE_MODES:
        raise InputError(f"curves must be one of {', '.join(CURVE_MODES)}, got {curves!r}")
    drawing.validate()
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be a positive number or None, got {tolerance}")
    if tolerance is None and curves != "spline" and not drawing.tolerance > 0:
        raise InputError(
            f"drawing.tolerance is {drawing.tolerance}; pass tolerance=... for {curves} output"
        )


def write_dxf(
    drawing: Drawing,
    path: str | Path,
    curves: str = "spline",
    tolerance: float | None = None,
) -> None:
    """Write ``drawing`` as a DXF R2010 file.

    Parameters
    ----------
    drawing : Drawing
        Loops of cubic Béziers ``(K, 4, 2)`` in pixels (x right, y down).
    path : str or Path
        Output file; written atomically (on failure the target is left untouched).
    curves : {"spline", "polyline", "arcs"}
        How loops are written; see the module docstring.
    tolerance : float, optional
        Maximum deviation of "polyline"/"arcs" output from the Béziers, in DXF drawing
        units (mm when ``drawing.mm_per_px`` is set, else pixels). Default:
        ``0.1 * drawing.tolerance`` pixels converted to drawing units. Unused for splines,
        which are exact.

    Raises
    ------
    InputError
        Unknown ``curves`` mode, bad tolerance, or NaN coordinates.
    ExportError
        ezdxf is missing, the folder does not exist, or the file cannot be written.
    """
    _validate(drawing, curves, tolerance)
    try:
        import ezdxf
    except ImportError as exc:  # optional dependency
        raise ExportError(
            "DXF export needs ezdxf; install it with: pip install 'pde2cad[dxf]'"
        ) from exc

    scale = float(drawing.mm_per_px) if drawing.mm_per_px is not None else 1.0
    tol = tolerance if tolerance is not None else _DEFAULT_TOL_FRACTION * drawing.tolerance * scale

    units = 4 if drawing.mm_per_px is not None else 0  # 4 = mm, 0 = unitless
    doc = ezdxf.new("R2010", setup=True, units=units)
    doc.header["$INSUNITS"] = units
    if drawing.mm_per_px is not None:
        doc.header["$MEASUREMENT"] = 1  # metric
    doc.layers.add(LAYER_OUTER, color=_COLOR_OUTER)
    doc.layers.add(LAYER_HOLES, color=_COLOR_HOLES)
    w, h = drawing.width * scale, drawing.height * scale
    doc.header["$EXTMIN"] = (0.0, 0.0, 0.0)
    doc.header["$EXTMAX"] = (w, h, 0.0)
    # Open the file zoomed on the image area instead of the origin.
    doc.set_modelspace_vport(height=h * 1.05, center=(w / 2.0, h / 2.0))

    msp = doc.modelspace()
    for shape in drawing.shapes():
        for loop in shape:
            if loop.n_curves == 0:
                continue
            c = to_dxf_coords(loop.curves, drawing.height, scale)
            layer = LAYER_HOLES if loop.is_hole else LAYER_OUTER
            if not _add_line_loop(msp, c, loop.is_line, layer):
                _add_loop(msp, c, curves, tol, layer)

    try:
        with atomic_path(path) as tmp:
            doc.saveas(tmp)
    except ExportError:
        raise
    except OSError as exc:
        raise ExportError(
            f"cannot write DXF {path}: {exc}; check the path and permissions"
        ) from exc
