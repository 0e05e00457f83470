"""DXF export of a :class:`~pde2cad.image.drawing.Drawing` (adapter around ezdxf).

Written so CAM software takes the file as it is: ``ezdxf audit`` clean for every version,
``$EXTMIN/$EXTMAX`` set to the extents of the geometry, outer loops counter-clockwise and
holes clockwise in the DXF frame (how CAM tells inside from outside), closed polylines
flagged closed.

Coordinates
    The image frame (x right, y down, pixels) is mapped to the DXF frame (y up) by
    ``x_dxf = x_px * s`` and ``y_dxf = (height - y_px) * s``. With ``drawing.mm_per_px``
    set, ``s = mm_per_px``, the coordinates are millimetres and the header says so
    (``$INSUNITS = 4``, ``$MEASUREMENT = 1``; R12 has neither). Without a scale, ``s = 1``:
    one drawing unit is one pixel and the file is marked unitless (``$INSUNITS = 0``).

Layers
    ``OUTER`` (colour 7, white/black) holds the outer loops of shapes (also shapes nested
    inside holes), ``HOLES`` (colour 1, red) the hole loops.

Curve modes
    ``"spline"``: one degree-3 SPLINE per corner-to-corner run of a loop (a loop without
    corners is one run). A corner is a join whose tangents differ (not G1). Each run is
    exactly its chain of cubic Béziers: control points p0, p1, p2, p3, p1', ... and a
    clamped knot vector with triple interior knots ``[0,0,0,0, 1,1,1, ..., m,m,m,m]``, so
    knot span k is Bézier k and every corner is a spline end point, which every reader
    hits exactly. Readers that draw a spline as a polyline sampled evenly in parameter
    (LibreCAD: ``8 x control points`` samples over the whole knot range) then cut no
    corner; Béziers are split (exactly, de Casteljau) until such a sampling stays within
    ``tolerance``. The SPLINE "closed" flag (70 bit 1) is not set: LibreCAD reads it as
    "wrap the first 3 control points and use uniform periodic knots", which would redraw
    these clamped splines as a different curve; runs are open by construction and a
    cornerless loop's spline starts and ends bit-for-bit at the same point.

    ``"polyline"``: each loop is a closed LWPOLYLINE (R12: POLYLINE) whose chord error is
    at most ``tolerance``.

    ``"arcs"``: each loop is a closed LWPOLYLINE (R12: POLYLINE) of lines and circular
    arcs (bulges) from G1 biarcs within ``tolerance``: what laser/CNC controllers without
    spline support want. R12 has no SPLINE, so "spline" becomes "arcs" there.

Kerf offset
    ``offset=d`` grows the material by ``d`` (outer loops out, holes in; see
    :mod:`pde2cad.io.kerf`), written as lines and arcs within ``tolerance``; holes the
    offset closes are left out and reported.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves.arcs import bezier_to_arcs, bezier_to_polyline
from pde2cad.curves.bezier import split
from pde2cad.errors import ExportError, InputError
from pde2cad.image.drawing import Drawing
from pde2cad.io.atomic import atomic_path

if TYPE_CHECKING:
    from ezdxf.document import Drawing as DxfDocument
    from ezdxf.layouts import Modelspace

__all__ = [
    "write_dxf", "dxf_document", "to_dxf_coords", "spline_data", "spline_runs",
    "corner_joins", "CURVE_MODES", "DXF_VERSIONS", "SPLINE_SAMPLES_PER_SPAN",
]  # fmt: skip

CURVE_MODES = ("spline", "polyline", "arcs")
DXF_VERSIONS = ("R12", "R2000", "R2010")
#: Fewest samples per Bézier span of a reader that samples evenly in parameter: LibreCAD
#: takes $SPLINESEGS (8) x (3m + 1) points over m spans, i.e. more than 24 per span.
SPLINE_SAMPLES_PER_SPAN = 24
#: Joins whose tangent directions differ by more than this (radians) are corners.
_CORNER_ANGLE = 1e-6
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
    """Control points and knots of the degree-3 B-spline equal to a Bézier chain.

    Parameters
    ----------
    curves : (K, 4, 2) float
        Chain: curve k ends where curve k+1 starts.

    Returns
    -------
    control_points : (3K + 1, 2) float
        p0 of curve 0, then p1, p2, p3 of every curve.
    knots : list of float, length 3K + 5
        ``[0,0,0,0, 1,1,1, 2,2,2, ..., K,K,K,K]``.
    """
    c = np.asarray(curves, dtype=float)
    k = len(c)
    cps = np.concatenate([c[:1, 0], c[:, 1:].reshape(-1, 2)])
    # Triple interior knots make the B-spline only C0 at the joins, so each knot span is
    # exactly one Bézier segment (a knot of multiplicity = degree is a Bézier end point).
    knots = [0.0] * 4 + [float(i) for i in range(1, k) for _ in range(3)] + [float(k)] * 4
    return cps, knots




# --------------------------------------------------------------------------- spline runs
def _end_directions(c: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit start and end tangents (K, 2) of Béziers (K, 4, 2); coincident control points
    fall back to the next distinct one (p1 == p0 -> p2 - p0, and so on)."""
    def first_distinct(d: NDArray[np.float64]) -> NDArray[np.float64]:
        # d: (K, 3, 2) differences from the end point, nearest first.
        n = np.hypot(d[..., 0], d[..., 1])
        idx = np.argmax(n > 1e-12 * (1.0 + np.max(np.abs(c))), axis=1)
        pick = d[np.arange(len(d)), idx]
        return pick / np.maximum(np.hypot(pick[:, 0], pick[:, 1]), 1e-300)[:, None]

    start = first_distinct(c[:, 1:] - c[:, :1])
    end = first_distinct(c[:, 3:4] - c[:, 2::-1])
    return start, end


def corner_joins(curves: NDArray[np.float64], angle: float = _CORNER_ANGLE) -> NDArray[np.int64]:
    """Indices j of the Béziers that start at a corner of a closed chain (K, 4, 2).

    Join j is the end of curve j-1 (cyclically) and the start of curve j; it is a corner
    when the two tangent directions differ by more than ``angle`` radians.
    """
    c = np.asarray(curves, dtype=float)
    start, end = _end_directions(c)
    cos = np.einsum("ij,ij->i", np.roll(end, 1, axis=0), start)
    return np.flatnonzero(cos < np.cos(angle))


def _refine(run: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """Split Béziers (exactly) until a polyline through samples 1/24 apart in parameter
    stays within ``tol`` of each: chord error <= h^2 / 8 max|B''| with h = 1/24 and
    max|B''| = 6 max(|p0 - 2 p1 + p2|, |p1 - 2 p2 + p3|)."""
    h = 1.0 / SPLINE_SAMPLES_PER_SPAN
    out = []
    for c in run:
        pieces = [c]
        for _ in range(12):  # each split quarters the second differences
            d2 = np.stack([p[0] - 2 * p[1] + p[2] for p in pieces] + [p[1] - 2 * p[2] + p[3] for p in pieces])
            if 6.0 * np.max(np.hypot(d2[:, 0], d2[:, 1])) * h * h / 8.0 <= tol:
                break
            pieces = [half for p in pieces for half in split(p, 0.5)]
        out.extend(pieces)
    return np.asarray(out)


def spline_runs(curves: NDArray[np.float64], tol: float | None = None) -> list[NDArray[np.float64]]:
    """A closed chain (K, 4, 2) cut at its corners into runs (m, 4, 2), in loop order.

    A loop without corners is one run starting at curve 0. With ``tol``, the Béziers of
    each run are split until even sampling in parameter stays within ``tol`` (see
    :data:`SPLINE_SAMPLES_PER_SPAN`).
    """
    c = np.asarray(curves, dtype=float)
    cuts = corner_joins(c)
    if len(cuts) == 0:
        cuts = np.array([0])
    rolled = np.roll(c, -int(cuts[0]), axis=0)
    bounds = list(cuts - cuts[0]) + [len(c)]
    runs = [rolled[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    return [_refine(r, tol) for r in runs] if tol is not None else runs


# --------------------------------------------------------------------------- loops
def _signed_area(curves: NDArray[np.float64]) -> float:
    """Area enclosed by a closed Bézier chain, positive when counter-clockwise (y up).

    Exact: the shoelace integral of each cubic in closed form (Green's theorem).
    """
    p = np.asarray(curves, dtype=float)
    x, y = p[..., 0], p[..., 1]
    # Half the integral of x dy - y dx over a cubic: sum_ij x_i y_j M[i, j] / 20, where
    # M / 10 = N - N^T and N[i, j] = integral of B_i B_j' over [0, 1] (Bernstein basis).
    m = np.array([[0, 6, 3, 1], [-6, 0, 3, 3], [-3, -3, 0, 6], [-1, -3, -6, 0]], dtype=float)
    return float(np.einsum("ki,ij,kj->", x, m, y)) / 20.0


def _oriented(curves: NDArray[np.float64], hole: bool) -> NDArray[np.float64]:
    """The chain run counter-clockwise for outer loops, clockwise for holes."""
    ccw = _signed_area(curves) > 0.0
    return curves if ccw != hole else curves[::-1, ::-1].copy()


def _loop_polyline(curves: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """Vertices (n, 2) of the closed polyline through a chain, last vertex not repeated."""
    return np.concatenate([bezier_to_polyline(c, tol)[:-1] for c in curves])


def _loop_bulges(curves: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """Bulge vertices ``(x, y, bulge)`` (n, 3) of a closed chain's biarcs."""
    return np.array(
        [(*seg.start, seg.bulge) for c in curves for seg in bezier_to_arcs(c, tol)], dtype=float
    )


def _add_closed(msp: Modelspace, verts: NDArray[np.float64], r12: bool, layer: str) -> None:
    """A closed polyline of ``(x, y)`` or ``(x, y, bulge)`` vertices."""
    if len(verts) < 2:
        return
    fmt = "xyb" if verts.shape[1] == 3 else "xy"
    attribs: dict[str, Any] = {"layer": layer}
    if r12:
        msp.add_polyline2d(verts.tolist(), format=fmt, close=True, dxfattribs=attribs)
    else:
        msp.add_lwpolyline(verts.tolist(), format=fmt, close=True, dxfattribs=attribs)


def _add_loop(msp: Modelspace, curves: NDArray[np.float64], mode: str, tol: float,
              layer: str, r12: bool) -> None:
    if mode == "spline":
        for run in spline_runs(curves, tol):
            cps, knots = spline_data(run)
            spline = msp.add_spline(dxfattribs={"layer": layer})
            spline.dxf.degree = 3
            spline.control_points = [(float(x), float(y), 0.0) for x, y in cps]
            spline.knots = knots
    elif mode == "polyline":
        _add_closed(msp, _loop_polyline(curves, tol), r12, layer)
    else:
        _add_closed(msp, _loop_bulges(curves, tol), r12, layer)


# --------------------------------------------------------------------------- document
def _validate(drawing: Drawing, curves: str, tolerance: float | None, version: str,
              offset: float) -> None:
    if curves not in CURVE_MODES:
        raise InputError(f"curves must be one of {', '.join(CURVE_MODES)}, got {curves!r}")
    if version not in DXF_VERSIONS:
        raise InputError(f"version must be one of {', '.join(DXF_VERSIONS)}, got {version!r}")
    if not np.isfinite(offset):
        raise InputError(f"offset must be a finite distance, got {offset}")
    drawing.validate()
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be a positive number or None, got {tolerance}")
    if tolerance is None and not drawing.tolerance > 0:
        raise InputError(f"drawing.tolerance is {drawing.tolerance}; pass tolerance=...")


def _new_document(drawing: Drawing, version: str) -> DxfDocument:
    try:
        import ezdxf
    except ImportError as exc:  # optional dependency
        raise ExportError(
            "DXF export needs ezdxf; install it with: pip install 'pde2cad[dxf]'"
        ) from exc
    units = 4 if drawing.mm_per_px is not None else 0  # 4 = mm, 0 = unitless
    doc = ezdxf.new(version, setup=True)
    if version != "R12":  # R12 has no unit header variables
        doc.header["$INSUNITS"] = units
        doc.header["$MEASUREMENT"] = 1 if drawing.mm_per_px is not None else 0
    doc.layers.add(LAYER_OUTER, color=_COLOR_OUTER)
    doc.layers.add(LAYER_HOLES, color=_COLOR_HOLES)
    return doc


def _set_extents(doc: DxfDocument, drawing: Drawing, scale: float) -> None:
    """$EXTMIN/$EXTMAX from the geometry; the view opens on it."""
    from ezdxf import bbox

    box = bbox.extents(doc.modelspace(), fast=False)
    if box.has_data:
        lo, hi = box.extmin, box.extmax
    else:  # an empty drawing: the image area
        lo, hi = (0.0, 0.0, 0.0), (drawing.width * scale, drawing.height * scale, 0.0)
    extmin, extmax = (float(lo[0]), float(lo[1]), 0.0), (float(hi[0]), float(hi[1]), 0.0)
    # ezdxf copies the modelspace layout's extents into the header on save (and leaves the
    # header's +-1e20 when they are unset), so set both.
    msp = doc.modelspace()
    try:
        msp.dxf.extmin, msp.dxf.extmax = extmin, extmax
        msp.dxf.limmin, msp.dxf.limmax = extmin[:2], extmax[:2]
    except Exception:  # noqa: BLE001 - R12 has no LAYOUT object to carry them
        pass
    doc.header["$EXTMIN"], doc.header["$EXTMAX"] = extmin, extmax
    doc.header["$LIMMIN"], doc.header["$LIMMAX"] = extmin[:2], extmax[:2]
    w, h = max(hi[0] - lo[0], 1e-9), max(hi[1] - lo[1], 1e-9)
    doc.set_modelspace_vport(height=max(h, w) * 1.05, center=((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2))


def dxf_document(
    drawing: Drawing,
    curves: str = "spline",
    tolerance: float | None = None,
    version: str = "R2010",
    offset: float = 0.0,
    notes: list[str] | None = None,
) -> DxfDocument:
    """The ezdxf document for ``drawing`` (see :func:`write_dxf`; nothing is written).

    Steps: 1. validate; 2. map every loop to the DXF frame and orient it (outer ccw,
    holes cw); 3. with ``offset``, offset each shape exactly (:mod:`pde2cad.io.kerf`) and
    write lines and arcs, else write the loops in the ``curves`` mode; 4. set the extents.
    Messages about loops the offset closed are appended to ``notes``.
    """
    _validate(drawing, curves, tolerance, version, offset)
    scale = float(drawing.mm_per_px) if drawing.mm_per_px is not None else 1.0
    tol = tolerance if tolerance is not None else _DEFAULT_TOL_FRACTION * drawing.tolerance * scale
    r12 = version == "R12"
    mode = "arcs" if r12 and curves == "spline" else curves
    doc = _new_document(drawing, version)
    msp = doc.modelspace()
    for n, shape in enumerate(drawing.shapes()):
        loops = [(_oriented(to_dxf_coords(lp.curves, drawing.height, scale), lp.is_hole), lp.is_hole)
                 for lp in shape if lp.n_curves > 0]  # fmt: skip
        if not loops:
            continue
        if offset:
            from pde2cad.io.kerf import offset_shape

            rings, lost = offset_shape([c for c, _ in loops], [h for _, h in loops], offset, tol)
            for verts, hole in rings:
                _add_closed(msp, verts, r12, LAYER_HOLES if hole else LAYER_OUTER)
            if lost and notes is not None:
                notes.append(f"offset {offset:g} closes {lost} loop(s) of shape {n}; left out")
            continue
        straight = [bool(lp.is_line) and all(lp.is_line) for lp in shape if lp.n_curves > 0]
        for (c, hole), lines in zip(loops, straight, strict=True):
            layer = LAYER_HOLES if hole else LAYER_OUTER
            if lines:  # a loop of straight lines only: one closed polyline of exact edges
                _add_closed(msp, c[:, 0], r12, layer)
            else:
                _add_loop(msp, c, mode, tol, layer, r12)
    _set_extents(doc, drawing, scale)
    return doc


def write_dxf(
    drawing: Drawing,
    path: str | Path,
    curves: str = "spline",
    tolerance: float | None = None,
    version: str = "R2010",
    offset: float = 0.0,
) -> list[str]:
    """Write ``drawing`` as a DXF file.

    Parameters
    ----------
    drawing : Drawing
        Loops of cubic Béziers ``(K, 4, 2)`` in pixels (x right, y down).
    path : str or Path
        Output file; written atomically (on failure the target is left untouched).
    curves : {"spline", "polyline", "arcs"}
        How loops are written; see the module docstring.
    tolerance : float, optional
        Maximum deviation of the written (or, for splines, the evenly sampled) curves from
        the Béziers, in DXF drawing units (mm when ``drawing.mm_per_px`` is set, else
        pixels). Default: ``0.1 * drawing.tolerance`` pixels converted to drawing units.
    version : {"R12", "R2000", "R2010"}
        DXF version. R12 has no SPLINE/LWPOLYLINE: loops become POLYLINEs with bulges.
    offset : float
        Kerf compensation in drawing units: outer loops grow, holes shrink by ``offset``.

    Returns
    -------
    list of str
        Notes for the user (loops an offset closed up and left out).

    Raises
    ------
    InputError
        Unknown ``curves`` mode or version, bad tolerance or offset, or NaN coordinates.
    ExportError
        ezdxf (or shapely, for an offset) is missing, or the file cannot be written.
    """
    notes: list[str] = []
    doc = dxf_document(drawing, curves, tolerance, version, offset, notes)
    try:
        with atomic_path(path) as tmp:
            doc.saveas(tmp)
    except ExportError:
        raise
    except OSError as exc:
        raise ExportError(
            f"cannot write DXF {path}: {exc}; check the path and permissions"
        ) from exc
    return notes
