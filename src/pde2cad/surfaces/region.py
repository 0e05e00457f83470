"""Boundary and corners of one segmented region of a point cloud (thesis Sections 5.2.1-5.2.2).

Pipeline (Fig. 5.1(c)-(d)):

1. Project the region's points onto their PCA plane (centroid + two main axes). The region must
   be *projectable*: a height field over that plane. A region that folds over itself overlaps
   in the projection; where its alpha shape then pinches or falls apart,
   :func:`boundary_loop` raises an :class:`~pde2cad.errors.InputError` saying so. A fold whose
   projection is still one simple shape is not detected: split such regions first.
2. Alpha shape of the projected points (Edelsbrunner): Delaunay triangles with circumradius
   below ``alpha``; edges used by exactly one kept triangle form the boundary, chained into
   one counter-clockwise loop (:func:`boundary_loop`).
3. Corners: the 4 (or 3) loop points of highest discrete curvature ``k = 4S/(abc)``
   (Fig. 5.2, :func:`corner_curvature`) with non-maximum suppression so two corners are never
   side by side (:func:`detect_region_corners`). A detected corner is then placed where its
   two sides meet (:func:`refine_corners`): the tip of an unordered cloud's corner lies
   beyond its nearest sample.
4. Sides: the loop points between consecutive corners, in 3D, fitted by the Chapter 3 chain
   fitter (:func:`pde2cad.curves.piecewise.fit_chain`) with the corners as exact end points.

Side-order contract of :class:`RegionBoundary`
---------------------------------------------
The loop runs counter-clockwise in the projection frame ``(u, v)``, whose axes with the plane
normal ``axes[2]`` form a right-handed frame. Corner 0 is the detected corner with the
smallest ``u + v`` (the "bottom-left" one), or the caller's first corner. Side ``k`` runs from
corner ``k`` to corner ``k + 1`` (the last back to corner 0), so for four corners
``BilinearCoons.from_loop(*sides)`` gives a patch with ``S(0, 0)`` at corner 0 and unit normal
``S_u x S_v`` pointing along ``axes[2]``; for three corners use ``three_sided(*sides)`` (the
apex ``S(., 1)`` is corner 2).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import maximum_filter, maximum_filter1d, median_filter, minimum_filter1d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay, QhullError, cKDTree

from pde2cad.curves.piecewise import denoise, fit_chain
from pde2cad.errors import FitError, InputError
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.columns import (
    centred_columns,
    column_max,
    column_min,
    scatter_matrix,
    unique_rows,
)
from pde2cad.surfaces.rim import (
    DENSITY_RANK,
    NOISE_DEPTH,
    RIM_DEPTH,
    RimEstimate,
    fit_rim_spline,
    locate_rim,
    onto_surface,
    sample_spacing,
    surface_normal,
)

#: Fewest points a region may have (a boundary loop and four sides need a few each).
MIN_POINTS = 10
#: Default alpha = ALPHA_FACTOR * median nearest-neighbour distance. For uniformly random
#: samples (median NN distance ~0.47 s, s = sqrt(area / N)) this is ~2.3 s, where the Poisson-
#: Delaunay circumradius tail P(R > r) = (1 + pi r^2/s^2) exp(-pi r^2/s^2) is ~1e-6: no sampling
#: gaps open inside the region. On a regular grid of spacing h it is 5 h.
ALPHA_FACTOR = 5.0
#: A default alpha that leaves the loop pinched, split or full of small gaps grows by this
#: factor up to ALPHA_RETRIES times (re-thresholding the same triangulation: cheap).
ALPHA_GROWTH = 1.5
ALPHA_RETRIES = 4
#: Holes smaller than HOLE_AREA * alpha0^2 are sampling gaps (alpha too small); larger ones
#: are real holes of the region and are ignored (only the outer loop matters).
HOLE_AREA = 10.0
#: Pieces split off the main region with less than this share of its area are outlier
#: clusters and are dropped; bigger ones mean the region falls apart at this alpha.
ISLAND_SHARE = 0.01
#: Above this many points the alpha shape is computed on a band of grid cells near empty space
#: (see :func:`_band`: exact, the interior does not change the boundary; the band holds
#: ~20-30 % of a dense region's points, and Delaunay costs ~8 us per point).
BAND_POINTS = 20_000
#: The band's grid cells are alpha / BAND_CELL_SPLIT wide; it may have at most BAND_CELLS
#: cells per point (else: full triangulation).
BAND_CELL_SPLIT = 10
BAND_CELLS = 200
#: Regions with more than 2 x SAMPLE_POINTS points (and no alpha given) get their loop from
#: the alpha shape of a random subsample of SAMPLE_POINTS, refined against the full-resolution
#: points near it (:func:`sampled_loop`): the loop then costs about the same for 1e5 or 1e7
#: points (1e6 points: 0.15 s instead of 3.3 s for the exact band triangulation).
SAMPLE_POINTS = 30_000
#: Width of the refinement bins along the coarse loop, in full-resolution nearest-neighbour
#: distances (see :func:`refine_loop`).
REFINE_BIN = 2.0
# Bins between a winner and the other normals its exposure test tries (see refine_loop).
_TILT = 3
#: Unused since the band is exact (it was the coarse-loop sample size); kept so code that
#: sets it keeps working.
COARSE_POINTS = 50_000
#: A curvature peak is "clearly a corner" when the boundary turns by at least this many
#: degrees over +-step (a 90-degree corner turns 90, a disc of 48 steps ~15 plus noise).
CORNER_ANGLE = 40.0
#: Default minimum spacing of two corners along the loop: perimeter / CORNER_SPACING.
#: Sides shorter than that (aspect ratio beyond ~7:1) need ``corners=``.
CORNER_SPACING = 16
#: Detected corners are re-placed where the two sides meet, each side's tangent line taken
#: from a quadratic fit over perimeter / REFINE_SPAN of arc length (see refine_corners).
REFINE_SPAN = 16
#: Default tolerance of the side fits: NOISE_FACTOR * RMS distance of the loop points to a
#: smoothed copy of their side, at least TOLERANCE_FLOOR * bounding-box diagonal.
NOISE_FACTOR = 3.0
TOLERANCE_FLOOR = 1e-4
#: Width of the band of points the rim estimate gets, in mean sample spacings (it reaches
#: RIM_BAND / 2 .. 3 RIM_BAND / 2 from the loop; the windows reach RIM_DEPTH = 4 spacings or
#: NOISE_DEPTH = 4 noise sigmas, plus 2 spacings; deeper windows get a wider band, see
#: _relocate_rims).
RIM_BAND = 20.0
#: Loop points within this RMS distance (in sample spacings) of their fitted side are a
#: sampled rim (structured data), whose sides stay on them (see _sampled_rim).
SAMPLED_LOOP = 0.05
#: A side is sparser than the band where its spacing estimate exceeds the band's by this.
SPARSE_SIDE = 1.2
#: Fewest rim stations, spread over half the side, whose line may move corners (_covers).
COVER_STATIONS = 6
#: Newton rounds of the side fits: boundary points are smooth samples, more rounds help.
SIDE_ROUNDS = 10


@dataclass(frozen=True)
class RegionBoundary:
    """The boundary of one region: an ordered loop, 3 or 4 corners and the fitted sides.

    Attributes
    ----------
    loop : (n, 3) float
        Boundary points in loop order (closed implicitly), counter-clockwise in the projection
        frame, starting at corner 0.
    loop_index : (n,) int
        Row of each loop point in the input ``points``.
    corners : (c,) int
        Indices into ``loop`` of the ``c`` in {3, 4} corners (the loop point nearest each),
        increasing; ``corners[0] == 0``. The corner positions themselves are
        :attr:`corner_points`, which may lie slightly beyond the loop point (detected corners
        are refined, given coordinates are used as given).
    sides : tuple of c PiecewiseBezier
        Head-to-tail: ``sides[k]`` runs from corner ``k`` to corner ``k + 1`` (the last one
        back to corner 0). Consecutive sides share the identical corner point. Four sides feed
        ``BilinearCoons.from_loop(*sides)``, three ``three_sided(*sides)``.
    frame : (origin (3,), axes (3, 3))
        The projection: ``(u, v) = (p - origin) @ axes[:2].T``; ``axes`` rows are the PCA axes
        (right-handed), ``axes[2]`` is the plane normal and the patch normal.
    side_errors : (c,) float
        Largest distance from a side's boundary points to its curve (an upper bound: the
        distance to the curve point at each point's parameter).
    tolerance : float
        The tolerance the sides were fitted with.
    """

    loop: NDArray[np.float64]
    loop_index: NDArray[np.int64]
    corners: NDArray[np.int64]
    sides: tuple[PiecewiseBezier, ...]
    frame: tuple[NDArray[np.float64], NDArray[np.float64]]
    side_errors: NDArray[np.float64]
    tolerance: float

    @property
    def corner_points(self) -> NDArray[np.float64]:
        """Corner positions ``(c, 3)``: the start point of each side."""
        return np.stack([s.start for s in self.sides])


# --------------------------------------------------------------------------- input checks
def _as_points(points: ArrayLike, dim: int, what: str) -> NDArray[np.float64]:
    """``points`` as a finite ``(N, dim)`` float array with N >= MIN_POINTS, or InputError."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != dim:
        raise InputError(f"{what} must have shape (N, {dim}), got {pts.shape}")
    if len(pts) < MIN_POINTS:
        raise InputError(
            f"{what} has {len(pts)} points; a region needs at least {MIN_POINTS} to have a "
            "boundary with corners — pass the whole segmented region"
        )
    if not np.isfinite(pts).all():
        bad = int((~np.isfinite(pts)).any(axis=1).sum())
        raise InputError(f"{what} contains NaN or inf in {bad} rows; remove those rows first")
    return pts


def pca_frame(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centroid and PCA axes of ``points`` (N, 3).

    Returns
    -------
    origin : (3,) float
    axes : (3, 3) float
        Rows: the main axis, the second axis and their cross product (the plane normal), so
        the frame is right-handed. Signs are fixed (largest component of each of the first two
        axes positive) so the result does not depend on the eigen-solver.

    Raises
    ------
    InputError
        If the points are (nearly) collinear or coincident.
    """
    origin, centred = centred_columns(points)
    return origin, _pca_axes(centred)


def _pca_axes(centred: NDArray[np.float64]) -> NDArray[np.float64]:
    """The axes of :func:`pca_frame` from the centred points, coordinate-major (3, N)."""
    # 3x3 covariance + eigh rather than an SVD of the (N, 3) data: same axes, far cheaper.
    cov = scatter_matrix(centred) / centred.shape[1]
    values, vectors = np.linalg.eigh(cov)
    values, vectors = values[::-1], vectors[:, ::-1]
    if not values[0] > 0 or values[1] <= 1e-12 * values[0]:
        raise InputError(
            "the points are collinear or coincident, so they span no surface region; "
            "pass the points of a 2D region (a patch), not of a curve"
        )
    axes = vectors[:, :2].T.copy()
    flip = np.sign(axes[np.arange(2), np.abs(axes).argmax(axis=1)])
    axes *= flip[:, None]
    return np.vstack([axes, np.cross(axes[0], axes[1])])


# --------------------------------------------------------------------------- alpha shape
def default_alpha(points2d: NDArray[np.float64]) -> float:
    """``ALPHA_FACTOR`` times the median nearest-neighbour distance of ``points2d`` (N, 2).

    The median is taken over at most 20,000 query points (against all points), which is
    exact enough and keeps 10^6 points cheap. Duplicate points (distance 0) are skipped.
    """
    return ALPHA_FACTOR * _spacing(points2d, 20_000)


def _spacing(points2d: NDArray[np.float64], queries: int, tree: cKDTree | None = None) -> float:
    """Median distance to the nearest distinct neighbour (duplicates skipped) over at most
    ``queries`` strided query points, against all points (``tree``: theirs, if built)."""
    if tree is None:
        # An unbalanced tree builds ~2x faster; nearest distances are the same.
        tree = cKDTree(points2d, balanced_tree=False, compact_nodes=False)
    dist, _ = tree.query(points2d[:: max(1, len(points2d) // queries)], k=4, workers=-1)
    # First positive neighbour distance of each query point: duplicates give zeros.
    positive = np.where(dist[:, 1:] > 0, dist[:, 1:], np.inf).min(axis=1)
    positive = positive[np.isfinite(positive)]
    if not positive.size:
        raise InputError("all points coincide; a region needs distinct points")
    return float(np.median(positive))


def _triangulate(points2d: NDArray[np.float64]) -> NDArray[np.int64]:
    """Delaunay triangles ``(T, 3)`` of ``points2d``, every one counter-clockwise."""
    try:
        tri = Delaunay(points2d).simplices.astype(np.int64)
    except QhullError as exc:
        raise InputError(
            "the projected points are collinear or degenerate, so they have no 2D boundary; "
            f"pass the points of a surface region (qhull: {str(exc).splitlines()[0]})"
        ) from exc
    a, b, c = (points2d[tri[:, i]] for i in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tri[cross < 0] = tri[cross < 0][:, ::-1]
    return tri


def _circumradius(points2d: NDArray[np.float64], tri: NDArray[np.int64]) -> NDArray[np.float64]:
    """Circumradius ``R = abc / (4S)`` of each triangle (T,); inf for degenerate ones."""
    a, b, c = (points2d[tri[:, i]] for i in range(3))
    la = np.linalg.norm(b - c, axis=1)
    lb = np.linalg.norm(c - a, axis=1)
    lc = np.linalg.norm(a - b, axis=1)
    ab, ac = b - a, c - a
    area2 = np.abs(ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = la * lb * lc / (2.0 * area2)
    return np.where(area2 > 0, radius, np.inf)


def _order_cycle(nxt: NDArray[np.int64]) -> NDArray[np.int64]:
    """Order of the vertices of one cycle given by the successor map ``nxt`` (m,).

    List ranking by pointer jumping (Wyllie): the cycle is cut before vertex 0, then every
    vertex learns its distance to the cut end in log2(m) vectorized doubling steps.
    """
    m = len(nxt)
    succ = nxt.copy()
    dist = np.ones(m, dtype=np.int64)
    last = int(np.flatnonzero(nxt == 0)[0])
    succ[last] = last
    dist[last] = 0
    for _ in range(int(np.ceil(np.log2(max(m, 2)))) + 1):
        dist = dist + dist[succ]
        succ = succ[succ]
    return np.argsort(-dist, kind="stable")


def _outer_loop(
    points2d: NDArray[np.float64],
    tri: NDArray[np.int64],
    hole_area: float,
    keep: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.int64] | None, str | None]:
    """The outer boundary loop of the union of triangles ``tri`` (counter-clockwise).

    ``keep`` (optional, per point): only boundary edges with both ends kept count (the band
    of :func:`_band`, whose other boundary edges are artefacts of the cut).

    Returns ``(loop, None)``, or ``(None, problem)`` naming why there is no simple loop.
    """
    empty = None, "no Delaunay triangle is smaller than alpha"
    if len(tri) == 0:
        return empty
    n = len(points2d)
    # Directed edges of the CCW triangles; an edge used once (either direction) is boundary,
    # and keeps the direction of its only triangle, so the outer loop runs CCW.
    edges = tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.minimum(edges[:, 0], edges[:, 1]) * n + np.maximum(edges[:, 0], edges[:, 1])
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    bnd = edges[counts[inverse.reshape(-1)] == 1]
    if keep is not None:
        bnd = bnd[keep[bnd[:, 0]] & keep[bnd[:, 1]]]
        if not len(bnd):
            return empty
    verts, local = np.unique(bnd, return_inverse=True)
    local = local.reshape(-1, 2)
    m = len(verts)
    graph = coo_matrix((np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(m, m))
    n_comp, label = connected_components(graph, directed=False)
    src, dst = points2d[verts[local[:, 0]]], points2d[verts[local[:, 1]]]
    # Shoelace per component: the sum over its directed edges of the cross products. Outer
    # loops come out positive (CCW), holes negative.
    cross = 0.5 * (src[:, 0] * dst[:, 1] - dst[:, 0] * src[:, 1])
    area = np.bincount(label[local[:, 0]], weights=cross, minlength=n_comp)
    outer = int(area.argmax())
    out_degree = np.bincount(local[:, 0], minlength=m)
    in_outer = label == outer
    pinches = int((out_degree[in_outer] != 1).sum())
    if pinches:
        return None, (
            f"the boundary pinches at {pinches} point(s) (the region touches itself in the "
            "projection, e.g. it folds over itself or is sampled too sparsely there)"
        )
    islands = np.flatnonzero((area > ISLAND_SHARE * area[outer]) & (np.arange(n_comp) != outer))
    if len(islands):
        return None, (
            f"the region falls apart into {len(islands) + 1} pieces (sampling gaps wider than "
            "alpha, or several regions passed as one)"
        )
    gaps = int(((area < 0) & (-area < hole_area)).sum())
    if gaps:
        return None, f"{gaps} small hole(s) open inside the region (sampling gaps wider than alpha)"
    # Successor map of the outer loop (out-degree 1 everywhere, so it is one cycle).
    rows = np.flatnonzero(in_outer[local[:, 0]])
    outer_verts = np.flatnonzero(in_outer)
    position = np.full(m, -1, dtype=np.int64)
    position[outer_verts] = np.arange(len(outer_verts))
    nxt = np.empty(len(outer_verts), dtype=np.int64)
    nxt[position[local[rows, 0]]] = position[local[rows, 1]]
    order = _order_cycle(nxt)
    return verts[outer_verts[order]], None


def _band(
    points2d: NDArray[np.float64], alpha: float
) -> tuple[NDArray[np.int64], NDArray[np.bool_]] | None:
    """Points whose alpha shape (circumradius ``< alpha``) has the same boundary edges.

    Returns ``(rows, keep)``: sorted indices of the band points and, per band point, whether
    it may be a boundary vertex; None if the grid would be too large (sparse, spread-out
    points): then triangulate everything.

    Why it is exact. A boundary edge borders a triangle with circumradius >= alpha (or the
    convex hull), whose open circumdisc holds no point, so both its ends touch an empty open
    disc D of radius alpha. D contains a square of side sqrt(2) alpha, so on a grid of cells
    h = alpha / BAND_CELL_SPLIT it contains a whole block of b x b cells (b = floor(split x
    sqrt(2)) - 1), and that block lies within L = ceil((1 + 1/sqrt(2)) split) + 1 cells of the
    point's own cell (one cell more for rounding). A point is ``keep`` unless every such block
    holds a point. A kept triangle at a boundary vertex p has a circumdisc of radius < alpha
    through p, so it and every point inside that disc lie within 2 alpha of p: with all points
    within ``2 split + 1`` cells of a ``keep`` point in the band, the band's Delaunay
    triangles at ``keep`` points are the full cloud's, and so are its boundary edges between
    ``keep`` points (the other boundary edges, along the inner cut of the band, are dropped by
    ``_outer_loop(..., keep=)``).
    """
    m = BAND_CELL_SPLIT
    h = alpha / m
    b = int(np.floor(m * np.sqrt(2.0))) - 1
    reach = int(np.ceil((1.0 + 1.0 / np.sqrt(2.0)) * m)) + 1
    lo = points2d.min(axis=0)
    ij = np.floor((points2d - lo) / h).astype(np.int64)
    dims = ij.max(axis=0) + 1
    if float(dims[0]) * float(dims[1]) > BAND_CELLS * len(points2d):
        return None
    occupied = np.zeros(tuple(dims), dtype=bool)
    occupied[ij[:, 0], ij[:, 1]] = True
    # Outside the grid is empty (cval=False): blocks reaching out of it count as empty.
    block = occupied  # block[j] = any point in cells j .. j + b - 1 (per axis)
    for axis in (0, 1):
        block = maximum_filter1d(block, b, axis, mode="constant", cval=False, origin=-(b // 2))
    # solid[i] = every block starting in i - reach .. i + reach - b + 1 holds a point.
    width = 2 * reach - b + 2
    solid = block
    for axis in (0, 1):
        solid = minimum_filter1d(
            solid, width, axis, mode="constant", cval=False, origin=reach - width // 2
        )
    candidate = ~solid
    grow = 2 * (2 * m + 1) + 1
    band = maximum_filter(candidate, size=grow, mode="constant", cval=False)
    rows = np.flatnonzero(band[ij[:, 0], ij[:, 1]])
    return rows, candidate[ij[rows, 0], ij[rows, 1]]


def boundary_loop(
    points2d: ArrayLike, alpha: float | None = None, *, retry: bool | None = None
) -> NDArray[np.int64]:
    """Ordered outer boundary of the alpha shape of 2D points (Section 5.2.1).

    Delaunay triangles with circumradius ``< alpha`` are kept; edges used by exactly one kept
    triangle are boundary edges; they are chained (vectorized list ranking) into loops and the
    outer one (largest area) is returned.

    Parameters
    ----------
    points2d : (N, 2) float, N >= 10
    alpha : float, optional
        Circumradius threshold (the alpha-disc radius), in the points' units. Default
        :func:`default_alpha` (5 x the median nearest-neighbour distance). Larger values bridge
        concavities narrower than ~2 alpha; smaller ones open gaps in sparse parts.
    retry : bool, optional
        Grow alpha by ALPHA_GROWTH (up to ALPHA_RETRIES times) while the loop pinches, splits
        or has small holes. Default: only when ``alpha`` was not given.

    Returns
    -------
    (n,) int
        Indices into ``points2d`` of the loop, counter-clockwise, closed implicitly.

    Raises
    ------
    InputError
        On bad input, or if no alpha gives one simple loop (the message names the problem).

    Notes
    -----
    Holes larger than ``HOLE_AREA * alpha^2`` (real holes of the region) are ignored, and so
    are pieces split off with under 1 % of the area (outlier clusters). Above BAND_POINTS
    points the triangulation is restricted to the points near empty grid cells (see
    :func:`_band`); the returned loop and any error are the same.
    """
    pts = _as_points(points2d, 2, "points2d")
    if alpha is not None and not (np.isfinite(alpha) and alpha > 0):
        raise InputError(f"alpha must be a positive number, got {alpha}")
    grow = alpha is None if retry is None else retry
    return _alpha_loop(pts, alpha, grow)[0]


def _alpha_loop(
    pts: NDArray[np.float64], alpha: float | None, grow: bool
) -> tuple[NDArray[np.int64], float]:
    """:func:`boundary_loop` on checked points; also returns the alpha that gave the loop."""
    alpha0 = default_alpha(pts) if alpha is None else float(alpha)
    whole = None  # (triangles, circumradii) of all points, computed at most once
    problem: str | None = ""
    for attempt in range(ALPHA_RETRIES + 1 if grow else 1):
        a = alpha0 * ALPHA_GROWTH**attempt
        band = _band(pts, a) if len(pts) > BAND_POINTS else None
        if band is not None:
            rows, keep = band
            sub = pts[rows]
            tri = _triangulate(sub)
            tri = tri[_circumradius(sub, tri) < a]
        else:
            if whole is None:
                tri = _triangulate(pts)
                whole = tri, _circumradius(pts, tri)
            rows, keep, sub = np.arange(len(pts)), None, pts
            tri = whole[0][whole[1] < a]
        loop, problem = _outer_loop(sub, tri, HOLE_AREA * alpha0**2, keep)
        if loop is not None:
            return rows[loop], a
    tried = f"alpha {alpha0:.4g} .. {a:.4g}" if grow else f"alpha {alpha0:.4g}"
    raise InputError(
        f"no single boundary loop with {tried}: {problem}. The region must be a height field "
        "over its PCA plane, without overlaps; split a folded region, or pass a larger alpha"
    )


# --------------------------------------------------------------------------- large regions
def sampled_loop(points2d: NDArray[np.float64], seed: int = 0) -> NDArray[np.int64]:
    """Boundary loop of a large region: alpha shape of a subsample, refined at full resolution.

    1. A random subsample of about ``SAMPLE_POINTS`` points (random rather than strided, so
       an ordered scan cannot alias; a fixed ``seed``, so a cloud always gives the same loop).
    2. Its alpha-shape loop, exactly as :func:`boundary_loop` finds it (same alpha growth and
       the same errors for pinched, split or gapped regions, now judged at the subsample's
       resolution).
    3. :func:`refine_loop`: the outermost full-resolution points along that loop.

    Parameters
    ----------
    points2d : (N, 2) float
        Checked points (finite, N >= 10).
    seed : int

    Returns
    -------
    (n,) int
        Indices into ``points2d`` of the refined loop, counter-clockwise.
    """
    n = len(points2d)
    sample = np.unique(np.random.default_rng(seed).integers(0, n, SAMPLE_POINTS))
    rows, alpha = _alpha_loop(points2d[sample], None, True)
    return refine_loop(points2d, sample[rows], alpha)


def _near_cells(
    points2d: NDArray[np.float64], path: NDArray[np.float64], cell: float, reach: int
) -> NDArray[np.int64]:
    """Rows of the points in grid cells (side ``cell``) within ``reach`` cells of a cell that
    ``path`` (m, 2), sampled at most half a cell apart, passes through: one binning of the
    points, no distance search. The grid spans the path's box and reach + 1 cells more; a
    point beyond it is clipped onto its unmarked border."""
    lo = path.min(axis=0) - (reach + 1) * cell
    dims = np.floor((path.max(axis=0) + (reach + 1) * cell - lo) / cell).astype(np.int64) + 1
    marked = np.zeros(tuple(dims), dtype=bool)
    ij = np.clip(np.floor((path - lo) / cell).astype(np.int64), 0, dims - 1)
    marked[ij[:, 0], ij[:, 1]] = True
    marked = maximum_filter(marked, size=2 * reach + 1, mode="constant", cval=False)
    scaled = (points2d - lo) * (1.0 / cell)
    i = np.clip(scaled[:, 0], 0, dims[0] - 1).astype(np.int64)
    j = np.clip(scaled[:, 1], 0, dims[1] - 1).astype(np.int64)
    return np.flatnonzero(marked.reshape(-1)[i * dims[1] + j])


def refine_loop(
    points2d: NDArray[np.float64], coarse: NDArray[np.int64], alpha: float
) -> NDArray[np.int64]:
    """The outermost full-resolution points along a coarse boundary loop (CCW).

    1. Candidates: the points within about ``alpha`` (the coarse loop's alpha: no point of
       the region lies farther beyond the coarse loop) of the coarse loop, by grid binning.
    2. Spacing ``s``: median nearest-neighbour distance of the candidates, scaled along the
       loop by the local length of the coarse loop's edges (which follows the density);
       bins of ``REFINE_BIN * s`` of arc length along the coarse loop.
    3. Each candidate goes to the bin of its nearest bin centre (a KD-tree over the few
       thousand centres only), with its offset along the loop's outward normal there; each
       bin keeps its outermost candidate.
    4. Dents: a winner is dropped where the disc of the full-resolution alpha
       (``ALPHA_FACTOR * s``) resting on it from straight outside holds a neighbouring
       winner (the alpha shape would not reach it either); the rest in arc order.

    Parameters
    ----------
    points2d : (N, 2) float
    coarse : (m,) int
        Rows of ``points2d`` forming the coarse loop, counter-clockwise.
    alpha : float
        The alpha of the coarse loop.

    Returns
    -------
    (n,) int
        Rows of ``points2d``, counter-clockwise, closed implicitly.
    """
    ring = points2d[coarse]
    path, _ = _resample(ring, max(len(ring), int(np.ceil(_perimeter(ring) / (0.25 * alpha)))))
    rows = _near_cells(points2d, path, 0.5 * alpha, 2)
    cand = points2d[rows]
    tree = cKDTree(cand, balanced_tree=False, compact_nodes=False)
    width = REFINE_BIN * _spacing(cand, 5_000, tree)
    centres, arc, scale = _bins(ring, width)
    # Tangents over +-2 bins: smooth across the coarse loop's vertices.
    tangent = np.roll(centres, -2, axis=0) - np.roll(centres, 2, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1), 1e-300)[:, None]
    outward = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    _, near = cKDTree(centres).query(cand, workers=-1)
    rel = cand - centres[near]
    offset = np.einsum("ij,ij->i", rel, outward[near])
    order = np.lexsort((offset, near))
    last = np.r_[near[order][1:] != near[order][:-1], True]
    win = order[last]  # outermost candidate of every non-empty bin
    perimeter = _perimeter(ring)
    along = (arc[near[win]] + np.einsum("ij,ij->i", rel[win], tangent[near[win]])) % perimeter
    # Never a smaller disc than the alpha of the median spacing: the edge lengths that
    # scale the bins are noisy, and a small disc finds empty room too easily.
    radius = (ALPHA_FACTOR / REFINE_BIN) * np.maximum(scale[near[win]], width)
    # Discs rest on a winner from its bin's outward normal and from those a few bins to
    # either side (so a corner's tip and the sides next to it stay).
    bins = near[win][:, None] + np.array([0, -_TILT, _TILT])
    keep = _exposed(tree, cand[win], outward[bins % len(centres)], radius)
    win, along = win[keep], along[keep]
    # In arc order: the winners of neighbouring bins may lie the other way round.
    return rows[win[np.argsort(along, kind="stable")]]


def _bins(
    ring: NDArray[np.float64], width: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Bin centres along a closed loop (n, 2), ``width`` apart where its edges have their
    median length and proportionally wider where they are longer (sparser points).

    Returns the centres (b, 2), their arc positions (b,) and the bin widths there (b,).
    """
    edge = np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1)
    local = median_filter(edge, size=min(15, len(edge)), mode="wrap")
    local = np.maximum(local, 1e-3 * float(np.median(local)))
    step = width * local / float(np.median(local))  # bin width along each edge
    arc = np.r_[0.0, np.cumsum(edge)]
    total = np.r_[0.0, np.cumsum(edge / step)]  # bins passed at each vertex
    count = max(len(ring), int(np.ceil(total[-1])))
    at = np.interp(np.arange(count) * (total[-1] / count), total, arc)
    closed = np.vstack([ring, ring[:1]])
    centres = np.stack([np.interp(at, arc, closed[:, d]) for d in range(2)], axis=1)
    piece = np.clip(np.searchsorted(arc, at, side="right") - 1, 0, len(edge) - 1)
    return centres, at, step[piece]


def _perimeter(ring: NDArray[np.float64]) -> float:
    return float(np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1).sum())


def _exposed(
    tree: cKDTree,
    ring: NDArray[np.float64],
    normals: NDArray[np.float64],
    radius: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Which points ``ring`` (n, 2) some disc of ``radius`` (n,) touching them from outside
    along one of their ``normals`` (n, k, 2) keeps free of every point in ``tree``: the
    alpha shape's test for a boundary vertex, over k directions instead of all."""
    centres = ring[:, None, :] + radius[:, None, None] * normals  # (n, k, 2)
    dist, _ = tree.query(centres.reshape(-1, 2))
    free = dist.reshape(normals.shape[:2]) >= (1.0 - 1e-6) * radius[:, None]
    return free.any(axis=1)


# --------------------------------------------------------------------------- corners
def _turning(
    loop: NDArray[np.float64], step: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Chords ``p[i] - p[i-step]`` and ``p[i+step] - p[i]`` of a closed loop, and the
    chord ``p[i+step] - p[i-step]``."""
    back = np.roll(loop, step, axis=0)
    ahead = np.roll(loop, -step, axis=0)
    return loop - back, ahead - loop, ahead - back


def _turning_angle(loop: NDArray[np.float64], step: int) -> NDArray[np.float64]:
    """Turning angle (degrees, 0..180) of a closed 2D loop at every point over +-step."""
    ab, bc, _ = _turning(loop, step)
    cross = ab[:, 0] * bc[:, 1] - ab[:, 1] * bc[:, 0]
    return np.degrees(np.arctan2(np.abs(cross), np.einsum("ij,ij->i", ab, bc)))


def corner_curvature(loop: ArrayLike, step: int) -> NDArray[np.float64]:
    """Discrete curvature ``k = 4S / (abc)`` at every point of a closed loop (Fig. 5.2).

    ``S`` is the area of the triangle ``(p[i-step], p[i], p[i+step])`` and ``a, b, c`` its side
    lengths: ``k`` is the inverse radius of the circle through the three points.

    Parameters
    ----------
    loop : (n, D) float
        Closed implicitly.
    step : int
        Index offset of the two neighbours (>= 1): the scale the curvature is measured at.

    Returns
    -------
    (n,) float
        For D = 2 signed by the turning direction (positive = left turn, i.e. convex on a
        counter-clockwise loop); unsigned otherwise. 0 where two of the points coincide.
    """
    pts = np.asarray(loop, dtype=float)
    if pts.ndim != 2 or len(pts) < 3:
        raise InputError(f"loop must have shape (n, D) with n >= 3, got {pts.shape}")
    if not 1 <= step < len(pts):
        raise InputError(f"step must be in 1..{len(pts) - 1}, got {step}")
    ab, bc, ac = _turning(pts, int(step))
    if pts.shape[1] == 2:
        area2 = ab[:, 0] * bc[:, 1] - ab[:, 1] * bc[:, 0]
    else:
        # |ab x bc| from Lagrange's identity: works in any dimension.
        dot = np.einsum("ij,ij->i", ab, bc)
        square = np.einsum("ij,ij->i", ab, ab) * np.einsum("ij,ij->i", bc, bc) - dot**2
        area2 = np.sqrt(np.maximum(square, 0.0))
    lengths = np.linalg.norm(ab, axis=1) * np.linalg.norm(bc, axis=1) * np.linalg.norm(ac, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = 2.0 * area2 / lengths  # 4S / (abc) with S = area2 / 2
    return np.where(lengths > 0, k, 0.0)


def _resample(
    loop: NDArray[np.float64], count: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``count`` points equally spaced by arc length around a closed loop (n, D).

    Returns the points (count, D) and the arc position of every loop vertex (n,).
    """
    closed = np.vstack([loop, loop[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    perimeter = arc[-1]
    s = np.arange(count) * (perimeter / count)
    out = np.stack([np.interp(s, arc, closed[:, d]) for d in range(loop.shape[1])], axis=1)
    return out, arc[:-1]


def _peaks(score: NDArray[np.float64], radius: int) -> NDArray[np.int64]:
    """Indices of cyclic local maxima of ``score`` (> 0), at least ``radius`` apart, strongest
    first (non-maximum suppression)."""
    m = len(score)
    window = min(2 * radius + 1, m if m % 2 else m - 1)
    top = maximum_filter1d(score, size=window, mode="wrap")
    local = np.flatnonzero((score > 0) & (score >= top))
    local = local[np.argsort(-score[local], kind="stable")]
    chosen: list[int] = []
    # Greedy suppression over the local maxima only (a handful; plateaus give ties).
    for i in local:
        if all(min(abs(i - j), m - abs(i - j)) >= radius for j in chosen):
            chosen.append(int(i))
    return np.asarray(chosen, dtype=np.int64)


def detect_region_corners(
    loop2d: ArrayLike,
    count: int | None = None,
    min_spacing: float | None = None,
    *,
    angle: float = CORNER_ANGLE,
) -> NDArray[np.int64]:
    """Corners of a region's boundary loop: the points of highest curvature (Section 5.2.1).

    The loop is resampled evenly by arc length and ``k = 4S/(abc)`` (:func:`corner_curvature`)
    is measured over ``+-step`` with ``step`` ~ perimeter / 48 (at least 4 loop edges, so the
    jitter of alpha-shape boundaries averages out). Peaks closer than ``min_spacing`` along the
    loop are suppressed in favour of the stronger one. Each chosen peak is moved to the loop
    vertex nearby that sticks out farthest (the sharp tip, not a point beside it).

    Parameters
    ----------
    loop2d : (n, 2) float
        The boundary loop (either orientation; convex means turning like the loop does).
    count : {3, 4, None}
        ``None``: the peaks that turn by at least ``angle`` degrees, over both ``+-step`` and
        ``+-2 step``, are the corners (so 4 when the 4th peak is clearly a corner, 3 when it
        is a smooth bend or noise); there must be 3 or 4 and all convex. ``3`` or ``4``: the ``count`` strongest convex peaks,
        however weak (a forced choice: e.g. 4 of the 5 convex corners of an L-shape, whose
        notch then lies inside a side).
    min_spacing : float, optional
        Least arc length between two corners; default perimeter / 16.
    angle : float
        Turning angle (degrees) from which a peak counts as a corner when ``count`` is None.

    Returns
    -------
    (c,) int
        Indices into ``loop2d``, increasing.

    Raises
    ------
    InputError
        With ``count=None`` if the number of clear corners is not 3 or 4, or a clear corner is
        concave (a Coons patch cannot have a reflex corner); with a ``count`` if fewer convex
        peaks exist.
    """
    loop = np.asarray(loop2d, dtype=float)
    if loop.ndim != 2 or loop.shape[1] != 2 or len(loop) < 6:
        raise InputError(f"loop2d must have shape (n, 2) with n >= 6, got {loop.shape}")
    if not np.isfinite(loop).all():
        raise InputError("loop2d contains NaN or inf; remove those points")
    if count is not None and count not in (3, 4):
        raise InputError(f"count must be 3, 4 or None, got {count}")
    after = np.roll(loop, -1, axis=0)
    edges = np.linalg.norm(after - loop, axis=1)
    perimeter = float(edges.sum())
    shoelace = float(np.sum(loop[:, 0] * after[:, 1] - after[:, 0] * loop[:, 1]))
    if not perimeter > 0 or shoelace == 0:
        raise InputError("the boundary loop encloses no area; pass the loop of a 2D region")
    orientation = 1.0 if shoelace > 0 else -1.0
    spacing = perimeter / CORNER_SPACING if min_spacing is None else float(min_spacing)
    if not spacing > 0:
        raise InputError(f"min_spacing must be > 0, got {min_spacing}")
    m = int(np.clip(2 * len(loop), 512, 4096))
    res, arc = _resample(loop, m)
    delta = perimeter / m
    step_len = min(max(perimeter / 48.0, 4.0 * float(np.median(edges))), 0.5 * spacing)
    step = int(np.clip(round(step_len / delta), 1, m // 4))
    k = orientation * corner_curvature(res, step)
    # Turning angle at the curvature's scale and at twice it: a corner between straight
    # sides turns as much at both, a smooth bend twice as much at 2 step, a noise wiggle
    # much less. The smaller of the two measures how clearly a peak is a corner.
    turn = np.minimum(_turning_angle(res, step), _turning_angle(res, min(2 * step, m // 4)))
    radius = max(1, int(round(spacing / delta)))
    convex = _peaks(np.where(k > 0, k, 0.0), radius)
    if count is None:
        concave = _peaks(np.where(k < 0, -k, 0.0), radius)
        sharp = convex[turn[convex] >= angle]
        reflex = concave[turn[concave] >= angle]
        total = len(sharp) + len(reflex)
        if total not in (3, 4) or len(reflex):
            detail = f" ({len(reflex)} concave)" if len(reflex) else ""
            hint = (
                "pass count=4 (or 3) to keep the sharpest convex ones, corners= explicitly, or "
                "split the region"
                if total > 4 or len(reflex)
                else "pass corners= explicitly (or count= to force the sharpest points)"
            )
            raise InputError(
                f"the region's boundary has {total} corners{detail} turning by at least "
                f"{angle:g} degrees; a patch needs 3 or 4 convex corners — {hint}"
            )
        picked = sharp
    else:
        if len(convex) < count:
            raise InputError(
                f"the region's boundary has only {len(convex)} convex curvature peaks at least "
                f"{spacing:.4g} apart; {count} corners were asked for — pass corners= "
                "explicitly or a smaller min_spacing"
            )
        picked = convex[:count]
    return np.sort(_snap(loop, arc, res, picked, step, delta, orientation))


def _snap(
    loop: NDArray[np.float64],
    arc: NDArray[np.float64],
    res: NDArray[np.float64],
    peaks: NDArray[np.int64],
    step: int,
    delta: float,
    orientation: float,
) -> NDArray[np.int64]:
    """Loop vertex of each resampled peak: among the vertices within +-step/2 of it (arc
    length), the one farthest outside the chord ``res[i-step] -> res[i+step]``."""
    m = len(res)
    perimeter = m * delta
    out = np.empty(len(peaks), dtype=np.int64)
    for j, i in enumerate(peaks):  # a loop over 3-4 corners
        centre = i * delta
        gap = np.abs((arc - centre + 0.5 * perimeter) % perimeter - 0.5 * perimeter)
        near = np.flatnonzero(gap <= 0.5 * step * delta)
        if not len(near):
            out[j] = int(gap.argmin())
            continue
        a, c = res[(i - step) % m], res[(i + step) % m]
        rel = loop[near] - a
        outside = -orientation * ((c[0] - a[0]) * rel[:, 1] - (c[1] - a[1]) * rel[:, 0])
        out[j] = int(near[outside.argmax()])
    return out


# --------------------------------------------------------------------------- sides
def refine_corners(
    loop: NDArray[np.float64], corners: NDArray[np.int64], reach: float, min_angle: float = 20.0
) -> NDArray[np.float64]:
    """Corner positions from the two sides that meet there, not from the nearest sample.

    The data rarely holds a point at a corner's tip: the corner of an unordered cloud lies
    about one sampling spacing beyond its nearest sample. Each side is fitted over the loop
    points within arc length ``reach`` of the corner (the corner vertex left out) by a line
    or, where that clearly fits better (a bent side with little noise: a line would be off by
    the sagitta), a quadratic in the arc length. Its value and slope at the corner give the
    side's tangent line there, and the corner is put midway between the closest points of the
    two tangent lines (skew in 3D). The vertex is kept where the sides meet at under
    ``min_angle`` degrees, where the estimate lands farther than ``reach / 2`` away or inside
    the region (a tip hidden beyond the samples lies outside), or where it moves by less than
    a tenth of the loop spacing (exact data with a sample at the tip: extrapolation would
    only add its own error).

    Parameters
    ----------
    loop : (n, D) float
        Closed loop.
    corners : (c,) int
        Corner indices into ``loop``, increasing.
    reach : float
        Arc length of each side used for its tangent line.

    Returns
    -------
    (c, D) float
    """
    seg = np.linalg.norm(np.roll(loop, -1, axis=0) - loop, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    perimeter = arc[-1]
    least_move = 0.1 * float(np.median(seg))
    out = loop[corners].astype(float)
    for j, c in enumerate(corners):  # 3-4 corners
        ahead = (arc[:-1] - arc[c]) % perimeter  # arc length from the corner, forwards
        behind = (arc[c] - arc[:-1]) % perimeter
        before, after = (_tangent_at_zero(loop, dist, reach) for dist in (behind, ahead))
        if before is None or after is None:
            continue
        estimate = _lines_meet(before, after, min_angle)
        if estimate is None:
            continue
        (_, d), (_, e) = before, after
        shift = estimate - loop[c]
        move = float(np.linalg.norm(shift))
        # d and e point from the corner into the sides, so d + e points into the region: a
        # tip hidden beyond the samples lies the other way.
        outward = float(shift @ (d + e)) < 0.0
        if outward and least_move <= move <= 0.5 * reach:
            out[j] = estimate
    return out


def _lines_meet(
    before: tuple[NDArray[np.float64], NDArray[np.float64]],
    after: tuple[NDArray[np.float64], NDArray[np.float64]],
    min_angle: float,
) -> NDArray[np.float64] | None:
    """Midpoint of the closest points of two lines ``(point, unit direction)`` (skew in 3D),
    or None where they meet at under ``min_angle`` degrees."""
    (p, d), (q, e) = before, after
    b = float(d @ e)
    if abs(b) > np.cos(np.radians(min_angle)):
        return None
    # Closest points p + s d and q + t e of the two lines (unit d, e): the normal
    # equations of min |w + s d - t e|^2 with w = p - q.
    w = p - q
    s = (b * float(e @ w) - float(d @ w)) / (1.0 - b * b)
    t = float(e @ w) + b * s
    return 0.5 * (p + s * d + q + t * e)


def _tangent_at_zero(
    loop: NDArray[np.float64], dist: NDArray[np.float64], reach: float, least_quadratic: int = 4
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Point and unit tangent at arc length 0 of the loop points with ``0 < dist <= reach``
    (line fit, or quadratic if it halves the RMS residual and there are ``least_quadratic``
    points); None with under 4 points."""
    inside = (dist > 0) & (dist <= reach)
    if inside.sum() < 4:
        return None
    x = dist[inside] / reach
    y = loop[inside]
    fits = []
    for degree in (1, 2):
        design = x[:, None] ** np.arange(degree + 1)[None, :]
        coef = np.linalg.lstsq(design, y, rcond=None)[0]
        fits.append((coef, float(np.sqrt(np.mean((design @ coef - y) ** 2)))))
    (line, line_rms), (quad, quad_rms) = fits
    coef = quad if quad_rms < 0.5 * line_rms and inside.sum() >= least_quadratic else line
    norm = float(np.linalg.norm(coef[1]))
    return None if norm == 0.0 else (coef[0], coef[1] / norm)


def _caller_corners(
    corners: ArrayLike, points: NDArray[np.float64], loop_index: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Map caller corners (indices into ``points`` or coordinates) to loop indices.

    Returns the loop indices in loop order starting with the caller's first corner, and the
    corner positions (the caller's coordinates, or the indexed points).
    """
    given = np.asarray(corners)
    if given.ndim == 1 and np.issubdtype(given.dtype, np.integer):
        if given.min(initial=0) < 0 or given.max(initial=0) >= len(points):
            raise InputError(
                f"corner indices must lie in 0..{len(points) - 1}, got {given.tolist()}"
            )
        position = points[given]
    elif given.ndim == 2 and given.shape[1] == 3:
        position = given.astype(float)
        if not np.isfinite(position).all():
            raise InputError("corners contain NaN or inf")
    else:
        raise InputError(
            f"corners must be (c,) int indices into points or (c, 3) coordinates, got an "
            f"array of shape {given.shape} and dtype {given.dtype}"
        )
    if len(position) not in (3, 4):
        raise InputError(f"{len(position)} corners were given; a patch needs 3 or 4")
    loop = points[loop_index]
    _, idx = cKDTree(loop).query(position)
    idx = np.asarray(idx, dtype=np.int64)
    if len(np.unique(idx)) != len(idx):
        raise InputError(
            "two of the given corners are nearest to the same boundary point; pass distinct "
            "corners on the region's boundary"
        )
    n = len(loop)
    # Loop order from the caller's first corner, in either direction.
    ahead = (idx - idx[0]) % n
    if np.all(np.diff(ahead) > 0):
        order = np.arange(len(idx))
    elif np.all(np.diff(ahead[np.r_[0, len(idx) - 1 : 0 : -1]]) > 0):
        order = np.r_[0, len(idx) - 1 : 0 : -1]
    else:
        raise InputError(
            "the given corners are not in order around the boundary (neither way round); "
            "list them as they follow each other along the region's edge"
        )
    return idx[order], position[order]


def _noise_tolerance(runs: list[NDArray[np.float64]], diagonal: float) -> float:
    """NOISE_FACTOR x RMS distance of the side points to a smoothed copy of their side (each
    smoothed on its own so corners do not blur), at least TOLERANCE_FLOOR x diagonal."""
    residuals = []
    for run in runs:
        window = int(min(31, max(5, len(run) // 4)))
        window -= 1 - window % 2
        if len(run) < 7:
            continue
        smooth, _ = denoise(run, closed=False, pos_window=window)
        residuals.append(np.linalg.norm(run - smooth, axis=1))
    rms = float(np.sqrt(np.mean(np.concatenate(residuals) ** 2))) if residuals else 0.0
    return max(NOISE_FACTOR * rms, TOLERANCE_FLOOR * diagonal)


def _rim_tolerance(runs: list[NDArray[np.float64]], diagonal: float) -> float:
    """Side-fit tolerance for rim points: the largest residual their noise is expected to
    leave, ``(sqrt(2 ln J) + 1) sigma`` for ``J`` points (the mean maximum of J Gaussian
    residuals, plus one sigma), at least TOLERANCE_FLOOR x diagonal.

    Rim points are averages of many samples, so their noise is small and nearly Gaussian;
    a tolerance below their largest noise residual would split a smooth side into pieces
    whose joints (curvature jumps) then show in the patch's interior. ``sigma`` is the RMS
    distance to a smoothed copy (:func:`_noise_tolerance` / NOISE_FACTOR).
    """
    sigma = _noise_tolerance(runs, 0.0) / NOISE_FACTOR
    count = max(sum(len(r) for r in runs), 2)
    return max((np.sqrt(2.0 * np.log(count)) + 1.0) * sigma, TOLERANCE_FLOOR * diagonal)


def fit_side(
    run: NDArray[np.float64], tolerance: float, start: NDArray[np.float64], end: NDArray[np.float64]
) -> tuple[PiecewiseBezier, float]:
    """Fit ordered points of one side between two fixed corners (G1 inside, Ch. 3 fitter).

    The corners are assigned after the fit so that sides meeting at a corner (and patches
    sharing an edge) hold bit-identical corner points.

    Returns
    -------
    (PiecewiseBezier, max_error)
    """
    smooth, tangent = denoise(run, closed=False)
    chain = fit_chain(
        run, tolerance, p_start=start, p_end=end, g1=True,
        param_points=smooth, join_tangents=tangent, rounds=SIDE_ROUNDS,
    )
    ctrl = chain.curves.copy()
    ctrl[0, 0], ctrl[-1, 3] = start, end
    return PiecewiseBezier.from_chain(ctrl), float(chain.max_error)


def _rim_corner(
    before: RimEstimate,
    after: RimEstimate,
    old: NDArray[np.float64],
    reach: float,
    normal: NDArray[np.float64] | None,
    least_move: float,
) -> NDArray[np.float64]:
    """Corner where the rims of two sides meet: their tangent lines (from the stations
    within ``reach`` of the corner, at least 4 each) extrapolated to where they cross.

    The stations are taken into the tangent plane through ``old`` (``normal``) first: the
    height of a curved surface would otherwise bend the lines (and pick quadratics that
    amplify the in-plane noise); the caller puts the corner back onto the surface. ``old`` is
    kept where the lines meet at under 20 degrees or cross farther than ``reach / 2`` from
    it, or closer than ``least_move`` (a sample at the tip, as on a grid: extrapolation would
    only add its own error).
    """
    lines = []
    for dist, est in ((before.length - before.arc, before), (after.arc, after)):
        span = max(reach, float(np.sort(dist)[min(3, len(dist) - 1)]))
        flat = est.points
        if normal is not None:
            flat = flat - np.outer((flat - old) @ normal, normal)
        # Noisy stations halve a line's RMS with a quadratic by chance (F(1, n - 3) > 3
        # (n - 3)): a third of the time for 4, ~1 % from 8, the least allowed here.
        lines.append(_tangent_at_zero(flat, dist, span, least_quadratic=8))
    if lines[0] is None or lines[1] is None:
        return old
    estimate = _lines_meet(lines[0], lines[1], 20.0)
    if estimate is None or not least_move <= np.linalg.norm(estimate - old) <= 0.5 * reach:
        return old
    return estimate


def _side_plane(
    run: NDArray[np.float64], tolerance: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """``(point, unit normal)`` of the plane the run lies in to ``tolerance``, or None.

    A straight run lies in many planes: None too (its side is made a line instead).
    """
    centre = run.mean(axis=0)
    _, vec = np.linalg.eigh((run - centre).T @ (run - centre))
    normal = vec[:, 0]
    if not _explained(np.abs((run - centre) @ normal), tolerance):
        return None
    if _explained(_off_chord(run, run[0], run[-1]), tolerance):
        return None
    return centre, normal


def _off_chord(
    run: NDArray[np.float64], start: NDArray[np.float64], end: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distances (n,) of ``run`` from the line through ``start`` and ``end``."""
    chord = end - start
    along = chord / max(float(np.linalg.norm(chord)), 1e-300)
    rel = run - start
    return np.linalg.norm(rel - np.outer(rel @ along, along), axis=1)


def _explained(distance: NDArray[np.float64], tolerance: float) -> bool:
    """Whether a line or plane explains rim points to within their noise: RMS distance at
    most ``tolerance / 2`` (the tolerance is about 4 noise sigmas, see _rim_tolerance), and
    none beyond ``2 tolerance`` (a real bend, not noise)."""
    rms = float(np.sqrt(np.mean(distance * distance)))
    return rms <= 0.5 * tolerance and float(distance.max()) <= 2.0 * tolerance


def _rim_side(
    run: NDArray[np.float64],
    start: NDArray[np.float64],
    end: NDArray[np.float64],
    plane: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    tolerance: float,
) -> tuple[PiecewiseBezier, float]:
    """The side through rim points ``run`` (corners included): a line when the run is
    straight to ``tolerance``, a plane curve when it is planar, else a free 3D curve (a C2
    spline, :func:`~pde2cad.surfaces.rim.fit_rim_spline`)."""
    off = _off_chord(run, start, end)
    if _explained(off, tolerance):
        ctrl = start + np.outer(np.arange(4) / 3.0, end - start)
        ctrl[0], ctrl[3] = start, end  # bit-identical corners for the neighbouring sides
        return PiecewiseBezier.from_cubic(ctrl), float(off.max())
    side, error = fit_rim_spline(run, start, end)
    if plane is None:
        return side, error
    # Control points onto the plane: a Bezier with planar control points is planar, and the
    # projection is affine, so G1 joints stay G1. The corners are the caller's.
    centre, normal = plane
    ctrl = side.ctrl - np.multiply.outer((side.ctrl - centre) @ normal, normal)
    ctrl[0, 0], ctrl[-1, 3] = start, end
    planar = PiecewiseBezier(ctrl, side.breaks)
    moved = float(cKDTree(planar.evaluate(np.linspace(0.0, 1.0, 4001))).query(run)[0].max())
    # The plane was accepted on RMS: where it moves the curve beyond the tolerance somewhere,
    # the free fit is kept.
    return (planar, moved) if moved <= tolerance else (side, error)


def _rim_band(
    uv: NDArray[np.float64], loop_uv: NDArray[np.float64], reach: float = 0.0
) -> tuple[NDArray[np.bool_], float]:
    """Which points lie within about RIM_BAND sample spacings of the loop (in the projection
    plane, on a grid of cells half that wide): all the rim estimate reads (its windows reach
    a few sample spacings, or noise sigmas, into the surface), so a dense cloud's interior
    never goes into a KD-tree. The spacing is the mean one, ``sqrt(area / N)`` inside the
    loop, or the loop's median edge if shorter (the refined loop of a large cloud has
    edges of 2-3 spacings, and a band in its edges held 30 % of a 1e6-point cloud).
    ``reach``: the band reaches at least this far (windows deeper than the default band).

    Returns the mask and the least distance from the loop to the band's edge (a cell).
    """
    after = np.roll(loop_uv, -1, axis=0)
    area = 0.5 * abs(float(np.sum(loop_uv[:, 0] * after[:, 1] - after[:, 0] * loop_uv[:, 1])))
    edge = float(np.median(np.linalg.norm(after - loop_uv, axis=1)))
    step = min(edge, float(np.sqrt(area / len(uv))))
    cell = max(0.5 * RIM_BAND * step, reach)
    lo = column_min(uv)
    ij = np.floor((uv - lo) / cell).astype(np.int64)
    dims = column_max(ij) + 1
    mark = np.zeros(tuple(dims), dtype=bool)
    at = np.clip(np.floor((loop_uv - lo) / cell).astype(np.int64), 0, dims - 1)
    mark[at[:, 0], at[:, 1]] = True
    mark = maximum_filter(mark, size=3, mode="constant", cval=False)
    return mark[ij[:, 0], ij[:, 1]], cell


def _straight_line(
    run: NDArray[np.float64], tolerance: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """``(point, unit direction)`` of the line the rim points lie on to within their noise
    (:func:`_explained`), or None."""
    centre = run.mean(axis=0)
    direction = np.linalg.eigh((run - centre).T @ (run - centre))[1][:, -1]
    rel = run - centre
    off = np.linalg.norm(rel - np.outer(rel @ direction, direction), axis=1)
    return (centre, direction) if _explained(off, tolerance) else None


def _onto_straight_rims(
    corners: NDArray[np.float64],
    lines: list[tuple[NDArray[np.float64], NDArray[np.float64]] | None],
) -> NDArray[np.float64]:
    """Corners between two straight rims where their lines meet (all the stations of both
    sides fix it, not only those near the corner); a corner with one straight rim onto its
    line. ``lines[k]`` is side k's line (from corner k to k + 1) or None."""
    out = corners.copy()
    for j in range(len(corners)):  # 3-4 corners
        before, after = lines[j - 1], lines[j]
        meet = None if before is None or after is None else _lines_meet(before, after, 20.0)
        if meet is not None:
            out[j] = meet
            continue
        for line in (before, after):
            if line is not None:
                point, direction = line
                out[j] = point + ((corners[j] - point) @ direction) * direction
                break
    return out


def _side_spacing(tree: cKDTree, run: NDArray[np.float64], spacing: float) -> float:
    """Sample spacing along one side, for clouds whose density varies: from the distances
    of the side's loop points to their ``DENSITY_RANK``-th neighbour (half discs at a rim:
    ``s = r sqrt(pi / 2k)``), towards its sparse end (75th percentile), where that exceeds
    ``spacing`` (the band's) by a factor SPARSE_SIDE; else ``spacing``. Windows sized by
    the band's spacing hold too few points where the cloud is sparser than average, and
    get dropped."""
    dist, _ = tree.query(run, k=DENSITY_RANK + 1)
    local = float(np.quantile(dist[:, -1], 0.75)) * np.sqrt(np.pi / (2.0 * DENSITY_RANK))
    # On a uniform cloud the estimate exceeds the band's by 5-10 % (the loop points lie a
    # little inside the rim, so more than a half disc): only a clear excess is a sparser side.
    return local if local > SPARSE_SIDE * spacing else spacing


def _covers(rim: RimEstimate) -> bool:
    """Whether rim stations span most of their side (at least COVER_STATIONS of them over
    half its length), so a line through them stands for the whole side."""
    return len(rim.arc) >= COVER_STATIONS and float(np.ptp(rim.arc)) >= 0.5 * rim.length


def _sampled_rim(run: NDArray[np.float64], side: PiecewiseBezier, spacing: float) -> bool:
    """Whether the loop points of a side are samples on its rim (a row of structured data).

    The loop of random samples zigzags between outermost samples whose depths differ by
    exponential gaps of about a spacing over a spacing's run, so it stays a sizeable fraction
    of a spacing off any smooth curve; a sampled row lies on its fitted side to the fit's
    tolerance. The RMS distance of the loop points to the side tells them apart at
    SAMPLED_LOOP spacings.
    """
    curve = side.evaluate(np.linspace(0.0, 1.0, 4001))
    dist = cKDTree(curve).query(run)[0]
    return float(np.sqrt(np.mean(dist * dist))) <= SAMPLED_LOOP * spacing


def _relocate_rims(
    pts: NDArray[np.float64],
    plane: tuple[NDArray[np.float64], NDArray[np.float64]],
    runs: list[NDArray[np.float64]],
    sides: list[PiecewiseBezier],
    loop_errors: NDArray[np.float64],
    corners: NDArray[np.float64],
    fixed: bool,
    tolerance: float | None,
    diagonal: float,
    reach: float = 0.0,
) -> tuple[list[PiecewiseBezier], NDArray[np.float64], float] | None:
    """Sides on the true rim (:mod:`pde2cad.surfaces.rim`) instead of the boundary loop,
    from the points near it: the band of :func:`_rim_band` around the loop, ``plane`` =
    (points, loop) in the projection plane, reaching at least ``reach`` (inf: all points).
    Windows deeper than the band (noise of several spacings, or sides sparser than the
    cloud's mean spacing) get a band 1.5 times their depth, the margin for the spacing
    estimate of the wider band; all points if that is still too shallow.

    1. Rim points along every side from the samples near it (:func:`locate_rim`); a side too
       short for a station keeps its loop points.
    2. Corners (unless ``fixed``, the caller's coordinates) where the rims of their two sides
       meet (:func:`_rim_corner`), at the height of the surface there (:func:`onto_surface`).
    3. Tolerance (unless given): the noise of the rim points (:func:`_rim_tolerance`);
       corners (unless fixed) on the lines of straight rims (:func:`_onto_straight_rims`).
    4. Sides refitted through the rim points: lines where straight, plane curves where
       planar (:func:`_rim_side`). A side whose rim is a sampled row (structured data) and
       whose corners stay keeps its loop fit.

    Returns the sides, their fit errors and the tolerance; None when no side has a rim to
    move (all too short, or sampled rows).
    """
    band = (np.ones(len(pts), dtype=bool), np.inf) if reach == np.inf else _rim_band(
        *plane, reach
    )
    # Duplicates would halve the spacing estimates and double the windows' counts: a
    # doubled cloud must give the same rims.
    cloud, pts = pts, unique_rows(pts[band[0]])
    tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)  # builds ~2x faster
    band_spacing = sample_spacing(pts, tree)
    spacings = [_side_spacing(tree, run, band_spacing) for run in runs]
    c = len(sides)
    # A side whose rim is sampled (structured data) keeps the loop points, which lie on it.
    sampled = [_sampled_rim(run, side, gap) for run, side, gap in zip(runs, sides, spacings)]
    # Windows at least RIM_DEPTH + 2 spacings deep: a band known to be too narrow is widened
    # before any rim is estimated in it (sides sparser than the cloud's mean).
    shallowest = max(
        ((RIM_DEPTH + 2.0) * gap for gap, row in zip(spacings, sampled) if not row), default=0.0
    )
    if shallowest > band[1]:
        wider = 1.5 * shallowest if reach == 0.0 else np.inf
        return _relocate_rims(
            cloud, plane, runs, sides, loop_errors, corners, fixed, tolerance, diagonal, wider
        )

    def rim_of(k: int) -> RimEstimate | None:
        run, side, gap = runs[k], sides[k], spacings[k]
        return None if sampled[k] else locate_rim(pts, side, gap, tree)

    # The sides on threads: numpy and the KD-tree release the GIL in their loops.
    with ThreadPoolExecutor(max_workers=min(c, os.cpu_count() or 1)) as pool:
        rims = list(pool.map(rim_of, range(c)))
    rims = [None if r is None or r.sampled.mean() > 0.5 else r for r in rims]
    depth = [
        max(RIM_DEPTH * gap, NOISE_DEPTH * float(np.median(r.noise))) + 2.0 * gap
        for r, gap in zip(rims, spacings) if r is not None
    ]
    deepest = max(depth, default=0.0)
    if deepest > band[1]:
        wider = 1.5 * deepest if reach == 0.0 else np.inf
        return _relocate_rims(
            cloud, plane, runs, sides, loop_errors, corners, fixed, tolerance, diagonal, wider
        )
    if all(r is None for r in rims):
        return None
    old = corners
    corners = corners.copy()
    if not fixed:
        perimeter = sum(r.length for r in rims if r is not None)
        for j in range(c):  # 3-4 corners
            before, after = rims[j - 1], rims[j]
            if before is not None and after is not None:
                spacing = max(spacings[j - 1], spacings[j])
                normal = surface_normal(pts, tree, corners[j], spacing)
                corner = _rim_corner(
                    before, after, corners[j], perimeter / REFINE_SPAN, normal, 0.1 * spacing
                )
                if corner is not corners[j]:
                    corners[j] = onto_surface(pts, tree, corner, spacing)
    inner = [run[1:-1] if r is None else r.points for run, r in zip(runs, rims)]
    tol = _rim_tolerance(inner, diagonal) if tolerance is None else tolerance
    if not fixed:
        corners = _onto_straight_rims(corners, [
            None if r is None or not _covers(r) else _straight_line(r.points, tol) for r in rims
        ])
    full = [np.vstack([corners[k], inner[k], corners[(k + 1) % c]]) for k in range(c)]
    out, errors = [], np.empty(c)
    for k in range(c):  # 3-4 sides
        ends = corners[k], corners[(k + 1) % c]
        if rims[k] is None and all(np.array_equal(corners[i % c], old[i % c]) for i in (k, k + 1)):
            out.append(sides[k])
            errors[k] = loop_errors[k]
            continue
        side, errors[k] = _rim_side(full[k], *ends, _side_plane(full[k], tol), tol)
        out.append(side)
    # The tolerance the sides meet: a kept loop fit may have used a larger one.
    return out, errors, max(tol, float(errors.max()))


def extract_boundary(
    points: ArrayLike,
    *,
    corners: ArrayLike | None = None,
    count: int | None = None,
    alpha: float | None = None,
    tolerance: float | None = None,
    rims: bool = True,
) -> RegionBoundary:
    """Boundary loop, corners and fitted sides of one region of a point cloud (Sec. 5.2.1-2).

    Parameters
    ----------
    points : (N, 3) float, N >= 10
        The region's points, unordered. The region must be a height field over its PCA plane
        (see the module docstring).
    corners : (c,) int or (c, 3) float, optional
        Corners chosen by the caller (c in {3, 4}): indices into ``points`` or coordinates.
        Each is matched to the nearest boundary-loop point. The caller's first corner is
        corner 0; the others keep their order if it runs counter-clockwise in the projection
        and are reversed (after the first) if it runs clockwise, so sides always run
        counter-clockwise. Given coordinates are used exactly as the side end points (so two
        neighbouring regions given the same corner coordinates share identical corners).
    count : {3, 4, None}
        Number of corners to detect when ``corners`` is not given (see
        :func:`detect_region_corners`). Detected corners are ordered from the one with the
        smallest ``u + v`` and placed where their sides meet (:func:`refine_corners`).
    alpha : float, optional
        Alpha-shape radius (see :func:`boundary_loop`).
    tolerance : float, optional
        Side-fit tolerance. Default: 3 x the RMS distance of the boundary points to a
        Savitzky-Golay smoothing of their side (the boundary's own noise, so sides follow the
        shape but not the jitter), at least 1e-4 x the bounding-box diagonal.
    rims : bool
        Place the sides on the true rim of the sampled surface, estimated from all samples
        near each side (:mod:`pde2cad.surfaces.rim`), rather than on the boundary loop,
        whose points lie about half a sample spacing inside and carry single-sample noise;
        straight rims become lines and planar ones plane curves. Detected corners move to
        where the rims meet; given corners stay as given. ``False``: sides fitted to the
        loop points (the thesis's Section 5.2.2). The default since the rim sides beat the
        loop sides on every held-out sheet measured (clean, noisy, non-uniform; 5e3-1e6
        points), e.g. a 100 x 60 flag of 50k points 1.6e-5 against 7.5e-5 of the diagonal.

    Returns
    -------
    RegionBoundary

    Raises
    ------
    InputError
        Bad points (NaN, < 10, collinear), no simple boundary loop, not 3 or 4 corners.
    FitError
        Two corners are adjacent on the loop, leaving a side without interior points.
    """
    pts = _as_points(points, 3, "points")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be a positive number, got {tolerance}")
    origin, centred = centred_columns(pts)
    axes = _pca_axes(centred)
    # A transposed view of (2, N): each coordinate stays one contiguous row. einsum, not @:
    # a threaded BLAS call costs more than the sum on a loaded machine.
    uv = np.einsum("ij,jk->ik", axes[:2], centred).T
    if alpha is None and len(pts) > 2 * SAMPLE_POINTS:
        loop_index = sampled_loop(uv)
    else:
        loop_index = boundary_loop(uv, alpha)
    n = len(loop_index)
    if corners is None:
        cidx = detect_region_corners(uv[loop_index], count=count)
        # Corner 0: the "bottom-left" corner, so sides come out bottom, right, top, left.
        first = int(uv[loop_index[cidx]].sum(axis=1).argmin())
        cidx = np.roll(cidx, -first)
        loop2d = uv[loop_index]
        perimeter = float(np.linalg.norm(np.roll(loop2d, -1, axis=0) - loop2d, axis=1).sum())
        cpos = refine_corners(pts[loop_index], cidx, perimeter / REFINE_SPAN)
    else:
        cidx, cpos = _caller_corners(corners, pts, loop_index)
        if count is not None and count != len(cidx):
            raise InputError(
                f"count={count} but {len(cidx)} corners were given; drop count or pass "
                f"{count} corners"
            )
    # Start the loop at corner 0, so corner indices increase from 0.
    loop_index = np.roll(loop_index, -int(cidx[0]))
    cidx = (cidx - cidx[0]) % n
    loop = pts[loop_index]
    ends = np.r_[cidx, n]
    if np.any(np.diff(ends) < 2):
        raise FitError(
            "two corners are neighbours on the boundary loop, leaving a side without points; "
            "pass corners= that are farther apart"
        )
    closed = np.vstack([loop, loop[:1]])
    runs = [closed[a : b + 1] for a, b in zip(ends[:-1], ends[1:])]
    diagonal = float(np.linalg.norm(column_max(pts) - column_min(pts)))
    tol = _noise_tolerance(runs, diagonal) if tolerance is None else float(tolerance)
    c = len(cidx)
    sides: list[PiecewiseBezier] = []
    errors = np.empty(c)
    for k, run in enumerate(runs):  # 3-4 sides, each fitted as a whole
        side, errors[k] = fit_side(run, tol, cpos[k], cpos[(k + 1) % c])
        sides.append(side)
    if rims:
        given = None if tolerance is None else float(tolerance)
        moved = _relocate_rims(
            pts, (uv, uv[loop_index]), runs, sides, errors, cpos, corners is not None, given,
            diagonal,
        )
        if moved is not None:
            sides, errors, tol = moved
    return RegionBoundary(
        loop=loop,
        loop_index=loop_index.astype(np.int64),
        corners=cidx.astype(np.int64),
        sides=tuple(sides),
        frame=(origin, axes),
        side_errors=errors,
        tolerance=tol,
    )
