"""Multi-patch reconstruction of a segmented point cloud (C0): cloud -> sewn B-spline shell.

Pipeline:

1. :func:`~pde2cad.layout.build_layout`: adjacency, border points and global corners.
2. Per segment, its corners are put in loop order (angle around the centroid in the
   segment's PCA plane) and :func:`~pde2cad.surfaces.region.extract_boundary` is run with
   their exact coordinates: it gives the loop orientation and a first fit of every side.
3. Shared edges: an edge is keyed by the sorted pair of its global corner ids. The first time
   an edge is met its curve is fitted once — for an edge two segments share, from the
   layout's border points of the pair (ordered by projection on the first segment's side,
   averaged in short bins to the band's midline, bins next to the corners dropped, then
   :func:`~pde2cad.curves.piecewise.fit_chain` between the exact corner coordinates); for an
   open edge, the segment's boundary-loop run between the same corners. Every patch then uses that
   same :class:`~pde2cad.surfaces.boundary.PiecewiseBezier` (reversed where its loop runs the
   other way), so neighbours interpolate the identical curve.
4. :func:`~pde2cad.surfaces.patch.fit_patch` (C0) per segment with those sides, then
   :func:`~pde2cad.bspline.convert.patch_to_bspline`, faces and :func:`~pde2cad.occ.sew`.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from pde2cad.bspline.convert import patch_to_bspline
from pde2cad.bspline.data import BSplineSurface
from pde2cad.errors import FitError, InputError
from pde2cad.layout import Layout, build_layout
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.patch import Patch, fit_patch
from pde2cad.surfaces.region import RegionBoundary, extract_boundary, fit_side, pca_frame

#: Default CAD (deformation -> B-spline) tolerance, relative to the cloud's bbox diagonal.
CAD_TOLERANCE = 1e-4
#: Sewing tolerance relative to the diagonal (shared edges are identical curves).
SEW_TOLERANCE = 1e-6
#: Samples per side used to order border points along an edge by projection.
EDGE_SAMPLES = 2000
#: Border points farther than this many neighbour radii from the side are ignored.
EDGE_BAND = 3.0
#: Border points are averaged in bins of this many cloud spacings of arc length.
EDGE_BIN = 2.0
#: Border-band bin means closer than this many spacings to an edge's corner are dropped: the
#: corners are cloud points up to a spacing off the band's midline, and a curve forced from
#: the corner onto the midline within a spacing or two kinks and folds the Coons base.
EDGE_END = 4.0
#: Edge-curve breaks are rounded to multiples of 2**-BREAK_BITS (see _dyadic_breaks).
BREAK_BITS = 24


@dataclass
class Reconstruction:
    """Result of :func:`reconstruct`.

    Attributes
    ----------
    shape : TopoDS_Shape
        Sewn shell (or solid when closed).
    patches : dict[int, Patch]
        Fitted patch per segment label.
    surfaces : dict[int, BSplineSurface]
        B-spline surface per segment label.
    faces : list of TopoDS_Face
        One face per segment, in ``labels`` order.
    labels : list of int
        Segment label of each face.
    sew_info : SewInfo
    layout : Layout
    edges : dict[(int, int), PiecewiseBezier]
        The shared curve of each edge, keyed by sorted global corner ids, running from the
        smaller id to the larger.
    edge_errors : dict[(int, int), float]
        Largest distance of the points fitted to each edge curve (bin means of the border
        band for shared edges).
    corners : (C, 3) float
        The corner positions used (the layout's).
    diagonal : float
        Bounding-box diagonal of the cloud.
    timings : dict[str, float]
        Seconds per stage.
    """

    shape: Any
    patches: dict[int, Patch]
    surfaces: dict[int, BSplineSurface]
    faces: list[Any]
    labels: list[int]
    sew_info: Any
    layout: Layout
    edges: dict[tuple[int, int], PiecewiseBezier]
    edge_errors: dict[tuple[int, int], float]
    corners: NDArray[np.float64]
    diagonal: float
    timings: dict[str, float] = field(default_factory=dict)

    def write_step(self, path: str | Path, units: str = "MM") -> Path:
        """Write the sewn shape to a STEP file."""
        from pde2cad.occ import write_step

        return write_step(self.shape, path, units=units)


def _loop_order(seg_points: NDArray[np.float64], corner_xyz: NDArray[np.float64]) -> NDArray[np.int64]:
    """Order of the corners around the segment: angle about the centroid in the PCA plane."""
    origin, axes = pca_frame(seg_points)
    uv = (corner_xyz - origin) @ axes[:2].T
    centre = ((seg_points - origin) @ axes[:2].T).mean(axis=0)
    angle = np.arctan2(uv[:, 1] - centre[1], uv[:, 0] - centre[0])
    return np.argsort(angle)


def _side_run(region: RegionBoundary, k: int) -> NDArray[np.float64]:
    """Loop points of side ``k`` (both corner points included)."""
    n = len(region.loop)
    ends = np.r_[region.corners, n]
    closed = np.vstack([region.loop, region.loop[:1]])
    return closed[ends[k] : ends[k + 1] + 1]


def _dyadic_breaks(curve: PiecewiseBezier) -> PiecewiseBezier:
    """The same curve with its breaks rounded to multiples of ``2**-BREAK_BITS``.

    A neighbour uses the edge reversed, with breaks ``1 - b``; for a dyadic ``b`` that is
    exact, so ``1 - (1 - b) == b`` and the Coons conversion, which unions the breaks of
    opposite sides, never meets two knots an ulp apart (OCCT would merge them into one knot
    of multiplicity 6 > degree and reject the surface).
    """
    scale = 2.0**BREAK_BITS
    snapped = np.round(np.asarray(curve.breaks) * scale) / scale
    if np.all(np.diff(snapped) > 0):
        return PiecewiseBezier(curve.ctrl, snapped)
    return curve


def _fit_edge(
    side: PiecewiseBezier,
    border: NDArray[np.float64],
    start: NDArray[np.float64],
    end: NDArray[np.float64],
    tolerance: float,
    band: float,
    bin_width: float,
    end_gap: float,
) -> tuple[PiecewiseBezier, float] | None:
    """Fit one shared edge from the border points near ``side`` (running start -> end).

    The border band (points of both segments along the edge) is ordered by its closest
    sample of ``side``, averaged in bins of ``bin_width`` arc length (the band's midline),
    bins within ``end_gap`` of a corner dropped, and fitted between the exact corners.
    """
    s = np.linspace(0.0, 1.0, EDGE_SAMPLES)
    samples = side.evaluate(s)
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(samples, axis=0), axis=1))]
    dist, idx = cKDTree(samples).query(border)
    keep = (dist < band) & (idx > 0) & (idx < EDGE_SAMPLES - 1)
    if keep.sum() < 8:
        return None
    t = arc[idx[keep]]
    nbins = max(int(arc[-1] / bin_width), 1)
    which = np.minimum((t / arc[-1] * nbins).astype(np.int64), nbins - 1)
    count = np.bincount(which, minlength=nbins)
    sums = np.stack([np.bincount(which, border[keep, d], minlength=nbins) for d in range(3)], 1)
    mid = sums[count > 0] / count[count > 0, None]
    far = (np.linalg.norm(mid - start, axis=1) > end_gap) & (np.linalg.norm(mid - end, axis=1) > end_gap)
    mid = mid[far]
    if len(mid) < 4:
        return None
    return fit_side(mid, tolerance, start, end)


def reconstruct(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    m: int = 6,
    n: int = 6,
    tolerance: float | None = None,
    cad_tolerance: float | None = None,
) -> Reconstruction:
    """Reconstruct a segmented cloud as C0-joined B-spline faces sewn into one shape.

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
        One segment label per point; every segment must be a 3- or 4-sided region.
    m, n : int
        Deformation terms per patch (see :func:`~pde2cad.surfaces.patch.fit_patch`).
    tolerance : float, optional
        Edge-curve fit tolerance. Default: the larger of the two regions' own side
        tolerances (noise based, at least 1e-4 x region diagonal).
    cad_tolerance : float, optional
        Tolerance of the deformation -> B-spline conversion. Default 1e-4 x the cloud's
        bounding-box diagonal.

    Returns
    -------
    Reconstruction
    """
    from pde2cad.occ import make_face, sew  # OCP is optional: imported only here

    pts = np.asarray(points, dtype=float)
    lab = np.asarray(labels).astype(np.int64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(lab) != len(pts):
        raise InputError(f"points must be (N, 3) with one label each; got {pts.shape}, {lab.shape}")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be a positive number, got {tolerance}")
    diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    layout = build_layout(pts, lab)
    timings["layout"] = time.perf_counter() - t0

    # Step 2: loop order and first sides of every segment.
    t0 = time.perf_counter()
    seg_points: dict[int, NDArray[np.float64]] = {}
    regions: dict[int, RegionBoundary] = {}
    loop_ids: dict[int, list[int]] = {}
    for label in layout.labels_present.tolist():
        sp = pts[lab == label]
        ids = layout.segment_corners[label]
        xyz = layout.corners[ids]
        order = _loop_order(sp, xyz)
        try:
            region = extract_boundary(sp, corners=xyz[order])
        except InputError as exc:
            raise InputError(f"segment {label}: {exc}") from exc
        except FitError as exc:
            raise FitError(f"segment {label}: {exc}") from exc
        # extract_boundary may reverse the order after the first corner: read it back.
        _, back = cKDTree(layout.corners).query(region.corner_points)
        seg_points[label], regions[label], loop_ids[label] = sp, region, [int(i) for i in back]
    timings["boundaries"] = time.perf_counter() - t0

    # Step 3: one curve per edge, keyed by its sorted pair of global corner ids.
    t0 = time.perf_counter()
    users: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for label, ids in loop_ids.items():
        c = len(ids)
        for k in range(c):
            key = (min(ids[k], ids[(k + 1) % c]), max(ids[k], ids[(k + 1) % c]))
            users.setdefault(key, []).append((label, k))

    corners = layout.corners
    edges: dict[tuple[int, int], PiecewiseBezier] = {}
    edge_errors: dict[tuple[int, int], float] = {}
    for key, who in users.items():
        lo, hi = corners[key[0]], corners[key[1]]
        label, k = who[0]
        region = regions[label]
        forward = loop_ids[label][k] == key[0]
        own = region.sides[k] if forward else region.sides[k].reversed()
        fitted = None
        pair = (min(who[0][0], who[-1][0]), max(who[0][0], who[-1][0]))
        if len(who) >= 2 and pair in layout.borders:
            # Shared edge: one fit from both segments' border band.
            tol = tolerance
            if tol is None:
                tol = max(regions[u].tolerance for u, _ in who)
            fitted = _fit_edge(
                own, layout.borders[pair], lo, hi, tol, EDGE_BAND * layout.radius,
                EDGE_BIN * layout.spacing, EDGE_END * layout.spacing,
            )
        if fitted is None:
            # Open edge (or a band too thin to fit): the segment's own boundary-loop run.
            run = _side_run(region, k)
            run = run if forward else run[::-1]
            tol = region.tolerance if tolerance is None else tolerance
            fitted = fit_side(run, tol, lo, hi)
        edges[key], edge_errors[key] = _dyadic_breaks(fitted[0]), fitted[1]
    timings["edges"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    patches: dict[int, Patch] = {}
    for label, ids in loop_ids.items():
        c = len(ids)
        sides: list[PiecewiseBezier] = []
        for k in range(c):
            a, b = ids[k], ids[(k + 1) % c]
            curve = edges[(min(a, b), max(a, b))]
            sides.append(curve if a < b else curve.reversed())
        boundary = dataclasses.replace(regions[label], sides=tuple(sides))
        patches[label] = fit_patch(seg_points[label], continuity="c0", m=m, n=n, boundary=boundary)
    timings["patches"] = time.perf_counter() - t0

    # Step 4: B-splines, faces, sewing.
    t0 = time.perf_counter()
    cad_tol = float(cad_tolerance) if cad_tolerance is not None else CAD_TOLERANCE * diagonal
    surfaces = {
        label: patch_to_bspline(p.base, p.deformation, cad_tol) for label, p in patches.items()
    }
    order = sorted(surfaces)
    faces = [make_face(surfaces[label]) for label in order]
    shape, info = sew(faces, tolerance=SEW_TOLERANCE * diagonal)
    timings["cad"] = time.perf_counter() - t0
    return Reconstruction(
        shape=shape,
        patches=patches,
        surfaces=surfaces,
        faces=faces,
        labels=order,
        sew_info=info,
        layout=layout,
        edges=edges,
        corners=corners,
        edge_errors=edge_errors,
        diagonal=diagonal,
        timings=timings,
    )
