"""Patch layout of a segmented point cloud: which segments touch, their borders and corners.

A segmented cloud (one integer label per point) is to become 3- or 4-sided surface patches
that share boundary curves with their neighbours. :func:`build_layout` finds the topology
that this needs, from the points alone:

1. **Neighbour graph.** k nearest neighbours (scipy ``cKDTree``), keeping only neighbours
   within the radius ``r = RADIUS_FACTOR`` x the median distance to the k-th neighbour (so
   the graph does not bridge gaps). Edges between different labels are *cross edges*.
2. **Adjacency and borders.** Two segments are adjacent when cross edges join them along a
   border longer than ``BORDER_SPAN`` x the neighbour radius. (Segments that only meet at a
   point, like the diagonal squares of a 2 x 2 grid, are joined by cross edges within one
   radius of that point: that is not a shared curve.) The border points of a pair are the
   points of either label with a neighbour of the other.
3. **Open boundary.** Each segment's outer loop is the alpha shape of its PCA projection
   (:func:`pde2cad.surfaces.region.boundary_loop`); loop points without a neighbour of another
   label lie on the open boundary of the whole cloud.
4. **Corners.** Candidates are (a) points whose neighbourhood holds >= 3 labels (where borders
   of different pairs meet), (b) loop points where a segment's loop switches between open
   boundary and border (a border meets the open boundary) and (c) sharp turns of a loop
   (turning angle over perimeter/32 of arc length >= ``CORNER_ANGLE``: outer corners of the
   cloud, and kinks of a border). Candidates closer than ``CLUSTER_FACTOR`` x the radius are
   clustered (``query_pairs`` + connected components); each cluster gives one corner, its
   centroid moved to the nearest cloud point. A segment's corners are those within
   ``CLUSTER_FACTOR`` x radius of one of its points.

Limits: two corners closer than ``CLUSTER_FACTOR`` x radius (~6 spacings on a grid, ~12 on
random samples) merge; a segment must be a
height field over its PCA plane (as for :func:`~pde2cad.surfaces.region.extract_boundary`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import maximum_filter1d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.surfaces.region import boundary_loop, pca_frame

#: The neighbour radius is RADIUS_FACTOR x the median distance to the k-th neighbour; farther
#: neighbours are ignored (so the graph does not bridge gaps). Scaling by the k-th rather
#: than the nearest neighbour makes it fit grids (k = 12: radius 2.5 x spacing) and random
#: samples (whose k-th neighbour lies ~4 x the median nearest-neighbour distance away) alike.
RADIUS_FACTOR = 1.25
#: A pair of segments is adjacent when its border points span more than BORDER_SPAN x radius
#: (segments touching at one point give border points within ~1 radius of it: span <= 2.9 r).
BORDER_SPAN = 4.0
#: Corner candidates closer than CLUSTER_FACTOR x radius form one corner.
CLUSTER_FACTOR = 2.5
#: A loop point is a sharp turn when the loop turns by at least this many degrees over
#: +- perimeter / TURN_STEPS of arc length (a 90-degree corner turns 90, the corners of a
#: cube-sphere face 60).
CORNER_ANGLE = 40.0
TURN_STEPS = 32
#: Connected components of a segment with less than this share of its points are ignored
#: (stray mislabelled points), bigger ones make the segment disconnected.
COMPONENT_SHARE = 0.01
#: The loop is resampled to this many points for the turning angle.
LOOP_SAMPLES = 512


@dataclass(frozen=True)
class Layout:
    """Topology of a segmented cloud: adjacency, borders, corners, open boundary.

    Attributes
    ----------
    labels_present : (S,) int
        The segment labels, sorted.
    adjacency : dict[(int, int), int]
        For each adjacent pair ``(a, b)`` with ``a < b``: the number of neighbour-graph edges
        joining them (a measure of the border length in samples).
    borders : dict[(int, int), (M, 3) float]
        The border points of each adjacent pair: points of either label with a neighbour of
        the other.
    corners : (C, 3) float
        Corner positions (cloud points).
    segment_corners : dict[int, (c,) int]
        Indices into ``corners`` of each segment's corners, sorted.
    open_boundary : dict[int, (K, 3) float]
        Each segment's points on the open boundary of the whole cloud (its alpha-shape loop
        minus border points), in loop order. Empty ``(0, 3)`` on a closed surface.
    spacing : float
        Median nearest-neighbour distance of the cloud.
    radius : float
        Neighbour radius: ``RADIUS_FACTOR`` x the median distance to the k-th neighbour.
    """

    labels_present: NDArray[np.int64]
    adjacency: dict[tuple[int, int], int]
    borders: dict[tuple[int, int], NDArray[np.float64]]
    corners: NDArray[np.float64]
    segment_corners: dict[int, NDArray[np.int64]]
    open_boundary: dict[int, NDArray[np.float64]]
    spacing: float
    radius: float


# --------------------------------------------------------------------------- checks
def _inputs(points: ArrayLike, labels: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    bad = int((~np.isfinite(pts)).any(axis=1).sum())
    if bad:
        raise InputError(f"points contain NaN or inf in {bad} rows; remove those rows first")
    lab = np.asarray(labels)
    if lab.shape != (len(pts),):
        raise InputError(
            f"labels must have one value per point: {lab.shape} labels for {len(pts)} points"
        )
    if lab.dtype.kind not in "iu":
        if lab.dtype.kind != "f" or not np.isfinite(lab).all() or (lab != np.rint(lab)).any():
            raise InputError("labels must be integers (read_cloud casts integral floats)")
    return pts, lab.astype(np.int64)


def _neighbours(
    pts: NDArray[np.float64], k: int
) -> tuple[NDArray[np.int64], NDArray[np.bool_], float, float]:
    """k-NN indices ``(N, k)`` (self excluded), a validity mask (within the radius), the median
    nearest-neighbour spacing and the radius."""
    tree = cKDTree(pts)
    dist, idx = tree.query(pts, k=k + 1, workers=-1)
    dist, idx = dist[:, 1:], idx[:, 1:]
    positive = dist[:, 0][dist[:, 0] > 0]
    if not positive.size:
        raise InputError("all points coincide; a layout needs a sampled surface")
    spacing = float(np.median(positive))
    radius = RADIUS_FACTOR * float(np.median(dist[:, -1]))
    return idx.astype(np.int64), dist <= radius, spacing, radius


def _components(n: int, rows: NDArray[np.int64], cols: NDArray[np.int64]) -> NDArray[np.int64]:
    """Connected-component id of each of ``n`` nodes of the graph with edges ``rows-cols``."""
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def _check_segments(
    lab: NDArray[np.int64],
    present: NDArray[np.int64],
    counts: NDArray[np.int64],
    idx: NDArray[np.int64],
    valid: NDArray[np.bool_],
    min_points: int,
) -> None:
    """InputError for segments that are too small or fall apart in the neighbour graph."""
    small = present[counts < min_points]
    if small.size:
        raise InputError(
            f"segment {int(small[0])} has {int(counts[counts < min_points][0])} points; a "
            f"segment needs at least {min_points} (merge it into a neighbour or relabel it)"
        )
    rows = np.repeat(np.arange(len(lab)), idx.shape[1])
    cols = idx.reshape(-1)
    same = valid.reshape(-1) & (lab[rows] == lab[cols])
    comp = _components(len(lab), rows[same], cols[same])
    size = np.bincount(comp)
    comp_label = np.empty(len(size), dtype=np.int64)
    comp_label[comp] = lab
    seg = np.searchsorted(present, comp_label)
    big = size >= COMPONENT_SHARE * counts[seg]
    n_big = np.bincount(seg[big], minlength=len(present))
    split = np.flatnonzero(n_big > 1)
    if split.size:
        s = split[0]
        raise InputError(
            f"segment {int(present[s])} falls apart into {int(n_big[s])} separate pieces; "
            "each segment must be one connected region — give each piece its own label"
        )


# --------------------------------------------------------------------------- loops
def _loop_candidates(
    pts: NDArray[np.float64], members: NDArray[np.int64], is_border: NDArray[np.bool_]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Open-boundary loop points and corner candidates (b), (c) of one segment.

    Returns indices into ``pts``: the open loop points (loop order) and the candidates.
    """
    origin, axes = pca_frame(pts[members])
    uv = (pts[members] - origin) @ axes[:2].T
    loop = members[boundary_loop(uv)]
    n = len(loop)
    border = is_border[loop]
    # Smooth the border/open state with a cyclic majority over 5 loop points, so one stray
    # point does not make two transitions.
    votes = sum(np.roll(border, s) for s in range(-2, 3))
    border = votes >= 3
    change = np.flatnonzero(border != np.roll(border, 1))
    # (b): both loop points at each switch (one on each side of it).
    trans = np.concatenate([loop[change], loop[change - 1]])
    # (c): sharp turns of the loop, measured on an arc-length resampling.
    loop2d = (pts[loop] - origin) @ axes[:2].T
    closed = np.vstack([loop2d, loop2d[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    m = LOOP_SAMPLES
    s = np.arange(m) * (arc[-1] / m)
    res = np.stack([np.interp(s, arc, closed[:, d]) for d in range(2)], axis=1)
    step = max(1, m // TURN_STEPS)
    ab = res - np.roll(res, step, axis=0)
    bc = np.roll(res, -step, axis=0) - res
    cross = ab[:, 0] * bc[:, 1] - ab[:, 1] * bc[:, 0]
    angle = np.degrees(np.arctan2(np.abs(cross), np.einsum("ij,ij->i", ab, bc)))
    top = maximum_filter1d(angle, size=2 * step + 1, mode="wrap")
    peaks = np.flatnonzero((angle >= CORNER_ANGLE) & (angle >= top))
    # The turning-angle peak of a jagged (randomly sampled) loop wanders by a fraction of
    # ``step``: move each peak to the loop vertex within +-step/2 (arc) that sticks out
    # farthest from the chord p[i - step] -> p[i + step], i.e. the corner's tip.
    a, b = res[(peaks - step) % m], res[(peaks + step) % m]
    chord = b - a
    normal = np.stack([-chord[:, 1], chord[:, 0]], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    height = np.abs(np.einsum("pd,npd->pn", normal, loop2d[:, None, :] - a[None, :, :]))
    gap = np.abs(arc[None, :-1] - s[peaks, None])
    gap = np.minimum(gap, arc[-1] - gap)
    height[gap > 0.5 * step * arc[-1] / m] = -1.0
    turns = loop[height.argmax(axis=1)] if len(peaks) else loop[:0]
    return loop[~border], np.concatenate([trans, turns])


# --------------------------------------------------------------------------- main
def build_layout(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    k: int = 12,
    min_points: int = 50,
    check: bool = True,
) -> Layout:
    """Adjacency, borders, open boundary and corners of a segmented point cloud.

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
        One segment label per point.
    k : int
        Neighbours per point of the neighbour graph.
    min_points : int
        Fewest points a segment may have.
    check : bool
        Require 3 or 4 corners per segment (a patch is 3- or 4-sided).

    Returns
    -------
    Layout

    Raises
    ------
    InputError
        Bad input; a segment with fewer than ``min_points`` points; a segment that falls
        apart into several pieces; with ``check``, a segment with other than 3 or 4 corners
        (each message names the segment label).

    Notes
    -----
    The algorithm and its constants are described in the module docstring. Cost is dominated
    by the k-NN query and one alpha shape per segment: ~13 s for 10^6 points in 4 segments,
    ~19 s in 6.
    """
    pts, lab = _inputs(points, labels)
    if k < 3:
        raise InputError(f"k must be >= 3 neighbours, got {k}")
    present, counts = np.unique(lab, return_counts=True)
    if len(pts) <= k:
        raise InputError(f"the cloud has {len(pts)} points; it needs more than k = {k}")
    idx, valid, spacing, radius = _neighbours(pts, k)
    _check_segments(lab, present, counts, idx, valid, min_points)

    # Cross edges, each unordered point pair once.
    rows = np.repeat(np.arange(len(pts)), k)
    cols = idx.reshape(-1)
    cross = valid.reshape(-1) & (lab[rows] != lab[cols])
    i, j = rows[cross], cols[cross]
    i, j = np.minimum(i, j), np.maximum(i, j)
    edge = np.unique(i * len(pts) + j)
    i, j = edge // len(pts), edge % len(pts)
    la, lb = np.minimum(lab[i], lab[j]), np.maximum(lab[i], lab[j])

    # Border points per label pair: both ends of every cross edge, each point once per pair.
    n_lab = len(present)
    pair = np.searchsorted(present, la) * n_lab + np.searchsorted(present, lb)
    pair_of_pt = np.concatenate([pair, pair])
    pt = np.concatenate([i, j])
    key = np.unique(pair_of_pt * len(pts) + pt)
    key_pair, key_pt = key // len(pts), key % len(pts)
    adjacency: dict[tuple[int, int], int] = {}
    borders: dict[tuple[int, int], NDArray[np.float64]] = {}
    edge_count = np.bincount(pair, minlength=n_lab * n_lab)
    starts = np.searchsorted(key_pair, np.arange(n_lab * n_lab + 1))
    for p in np.flatnonzero(edge_count):
        border = pts[key_pt[starts[p] : starts[p + 1]]]
        span = float(np.linalg.norm(border.max(axis=0) - border.min(axis=0)))
        if span > BORDER_SPAN * radius:
            a, b = int(present[p // n_lab]), int(present[p % n_lab])
            adjacency[(a, b)] = int(edge_count[p])
            borders[(a, b)] = border

    is_border = np.zeros(len(pts), dtype=bool)
    is_border[pt] = True

    # (a) points whose neighbourhood (with themselves) holds >= 3 labels.
    hood = np.where(valid, lab[idx], lab[:, None])
    hood = np.sort(np.column_stack([lab, hood]), axis=1)
    n_distinct = 1 + (np.diff(hood, axis=1) != 0).sum(axis=1)
    candidates = [np.flatnonzero(n_distinct >= 3)]

    # (b), (c) and the open boundary from each segment's loop.
    order = np.argsort(lab, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(counts)])
    open_boundary: dict[int, NDArray[np.float64]] = {}
    for s, label in enumerate(present):
        members = np.sort(order[bounds[s] : bounds[s + 1]])
        try:
            open_pts, cand = _loop_candidates(pts, members, is_border)
        except InputError as exc:
            raise InputError(f"segment {int(label)}: {exc}") from exc
        open_boundary[int(label)] = pts[open_pts]
        candidates.append(cand)
    cand = np.unique(np.concatenate(candidates))

    corners = _cluster(pts, cand, CLUSTER_FACTOR * radius)
    segment_corners = _assign(pts, lab, present, corners, CLUSTER_FACTOR * radius)
    if check:
        for label, which in segment_corners.items():
            if len(which) not in (3, 4):
                raise InputError(
                    f"segment {label} has {len(which)} corners; a patch needs 3 or 4 — split "
                    "or merge segments so each is a 3- or 4-sided region"
                )
    return Layout(
        labels_present=present.astype(np.int64),
        adjacency=adjacency,
        borders=borders,
        corners=corners,
        segment_corners=segment_corners,
        open_boundary=open_boundary,
        spacing=spacing,
        radius=radius,
    )


def _cluster(pts: NDArray[np.float64], cand: NDArray[np.int64], dist: float) -> NDArray[np.float64]:
    """One corner per cluster of candidate points: the cloud point nearest the centroid."""
    if not cand.size:
        return np.zeros((0, 3))
    pairs = cKDTree(pts[cand]).query_pairs(dist, output_type="ndarray")
    comp = _components(len(cand), pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64))
    n = int(comp.max()) + 1
    size = np.bincount(comp, minlength=n)
    centroid = np.stack([np.bincount(comp, pts[cand, d], minlength=n) for d in range(3)], axis=1)
    centroid /= size[:, None]
    _, nearest = cKDTree(pts).query(centroid)
    return pts[nearest]


def _assign(
    pts: NDArray[np.float64],
    lab: NDArray[np.int64],
    present: NDArray[np.int64],
    corners: NDArray[np.float64],
    dist: float,
) -> dict[int, NDArray[np.int64]]:
    """Corners within ``dist`` of at least one point of each segment."""
    out: dict[int, list[int]] = {int(label): [] for label in present}
    if len(corners):
        near = cKDTree(pts).query_ball_point(corners, dist)
        for c, rows in enumerate(near):  # one small list per corner, not per point
            for label in np.unique(lab[np.asarray(rows, dtype=np.int64)]):
                out[int(label)].append(c)
    return {label: np.asarray(sorted(v), dtype=np.int64) for label, v in out.items()}
