"""Patch layout of a segmented point cloud: which segments touch, their borders and corners.

A segmented cloud (one integer label per point) is to become 3- or 4-sided surface patches
that share boundary curves with their neighbours. :func:`build_layout` finds the topology
that this needs, from the points alone:

1. **Neighbour graph.** k nearest neighbours (scipy ``cKDTree``), keeping only neighbours
   within the radius ``r = RADIUS_FACTOR`` x the median distance to the k-th neighbour (so
   the graph does not bridge gaps; the medians are taken over at most ``SAMPLE_POINTS``
   points). Edges between different labels are *cross edges*. Only points whose voxel (side
   r) or an adjacent one holds another label can have one, so only they are queried: the
   same cross edges as from the k-NN of every point, at a few percent of the cost.
2. **Adjacency and borders.** Two segments are adjacent when cross edges join them along a
   border longer than ``BORDER_SPAN`` x the neighbour radius. (Segments that only meet at a
   point, like the diagonal squares of a 2 x 2 grid, are joined by cross edges within one
   radius of that point: that is not a shared curve.) The border points of a pair are the
   points of either label with a neighbour of the other.
3. **Open boundary.** Each segment's outer loop is the alpha shape of its projection on a
   plane (:func:`pde2cad.surfaces.region.boundary_loop`, kept in :attr:`Layout.loops`): its
   PCA plane, unless the segment's normals (sampled) show that this folds it, then the plane
   whose normal is farthest from being tangent to it (see ``FOLD_COS``); a segment that no
   plane fits (a strip folded across its width, like the teapot's rim) is unfolded instead:
   its main-axis coordinate x the geodesic distance from its longest border. Loop points
   without a neighbour of another label lie on the open boundary of the whole cloud. Runs of
   either state shorter than ``RUN_FACTOR`` x r of arc are noise (the alpha shape dips up to
   ~2.5 r into a dense random sample, between points with such a neighbour) and are flipped.
4. **Corners.** Candidates are (a) points whose neighbourhood holds >= 3 labels (where borders
   of different pairs meet; where a sparse spot leaves no such point: points whose
   neighbourhood holds 2 labels next to one holding another 2), (b) loop points where a
   segment's loop switches between open boundary and border (a border meets the open
   boundary) and (c) sharp turns of a loop (turning angle over +-perimeter/``TURN_STEPS`` of
   arc length >= ``CORNER_ANGLE``: outer corners of the cloud, and kinks of a border). The
   alpha shape of a noisy cloud wobbles, so a turn must persist over ``COARSE_TURN`` x that
   arc; a turn on a border must also be one of the loop on its other side (or of two other
   loops: a junction that (a) missed); and a turn within ``BORDER_SPAN`` x r of an (a) or
   (b) candidate is dropped (it is that corner, or a kink that would merge into it).
   Candidates closer than ``CLUSTER_FACTOR`` x the radius are clustered (``query_pairs`` +
   connected components); each cluster gives one corner, its centroid moved to the nearest
   cloud point. A segment's corners are those within ``CLUSTER_FACTOR`` x radius of one of
   its points. Linking, merging and assigning only relate *related* segments: those the
   candidates touch (within the radius) and the segments adjacent to those, so separate
   pieces less than ``CLUSTER_FACTOR`` x radius apart keep their own corners. A corner whose
   cluster holds a (b) candidate or a turn of an open run lies on
   the open boundary (:attr:`Layout.open_corners`); the other corners of two segments are
   kinks of a border, no patch corners.

A segment falls apart when its points' voxels (side r) form several 26-connected groups of
more than ``COMPONENT_SHARE`` of its points; pieces closer than ~3.5 r count as joined.

Limits: two corners of one segment closer than ``CLUSTER_FACTOR`` x radius (~6 spacings on a
grid, ~12 on random samples) merge, as do two closer than ``BORDER_SPAN`` x radius unless one
lies on the open boundary and the other not; a border shorter than ``BORDER_SPAN`` x radius
is none. (The Utah teapot's rim: its inner and outer corners are 0.1 apart, its seams 0.3
long, so it needs r < 0.025, ~300k points for rim + body; at 20k r = 0.095.) A segment must be
a height field over some plane, or a strip folded across its width that :func:`_unfold`
flattens.
"""

from __future__ import annotations

import os
import zlib
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Iterable
from dataclasses import dataclass, field
from itertools import chain
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import maximum_filter1d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.surfaces.region import boundary_loop, pca_frame
from pde2cad.surfaces.sheets import same_sheet

#: The neighbour radius is RADIUS_FACTOR x the median distance to the k-th neighbour; farther
#: neighbours are ignored (so the graph does not bridge gaps). Scaling by the k-th rather
#: than the nearest neighbour makes it fit grids (k = 12: radius 2.5 x spacing) and random
#: samples (whose k-th neighbour lies ~4 x the median nearest-neighbour distance away) alike.
RADIUS_FACTOR = 1.25
#: A pair of segments is adjacent when its border points span more than BORDER_SPAN x radius
#: (segments touching at one point give border points within ~1 radius of it: span <= 2.9 r).
BORDER_SPAN = 4.0
#: Corner candidates closer than CLUSTER_FACTOR x radius form one corner. Corners closer than
#: BORDER_SPAN x radius are then merged too: no border that short counts as an edge, so they
#: cannot be the two ends of one (sparse random samples split a four-way junction into two
#: three-way ones joined by a stub of diagonal border).
CLUSTER_FACTOR = 2.5
#: A loop point is a sharp turn when the loop turns by at least this many degrees over
#: +- perimeter / TURN_STEPS of arc length (a 90-degree corner turns 90, the corners of a
#: cube-sphere face 60) ...
CORNER_ANGLE = 40.0
TURN_STEPS = 32
#: ... and over COARSE_TURN x that arc too. Along the open boundary of a noisy cloud (noise
#: 0.5 % of the diagonal, 20k points) the alpha shape wobbles by up to ~70 degrees over
#: +- perimeter / 32 but by <= ~35 over twice that; the corners of the sample shapes turn by
#: >= 60 (90-degree corners) or >= 45 (cube-sphere faces, curved sides) at both scales.
COARSE_TURN = 2
#: Connected components of a segment with less than this share of its points are ignored
#: (stray mislabelled points), bigger ones make the segment disconnected.
COMPONENT_SHARE = 0.01
#: Runs of border (or open) loop points shorter than RUN_FACTOR x radius of arc are noise.
RUN_FACTOR = 4.0
#: The loop is resampled to this many points for the turning angle.
LOOP_SAMPLES = 512
#: The spacing and the radius are medians over at most this many points (every m-th point in
#: k-d tree order, so spread over the whole cloud).
SAMPLE_POINTS = 50_000
#: Voxel look-ups use a dense table while the voxel grid has at most TABLE_CELLS cells per
#: point (4 bytes each), else a binary search.
TABLE_CELLS = 32
#: The segments' alpha shapes run on up to this many threads (at most one per CPU).
MAX_THREADS = 4
#: A segment's projection plane: its PCA plane, unless that folds it. Normals (PCA of the
#: FRAME_NEIGHBOURS nearest cloud points: with k = 12, noise of 0.5 % of the diagonal tilts
#: them so far that the quantile below drops to ~0.03 on flat patches; with 48 it stays
#: >= 0.49 on the sample shapes) are estimated at up to FRAME_SAMPLES of its points; when the
#: FRAME_QUANTILE quantile of ``|normal . plane normal|`` is below FOLD_COS (normals within
#: ~84 degrees of the plane: the projection folds, as for the bulb-shaped knob quarters of
#: the Utah teapot lid, whose PCA normal is tangential), the plane normal is instead the one
#: of FRAME_DIRECTIONS directions (a Fibonacci hemisphere) maximising that quantile, if that
#: reaches FRAME_ACCEPT (the knob quarters: 0.28-0.31; the rim, whose cross-section turns by
#: ~175 degrees, fits no plane: <= 0.11 at 300k points, and keeps its PCA plane).
FRAME_SAMPLES = 256
FRAME_NEIGHBOURS = 48
FRAME_QUANTILE = 0.01
FOLD_COS = 0.1
FRAME_ACCEPT = 0.2
#: A segment that fits no plane is unfolded (:func:`_unfold`) on its graph of up to
#: UNFOLD_NEIGHBOURS nearest own points within the radius.
UNFOLD_NEIGHBOURS = 12
#: ... when that graph reaches at least this share of it (crumbs apart from it are allowed).
UNFOLD_REACHED = 0.9
#: An unfolded strip's border run is bent when its extent along the main axis is under
#: this share of its length (an arc of ~230 degrees: 2 r over its length; the axis folds
#: one past 180, but half tubes of exactly 180 must keep it).
BENT_RUN = 0.5
FRAME_DIRECTIONS = 600
#: Distances along the surface: shortest paths in the graph of each point's
#: GEODESIC_NEIGHBOURS nearest points within the radius, from GEODESIC_CHUNK sources at a time.
GEODESIC_NEIGHBOURS = 12
GEODESIC_CHUNK = 128
#: Corner candidates within the linkage distance are linked only when a path along the
#: surface joins them within GEODESIC_SLACK x their distance (or that + half a radius): the
#: teapot rim's inner and outer corners lie 0.1 apart in space, 0.3 along the surface
#: (candidates 2.2 radii apart, 4.1 along the surface, at 112k points).
GEODESIC_SLACK = 1.4
#: ... and a candidate on the open boundary with one that is not only within MIXED_LINK
#: radii (the rim's inner and outer candidates: >= 1.9 radii apart at 112k points).
MIXED_LINK = 1.5
#: Two segments whose border is no boundary of one of them cross or touch (the teapot's
#: handle and spout pierce its body): one-sidedness (see :func:`_one_sided`) below
#: EDGE_SHARE, from EDGE_NEIGHBOURS neighbours of up to EDGE_SAMPLES border points, counting
#: those within EDGE_SLAB (|height| / distance) of the tangent plane, and the other
#: segment rising off that plane by EDGE_RISE. Measured at 112k points: one-sidedness
#: 0.35-0.87 at the teapot's borders, 0.10-0.25 where handle and spout pierce the body.
EDGE_SHARE = 0.3
EDGE_SLAB = 0.5
EDGE_RISE = 0.3
#: Segments (with at least TOUCH_LEAST border points) whose shortest cross link is longer
#: than TOUCH_GAP x radius only face each other across a gap: no border. On a shared border
#: the links interleave (shortest 0.05-0.2 radius at the noisy teapot's seams, its rim's
#: sparse lip seams included); its lid and rim on a 0.2 %-noise cloud, 0.1 apart at radius
#: 0.053, read 0.50-0.85. Uniform random links would all exceed 0.4 radius with
#: probability 0.6^10 ~ 0.6 % on 10 points, 4e-5 on 20.
TOUCH_LEAST = 10
TOUCH_GAP = 0.4
#: The tangent plane: PCA of the segment's NORMAL_NEIGHBOURS nearest points.
NORMAL_NEIGHBOURS = 12
EDGE_NEIGHBOURS = 64
EDGE_SAMPLES = 64


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
    loops : dict[int, (n,) int]
        Each segment's alpha-shape boundary loop as row indices into the input ``points``,
        counter-clockwise in the segment's projection frame: ``members[boundary_loop(uv)]``
        with ``members = np.flatnonzero(labels == label)`` and ``uv`` the members' projection
        on their :func:`~pde2cad.surfaces.region.pca_frame` (what ``extract_boundary``
        computes for ``points[members]`` with the default alpha) or, where that plane folds
        the segment, on a tilted plane or an unfolding (see ``FOLD_COS``).
    tree : cKDTree or None
        The k-d tree of all the points (kept so later stages need not build another).
    open_corners : (C,) bool or None
        Whether each corner lies on the open boundary of the cloud: its cluster holds a (b)
        candidate (a border meets the open boundary) or a sharp turn of an open run of a loop.
        Corners of two segments that are not (kinks of a border) are no patch corners.
    sharp_corners : (C,) bool or None
        Corners of two segments kept all the same: sharp turns of a border (where a merged
        segment meets its neighbour at a corner of the neighbour's), found by
        :func:`~pde2cad.layout.split.split_segments`.
    crossing : frozenset of (int, int)
        Pairs ``(a, b)``, ``a < b``, that cross or touch without sharing a boundary (the
        teapot's spout piercing its body): no border, no corners from each other.
    """

    labels_present: NDArray[np.int64]
    adjacency: dict[tuple[int, int], int]
    borders: dict[tuple[int, int], NDArray[np.float64]]
    corners: NDArray[np.float64]
    segment_corners: dict[int, NDArray[np.int64]]
    open_boundary: dict[int, NDArray[np.float64]]
    spacing: float
    radius: float
    loops: dict[int, NDArray[np.int64]] = field(default_factory=dict)
    tree: cKDTree | None = field(default=None, repr=False, compare=False)
    open_corners: NDArray[np.bool_] | None = None
    sharp_corners: NDArray[np.bool_] | None = None
    crossing: frozenset[tuple[int, int]] = frozenset()

    def crossed(self, label: int) -> set[int]:
        """The segments that cross or touch ``label`` without a shared boundary."""
        return {b if a == label else a for a, b in self.crossing if label in (a, b)}


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


def _neighbours(pts: NDArray[np.float64], k: int) -> tuple[cKDTree, float, float]:
    """k-d tree of all points, the median nearest-neighbour spacing and the radius (medians
    over at most SAMPLE_POINTS points, exact below that)."""
    # Unbalanced: builds ~2x faster, same neighbours.
    tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
    step = max(1, len(pts) // SAMPLE_POINTS)
    # Every step-th point in tree order: spread over the cloud and cache-friendly to query.
    probe = tree.indices[::step] if step > 1 else np.arange(len(pts))
    dist, _ = tree.query(pts[probe], k=k + 1, workers=-1)
    dist = dist[:, 1:]
    positive = dist[:, 0][dist[:, 0] > 0]
    if not positive.size:
        raise InputError("all points coincide; a layout needs a sampled surface")
    spacing = float(np.median(positive))
    radius = RADIUS_FACTOR * float(np.median(dist[:, -1]))
    return tree, spacing, radius


@dataclass(frozen=True)
class _Voxels:
    """Points binned in cubes of side >= radius: two points within the radius of each other
    lie in the same or 26-adjacent voxels."""

    key: NDArray[np.int64]  # (V,) sorted voxel keys
    vid: NDArray[np.int64]  # (N,) voxel of each point (index into key)
    order: NDArray[np.int64]  # (N,) points sorted by voxel
    start: NDArray[np.int64]  # (V + 1,) voxel v holds order[start[v]:start[v + 1]]
    offsets: NDArray[np.int64]  # (26,) key offsets of the adjacent voxels
    table: NDArray[np.int32] | None  # voxel index of every key (-1: empty), if not too big

    def adjacent(
        self, key: NDArray[np.int64], off: int
    ) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """Voxel index of ``key + off`` and whether that voxel holds points."""
        want = key + off
        if self.table is not None:
            pos = self.table[want]
            found = pos >= 0
            return np.where(found, pos, 0).astype(np.int64), found
        near = np.minimum(np.searchsorted(self.key, want), len(self.key) - 1)
        return near, self.key[near] == want


def _voxels(pts: NDArray[np.float64], size: float) -> _Voxels:
    lo = pts.min(axis=0)
    size = max(size, float((pts.max(axis=0) - lo).max()) * 1e-6)  # keys fit in int64
    # +1: a margin of empty voxels all round, so key offsets never wrap.
    ijk = np.floor((pts - lo) / size).astype(np.int64) + 1
    dims = ijk.max(axis=0) + 2
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    first = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    vid = np.empty(len(pts), dtype=np.int64)
    vid[order] = np.cumsum(np.r_[False, sorted_key[1:] != sorted_key[:-1]])
    d = (-1, 0, 1)
    offsets = np.array(
        [(a * dims[1] + b) * dims[2] + c for a in d for b in d for c in d if (a, b, c) != (0, 0, 0)],
        dtype=np.int64,
    )
    ukey = sorted_key[first]
    table = None
    size_table = int(dims.prod())
    if size_table <= TABLE_CELLS * len(pts) and len(ukey) < 2**31:
        table = np.full(size_table, -1, dtype=np.int32)
        table[ukey] = np.arange(len(ukey), dtype=np.int32)
    return _Voxels(ukey, vid, order, np.r_[first, len(pts)], offsets, table)


def _mixed_points(vox: _Voxels, lab: NDArray[np.int64]) -> NDArray[np.int64]:
    """Points whose voxel or an adjacent one holds another label: all points that can have a
    neighbour (within the radius) of another label. Sorted by voxel."""
    sorted_lab = lab[vox.order]
    low = np.minimum.reduceat(sorted_lab, vox.start[:-1])
    high = np.maximum.reduceat(sorted_lab, vox.start[:-1])
    hood_low, hood_high = low.copy(), high.copy()
    for off in vox.offsets:
        pos, found = vox.adjacent(vox.key, int(off))
        np.minimum(hood_low, np.where(found, low[pos], hood_low), out=hood_low)
        np.maximum(hood_high, np.where(found, high[pos], hood_high), out=hood_high)
    mixed = hood_low != hood_high
    return vox.order[np.repeat(mixed, np.diff(vox.start))]


def _components(n: int, rows: NDArray[np.int64], cols: NDArray[np.int64]) -> NDArray[np.int64]:
    """Connected-component id of each of ``n`` nodes of the graph with edges ``rows-cols``."""
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def _check_segments(
    lab: NDArray[np.int64],
    present: NDArray[np.int64],
    counts: NDArray[np.int64],
    vox: _Voxels,
    min_points: int,
) -> None:
    """InputError for segments that are too small or fall apart.

    A segment falls apart when its occupied voxels (side >= the neighbour radius) form more
    than one 26-connected group holding >= COMPONENT_SHARE of its points
    (:func:`_segment_pieces`). Points within the radius of each other are in adjacent
    voxels, so this never splits what the neighbour graph joins; it may join pieces less
    than ~3.5 radii apart.
    """
    small = present[counts < min_points]
    if small.size:
        raise InputError(
            f"segment {int(small[0])} has {int(counts[counts < min_points][0])} points; a "
            f"segment needs at least {min_points} (merge it into a neighbour or relabel it)"
        )
    _, big, comp_seg = _segment_pieces(lab, present, counts, vox)
    n_big = np.bincount(comp_seg[big], minlength=len(present))
    split = np.flatnonzero(n_big > 1)
    if split.size:
        s = split[0]
        raise InputError(
            f"segment {int(present[s])} falls apart into {int(n_big[s])} separate pieces; "
            "each segment must be one connected region — give each piece its own label"
        )


def _segment_pieces(
    lab: NDArray[np.int64], present: NDArray[np.int64], counts: NDArray[np.int64], vox: _Voxels,
) -> tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.int64]]:
    """The 26-connected voxel groups of every segment.

    Returns
    -------
    piece : (N,) int
        Group of each point.
    big : (G,) bool
        Groups holding >= COMPONENT_SHARE of their segment's points.
    group_segment : (G,) int
        Index into ``present`` of each group's segment.
    """
    n_lab = len(present)
    seg = np.searchsorted(present, lab[vox.order])
    # Graph nodes: (voxel, segment) pairs holding points. In voxel order the keys are nearly
    # sorted already (only mixed voxels are not): a stable (tim)sort is close to linear.
    point_keys = vox.vid[vox.order] * n_lab + seg
    keys = np.sort(point_keys, kind="stable")
    first = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    node, weight = keys[first], np.diff(np.r_[first, len(keys)])
    node_vid, node_seg = node // n_lab, node % n_lab
    # Nodes of voxel v: node_start[v] .. node_start[v + 1] - 1 (one, unless labels mix).
    node_start = np.searchsorted(node_vid, np.arange(len(vox.key) + 1))
    several = np.diff(node_start) > 1
    rows, cols = [], []
    for off in vox.offsets[len(vox.offsets) // 2 :]:  # 13 of the 26 (each pair once)
        pos, found = vox.adjacent(vox.key[node_vid], int(off))
        at = node_start[pos]
        hit = found & (node_seg[at] == node_seg)
        again = np.flatnonzero(found & ~hit & several[pos])
        if again.size:  # a voxel of several labels: find the node of this one
            want = pos[again] * n_lab + node_seg[again]
            where = np.minimum(np.searchsorted(node, want), len(node) - 1)
            ok = node[where] == want
            at[again[ok]] = where[ok]
            hit[again[ok]] = True
        rows.append(np.flatnonzero(hit))
        cols.append(at[hit])
    comp = _components(len(node), np.concatenate(rows), np.concatenate(cols))
    size = np.bincount(comp, weights=weight)
    comp_seg = np.empty(len(size), dtype=np.int64)
    comp_seg[comp] = node_seg
    piece = np.empty(len(lab), dtype=np.int64)
    piece[vox.order] = comp[np.searchsorted(node, point_keys)]
    return piece, size >= COMPONENT_SHARE * counts[comp_seg], comp_seg


def separate_pieces(
    points: ArrayLike, labels: ArrayLike, first_new: int, k: int = 12, min_points: int = 50,
) -> tuple[NDArray[np.int64], dict[int, list[int]]]:
    """Labels with every segment that falls apart (as :func:`build_layout` checks it) cut
    into its pieces: the piece with the most points keeps the label, each other piece of at
    least ``COMPONENT_SHARE`` of the segment's points and ``min_points`` takes a new label
    (``first_new``, ``first_new + 1``, ...); pieces of that share with fewer points join the
    segment of their nearest point outside them; smaller crumbs stay with their label (the
    check ignores them).

    Returns
    -------
    labels : (N,) int
        The input array itself when nothing falls apart.
    pieces : dict[int, list[int]]
        Per cut label, its pieces' labels (the first is the label itself).
    """
    pts, lab = _inputs(points, labels)
    present, counts = np.unique(lab, return_counts=True)
    _, _, radius = _neighbours(pts, k)
    piece, big, comp_seg = _segment_pieces(lab, present, counts, _voxels(pts, radius))
    size = np.bincount(piece, minlength=len(big))
    n_big = np.bincount(comp_seg[big], minlength=len(present))
    apart = np.flatnonzero(n_big > 1)
    if not apart.size:
        return np.asarray(labels), {}
    out, pieces, new = lab.copy(), {}, int(first_new)
    crumbs = np.zeros(len(big), dtype=bool)
    for s in apart.tolist():
        groups = np.flatnonzero(big & (comp_seg == s))
        groups = groups[np.argsort(-size[groups], kind="stable")]
        crumbs[groups[1:][size[groups[1:]] < min_points]] = True
        groups = np.r_[groups[:1], groups[1:][size[groups[1:]] >= min_points]]
        names = [int(present[s])] + list(range(new, new + len(groups) - 1))
        for g, name in zip(groups[1:].tolist(), names[1:]):
            out[piece == g] = name
        new += len(groups) - 1
        if len(names) > 1:
            pieces[int(present[s])] = names
    return take_nearest(pts, out, crumbs[piece]), pieces


def take_nearest(points: NDArray[np.float64], labels: NDArray[np.int64], moving: NDArray[np.bool_]
                 ) -> NDArray[np.int64]:
    """``labels`` with every ``moving`` point given the label of its nearest point that does
    not move (unchanged when none or all move)."""
    if not moving.any() or moving.all():
        return labels
    stay = np.flatnonzero(~moving)
    _, near = cKDTree(points[stay]).query(points[moving], workers=-1)
    out = labels.copy()
    out[moving] = labels[stay[near]]
    return out


def merge_small(
    points: NDArray[np.float64], labels: NDArray[np.int64], least: int,
    avoid: dict[int, set[int]] | None = None, prefer: dict[int, set[int]] | None = None,
    k: int = 12,
) -> NDArray[np.int64]:
    """``labels`` with every segment of fewer than ``least`` points merged into the
    neighbour it shares the longest border with: the label most often among its points'
    ``k`` nearest neighbours within the neighbour radius (as :func:`build_layout` counts a
    border).

    1. Smallest segment first; merged, it is counted again with its new neighbour.
    2. ``avoid[label]``: labels it joins only when it borders no other (a piece cut from a
       segment goes back into its one sibling only then: that would undo the cut, which
       the next round would make again); ``prefer[label]``: labels it joins when it borders
       one (a sliver of a cut into several pieces stays in its segment, so no neighbour's
       border moves).
    3. A segment that borders none (an island) takes its points' nearest other labels.

    The input array itself when no segment is that small (or every one is).
    """
    out = labels
    counts = np.unique(labels, return_counts=True)[1]
    if not (counts < least).any() or (counts < least).all():
        return labels
    tree, _, radius = _neighbours(points, k)
    kk = min(k + 1, len(points))
    while True:
        present, counts = np.unique(out, return_counts=True)
        if not (counts < least).any() or len(present) < 2:
            return out
        label = int(present[np.argmin(counts)])
        own = np.flatnonzero(out == label)
        _, idx = tree.query(points[own], k=kk, distance_upper_bound=radius, workers=-1)
        near = out[idx[(idx < len(points))]]
        near = near[near != label]
        out = out.copy() if out is labels else out
        if not len(near):
            out[:] = take_nearest(points, out, out == label)
            continue
        names, votes = np.unique(near, return_counts=True)
        shunned = np.isin(names, list((avoid or {}).get(label, ())))
        if not shunned.all():
            votes = np.where(shunned, 0, votes)
        liked = np.isin(names, list((prefer or {}).get(label, ())))
        if liked.any():
            votes = np.where(liked, votes, 0)
        out[own] = names[int(np.argmax(votes))]


# --------------------------------------------------------------------------- on the surface
def _local_graph(
    pts: NDArray[np.float64], tree: cKDTree, centres: NDArray[np.float64], reach: float,
    radius: float, k: int = GEODESIC_NEIGHBOURS,
) -> tuple[NDArray[np.int64], coo_matrix]:
    """The cloud points within ``reach`` of any of ``centres`` (sorted) and their k-NN
    graph (edges at most ``radius`` long, one way each: search it with ``directed=False``):
    its shortest paths run along the surface.

    Nothing here is as long as the cloud: a border's geodesic test runs this hundreds of
    times on a layout of a hundred segments."""
    rows = tree.query_ball_point(centres, reach)
    local = np.unique(np.fromiter(chain.from_iterable(rows), dtype=np.int64))
    dist, idx = tree.query(pts[local], k=min(k + 1, len(pts)), distance_upper_bound=radius)
    j = _local_index(local, idx)
    ok = j >= 0
    i = np.repeat(np.arange(len(local)), idx.shape[1]).reshape(idx.shape)
    return local, coo_matrix((dist[ok], (i[ok], j[ok])), shape=(len(local),) * 2)


def _local_index(local: NDArray[np.int64], ids: NDArray[np.int64]) -> NDArray[np.int64]:
    """Position of each of ``ids`` in the sorted ``local``, -1 where it is not there."""
    if not len(local):
        return np.full(np.shape(ids), -1, dtype=np.int64)
    pos = np.minimum(np.searchsorted(local, ids), len(local) - 1)
    return np.where(local[pos] == ids, pos, -1)


def surface_distances(
    pts: NDArray[np.float64], tree: cKDTree, sources: NDArray[np.int64],
    targets: NDArray[np.int64], reach: float, radius: float,
) -> NDArray[np.float64]:
    """Distance along the surface (shortest path in the neighbour graph, hops at most
    ``radius``) from point ``sources[p]`` to point ``targets[p]``, inf beyond ``reach``.

    A chord across a fold is no path: the teapot's rim turns its 0.3-long cross-section
    back so that its inner and outer edges lie 0.1 apart in space."""
    out = np.full(len(sources), np.inf)
    if not len(sources):
        return out
    local, graph = _local_graph(pts, tree, pts[np.unique(sources)], reach, radius)
    csr = graph.tocsr()
    src, inverse = np.unique(_local_index(local, sources), return_inverse=True)
    dst = _local_index(local, targets)
    for lo in range(0, len(src), GEODESIC_CHUNK):
        chunk = src[lo : lo + GEODESIC_CHUNK]
        dist = dijkstra(csr, directed=False, indices=chunk, limit=reach)
        pick = (inverse >= lo) & (inverse < lo + len(chunk)) & (dst >= 0)
        out[pick] = dist[inverse[pick] - lo, dst[pick]]
    return out


def _run_span(border: NDArray[np.float64], radius: float) -> float:
    """Bounding-box diagonal of the largest run of border points (linked within ``radius``):
    two diagonal patches of a tube's 2 x 2 grid touch at two points on opposite sides."""
    pairs = cKDTree(border).query_pairs(radius, output_type="ndarray")
    comp = _components(len(border), pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64))
    run = border[comp == np.bincount(comp).argmax()]
    return float(np.linalg.norm(run.max(axis=0) - run.min(axis=0)))


def _surface_span(
    pts: NDArray[np.float64], tree: cKDTree, members: NDArray[np.int64], radius: float
) -> float:
    """Length along the surface of a set of points (a border band): the largest path from
    the point farthest from its first point (two sweeps), at most 2 x ``BORDER_SPAN`` radii."""
    reach = 2 * BORDER_SPAN * radius
    start = members[:1]
    for _ in range(2):
        dist = surface_distances(pts, tree, np.repeat(start, len(members)), members, reach, radius)
        if not np.isfinite(dist).any():
            return 0.0
        far = int(np.argmax(np.where(np.isfinite(dist), dist, -1.0)))
        span, start = float(dist[far]), members[far : far + 1]
    return span


def surface_reach(
    pts: NDArray[np.float64], tree: cKDTree, centres: NDArray[np.float64], reach: float,
    radius: float,
) -> list[NDArray[np.int64]]:
    """For each centre, the cloud points within ``reach`` of it along the surface (from its
    nearest cloud point; see :func:`surface_distances`)."""
    if not len(centres):
        return []
    local, graph = _local_graph(pts, tree, centres, reach, radius)
    csr = graph.tocsr()
    gap, seed = tree.query(centres)
    start = _local_index(local, seed)
    out: list[NDArray[np.int64]] = []
    for lo in range(0, len(centres), GEODESIC_CHUNK):
        dist = dijkstra(csr, directed=False, indices=start[lo : lo + GEODESIC_CHUNK], limit=reach)
        out += [local[row + g <= reach] for row, g in zip(dist, gap[lo : lo + GEODESIC_CHUNK])]
    return out


#: What :func:`build_layout` keeps of the last cloud it laid out (:func:`cloud_memo`), and
#: that cloud's digest.
_MEMO: dict[tuple[object, ...], object] = {}
_MEMO_CLOUD: list[tuple[tuple[int, ...], int]] = []
#: Entries kept at most (a layout of a few hundred segments has ~1000 borders).
_MEMO_KEPT = 20_000


def cloud_memo(pts: NDArray[np.float64]) -> dict[tuple[object, ...], object]:
    """Results kept for ``pts`` between layouts: the split step lays out the same cloud
    dozens of times with most segments and borders unchanged. Each entry's key holds
    everything its value depends on besides the points (see its user); the cloud is known
    by a checksum of its coordinates (a few ms per million points)."""
    cloud = (pts.shape, zlib.crc32(np.ascontiguousarray(pts).tobytes()))
    if _MEMO_CLOUD != [cloud] or len(_MEMO) > _MEMO_KEPT:
        _MEMO.clear()
        _MEMO_CLOUD[:] = [cloud]
    return _MEMO


def _border_span(
    pts: NDArray[np.float64], tree: cKDTree, members: NDArray[np.int64], radius: float,
    memo: dict[tuple[object, ...], object],
) -> float:
    """Length of a border band (its points ``members``): the bounding-box diagonal of its
    largest run (:func:`_run_span`), or where that is short, its length along the surface
    (:func:`_surface_span`: a border curving round a fold, the teapot rim's seams, is longer
    than its box); looked up in ``memo`` (:func:`cloud_memo`; the points alone decide it)."""
    key = ("span", radius, members.tobytes())
    if key not in memo:
        span = _run_span(pts[members], radius)
        if span <= BORDER_SPAN * radius:
            span = _surface_span(pts, tree, members, radius)
        memo[key] = span
    return cast(float, memo[key])


def _borders(
    pts: NDArray[np.float64], tree: cKDTree, lab: NDArray[np.int64], present: NDArray[np.int64],
    near: NDArray[np.int64], idx: NDArray[np.int64], valid: NDArray[np.bool_], radius: float,
    memo: dict[tuple[object, ...], object], digest: dict[int, int], find_crossing: bool = True,
) -> tuple[dict[tuple[int, int], int], dict[tuple[int, int], NDArray[np.float64]],
           NDArray[np.bool_], list[tuple[int, int]], dict[tuple[int, int], tuple[int, NDArray[np.float64]]]]:
    """Step 2 of the module docstring: adjacency, border points and whether each point is one
    (from the ``valid`` neighbours ``idx`` of the points ``near``); the pairs that cross or
    touch instead of sharing a boundary (:func:`_crossing`), left out, then ``(-1, -1)`` and
    the pairs where the surface goes on past the border (one-sidedness below
    ``EDGE_SHARE``); and the pairs left out as too short (their edge counts and border
    points). No pair crosses unless ``find_crossing``."""
    # Cross edges, each unordered point pair once.
    k = idx.shape[1]
    rows = np.repeat(near, k)
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
    pt = np.concatenate([i, j])
    every = np.concatenate([pair, pair]) * len(pts) + pt
    key = np.unique(every)
    key_pair, key_pt = key // len(pts), key % len(pts)
    # Per border point, its shortest cross edge (to the pair's other segment).
    span_ij = np.linalg.norm(pts[i] - pts[j], axis=1)
    order = np.lexsort((np.concatenate([span_ij, span_ij]), every))
    gap_of = np.concatenate([span_ij, span_ij])[order][np.searchsorted(every[order], key)]
    adjacency: dict[tuple[int, int], int] = {}
    borders: dict[tuple[int, int], NDArray[np.float64]] = {}
    crossing: list[tuple[int, int]] = []
    short: dict[tuple[int, int], tuple[int, NDArray[np.float64]]] = {}
    weak: list[tuple[int, int]] = []
    edge_count = np.bincount(pair, minlength=n_lab * n_lab)
    starts = np.searchsorted(key_pair, np.arange(n_lab * n_lab + 1))
    for p in np.flatnonzero(edge_count):
        members = key_pt[starts[p] : starts[p + 1]]
        border = pts[members]
        span = _border_span(pts, tree, members, radius, memo)
        a, b = int(present[p // n_lab]), int(present[p % n_lab])
        # The test sees the border points and which points are a's and b's, nothing else.
        seen = ("crossing", members.tobytes(), digest[a], digest[b])
        if seen not in memo:
            memo[seen] = _crossing(pts, tree, lab, members, a, b)
        share, rise = cast("tuple[float, float]", memo[seen])
        if share < EDGE_SHARE:
            weak.append((a, b))
        # Two pieces apart (the teapot's lid within 1-2 radii of its rim on a noisy cloud)
        # are linked only across their gap: even their closest points stay a gap apart,
        # where a shared border's interleave.
        apart = len(members) >= TOUCH_LEAST and float(
            gap_of[starts[p] : starts[p + 1]].min()) > TOUCH_GAP * radius
        if find_crossing and (apart or (share < EDGE_SHARE and rise >= EDGE_RISE)):
            crossing.append((a, b))
        elif span > BORDER_SPAN * radius:
            adjacency[(a, b)] = int(edge_count[p])
            borders[(a, b)] = border
        else:
            short[(a, b)] = (int(edge_count[p]), border)
    is_border = np.zeros(len(pts), dtype=bool)
    is_border[pt] = True
    return adjacency, borders, is_border, crossing + [(-1, -1)] + weak, short


def _crossing(
    pts: NDArray[np.float64], tree: cKDTree, lab: NDArray[np.int64], members: NDArray[np.int64],
    a: int, b: int,
) -> tuple[float, float]:
    """Whether segments ``a`` and ``b`` (border points ``members``) cross or touch instead of
    sharing a boundary: the smaller one-sidedness of the two (:func:`_one_sided`; below
    ``EDGE_SHARE`` the surface goes on past their border on one side) and the larger rise of
    one off the other's tangent plane (``EDGE_RISE`` or more where they cross: where a
    smooth surface goes on past a border through other segments, as past the corner that
    two diagonal patches of a 2 x 2 grid touch at, neither rises)."""
    (share_a, rise_a), (share_b, rise_b) = (
        _one_sided(pts, tree, lab, members, x, y) for x, y in ((a, b), (b, a))
    )
    return min(share_a, share_b), max(rise_a, rise_b)


def _one_sided(
    pts: NDArray[np.float64], tree: cKDTree, lab: NDArray[np.int64], members: NDArray[np.int64],
    label: int, other: int,
) -> tuple[float, float]:
    """How one-sided the surface is around a segment's border points with ``other``, and how
    far ``other``'s points rise off its tangent plane there (|height| / distance; medians
    over up to ``EDGE_SAMPLES`` of its ``members``, from their ``EDGE_NEIGHBOURS`` nearest
    points).

    One-sidedness: the offset of the neighbours that are not ``other``'s and lie within
    ``EDGE_SLAB`` of the segment's tangent plane (in that plane), over their mean distance.
    About 0.6 where the surface ends at the border (a half disc), near 0 where it goes on
    past it: the teapot's spout pierces its body, whose points (and its neighbour's, where the
    spout crosses a body seam) lie all round the piercing."""
    own = members[lab[members] == label]
    own = own[np.linspace(0, len(own) - 1, min(len(own), EDGE_SAMPLES)).astype(np.int64)]
    if not len(own):
        return 0.0, 0.0
    _, hood = tree.query(pts[own], k=min(EDGE_NEIGHBOURS, len(pts)))
    rel = pts[hood] - pts[own][:, None]

    def normals(mask: NDArray[np.bool_]) -> NDArray[np.float64]:
        # From the nearest few only: a hood as wide as the teapot's rim or spout is bent.
        m = (mask & (np.cumsum(mask, axis=1) <= NORMAL_NEIGHBOURS))[..., None]
        mean = (rel * m).sum(axis=1) / np.maximum(m.sum(axis=1), 1)
        centred = (rel - mean[:, None]) * m
        return np.linalg.eigh(np.einsum("pki,pkj->pij", centred, centred))[1][:, :, 0]

    normal = normals(lab[hood] == label)
    height = np.einsum("pki,pi->pk", rel, normal)
    dist = np.linalg.norm(rel, axis=2)
    w = ((lab[hood] != other) & (np.abs(height) <= EDGE_SLAB * dist)).astype(float)
    flat = rel - height[..., None] * normal[:, None]
    offset = (flat * w[..., None]).sum(axis=1) / np.maximum(w.sum(axis=1), 1)[:, None]
    size = (dist * w).sum(axis=1) / np.maximum(w.sum(axis=1), 1)
    share = float(np.median(np.linalg.norm(offset, axis=1) / np.maximum(size, 1e-300)))
    # Rise over the neighbours beyond half the hood (noise tilts the nearest), less the
    # segment's own there (the noise level).
    far = dist >= 0.5 * dist[:, -1:]
    slope = np.abs(height) / np.maximum(dist, 1e-300)
    theirs = (lab[hood] == other) & far
    mine = (lab[hood] == label) & far
    enough = (theirs.sum(axis=1) >= NORMAL_NEIGHBOURS // 2) & (mine.sum(axis=1) >= NORMAL_NEIGHBOURS // 2)
    if not enough.any():
        return share, 0.0
    rise = _row_median(slope[enough], theirs[enough])
    base = _row_median(slope[enough], mine[enough])
    return share, float(np.median(rise - base))


def _row_median(values: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Per row, the median of the finite ``values`` where ``mask`` holds (each row has one):
    ``np.nanmedian`` of the rows with NaN elsewhere, the same numbers without its
    masked-array path (which cost more than the rest of :func:`_one_sided`)."""
    ordered = np.sort(np.where(mask, values, np.inf), axis=1)
    count = mask.sum(axis=1)
    rows = np.arange(len(ordered))
    return 0.5 * (ordered[rows, (count - 1) // 2] + ordered[rows, count // 2])


# --------------------------------------------------------------------------- loops
def _drop_short_runs(
    state: NDArray[np.bool_], step_len: NDArray[np.float64], min_len: float, value: bool
) -> NDArray[np.bool_]:
    """``state`` of a closed loop with the runs of ``value`` shorter than ``min_len`` (sum of
    ``step_len``, the distance from each point to the next) flipped."""
    n = len(state)
    if state.all() or not state.any():
        return state
    start = np.flatnonzero(state != np.roll(state, 1))
    end = np.roll(start, -1)
    csum = np.concatenate([[0.0], np.cumsum(step_len)])
    length = np.where(end > start, csum[end] - csum[start], csum[n] - csum[start] + csum[end])
    out = state.copy()
    for a, b, run in zip(start, end, length):  # a few runs per loop
        if state[a] == value and run < min_len:
            out[np.arange(a, b if b > a else b + n) % n] = not value
    return out


def _turning(res: NDArray[np.float64], step: int) -> NDArray[np.float64]:
    """Turning angle of a closed loop at each sample, over ``step`` samples either side.

    Parameters
    ----------
    res : (m, 2) float
        The loop, evenly resampled along its arc length, closed implicitly.
    step : int
        Samples either side, ``1 <= step < m``.

    Returns
    -------
    (m,) float
        Angle in degrees, [0, 180], between ``res[i] - res[i - step]`` and
        ``res[i + step] - res[i]``.
    """
    ab = res - np.roll(res, step, axis=0)
    bc = np.roll(res, -step, axis=0) - res
    cross = ab[:, 0] * bc[:, 1] - ab[:, 1] * bc[:, 0]
    return np.degrees(np.arctan2(np.abs(cross), np.einsum("ij,ij->i", ab, bc)))


def _hemisphere(n: int) -> NDArray[np.float64]:
    """``n`` unit vectors spread evenly over the hemisphere z >= 0 (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1.0 - i / n
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    rho = np.sqrt(1.0 - z * z)
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


def sample_normals(
    pts: NDArray[np.float64], members: NDArray[np.int64], tree: cKDTree
) -> NDArray[np.float64]:
    """(n, 3) unoriented normals at up to ``FRAME_SAMPLES`` of a segment's points, spread
    over it: PCA of those of their ``FRAME_NEIGHBOURS`` nearest cloud points on their own
    sheet (:func:`~pde2cad.surfaces.sheets.same_sheet`)."""
    n_sample = min(FRAME_SAMPLES, len(members))
    sample = members[np.linspace(0, len(members) - 1, n_sample).astype(np.int64)]
    _, idx = tree.query(pts[sample], k=min(FRAME_NEIGHBOURS, len(pts)))
    # Only the sample's own sheet: on a thin lip the far side's points tilt the normal.
    w = same_sheet(pts, idx).astype(float)[:, :, None]
    mean = (w * pts[idx]).sum(axis=1, keepdims=True) / w.sum(axis=1, keepdims=True)
    hood = w * (pts[idx] - mean)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", hood, hood))
    return vectors[:, :, 0]  # smallest-variance direction of each neighbourhood


def _best_plane(normals: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """The plane normal (of ``FRAME_DIRECTIONS``) that maximises the ``FRAME_QUANTILE``
    quantile of ``|normal . plane normal|`` over ``normals``, and that quantile: the cosine
    of how close to edge-on the segment comes over its best plane."""
    dirs = _hemisphere(FRAME_DIRECTIONS)
    score = np.quantile(np.abs(normals @ dirs.T), FRAME_QUANTILE, axis=0)
    best = int(score.argmax())
    return dirs[best], float(score[best])


def plane_score(pts: NDArray[np.float64], members: NDArray[np.int64], tree: cKDTree) -> float:
    """:func:`_best_plane`'s quantile for a segment: near 1 on a flat one, ~0.3 on a
    band of a cylinder turning 150 degrees, 0.05-0.08 on one turning 180 degrees or more,
    which no plane sees as a height field."""
    return _best_plane(sample_normals(pts, members, tree))[1]


def _frame(
    pts: NDArray[np.float64], members: NDArray[np.int64], tree: cKDTree | None
) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
    """Origin and axes (rows: two in-plane axes, then the normal) of the plane a segment is
    projected on for its alpha shape: its PCA plane, unless the segment folds over it (see
    FOLD_COS), then the plane whose normal makes the smallest largest angle with the
    segment's normals; and whether the segment folds over that plane too (no plane fits)."""
    origin, axes = pca_frame(pts[members])
    if tree is None:
        return origin, axes, False
    normals = sample_normals(pts, members, tree)
    if np.quantile(np.abs(normals @ axes[2]), FRAME_QUANTILE) >= FOLD_COS:
        return origin, axes, False
    best, score = _best_plane(normals)
    if score < FRAME_ACCEPT:
        # No plane keeps it a height field (the teapot's rim: its cross-section turns by
        # ~175 degrees); an arbitrary tilted one would fold it worse than the PCA plane.
        return origin, axes, True
    normal = best
    # In-plane axes: PCA of the points projected on the plane.
    flat = pts[members] - origin
    flat -= np.outer(flat @ normal, normal)
    _, vec = np.linalg.eigh(flat.T @ flat)
    u = vec[:, 2]
    u *= np.sign(u[np.abs(u).argmax()])
    v = np.cross(normal, u)
    return origin, np.vstack([u, v, normal]), False


def _unfold(
    pts: NDArray[np.float64],
    members: NDArray[np.int64],
    lab: NDArray[np.int64],
    tree: cKDTree,
    radius: float,
    along: NDArray[np.float64],
    is_border: NDArray[np.bool_],
) -> NDArray[np.float64] | None:
    """2D coordinates of a segment that fits no plane (a strip folded across its width, like
    the teapot's rim, or a band of a wall bending round in its own plane): the geodesic
    distance (shortest path in its own neighbour graph) from one run of its border with the
    segment it shares the most border points with, and the geodesic distance from one end of
    that run (the coordinate ``along`` its main axis where that graph falls apart). None when
    it has no border or the graph falls apart."""
    own = pts[members]
    dist, idx = cKDTree(own).query(own, k=UNFOLD_NEIGHBOURS + 1, distance_upper_bound=radius)
    ok = np.isfinite(dist[:, 1:])
    rows = np.repeat(np.arange(len(members)), UNFOLD_NEIGHBOURS)[ok.reshape(-1)]
    cols = idx[:, 1:][ok]
    border = np.flatnonzero(is_border[members])
    if not border.size:
        return None
    _, hood = tree.query(own[border], k=UNFOLD_NEIGHBOURS + 1, distance_upper_bound=radius)
    found = hood < len(pts)
    other = np.where(found, lab[np.where(found, hood, 0)], lab[members[0]])
    other_lab = other[other != lab[members[0]]]
    if not other_lab.size:
        return None
    values, counts = np.unique(other_lab, return_counts=True)
    seeds = border[(other == values[counts.argmax()]).any(axis=1)]
    graph = coo_matrix((dist[:, 1:][ok], (rows, cols)), shape=(len(members),) * 2).tocsr()
    # One run of that border: from both seams of a half tube (the teapot's handle halves
    # meet along two), the distance would fold the strip at its middle.
    link = cKDTree(own[seeds]).query_pairs(2 * radius, output_type="ndarray")
    comp = _components(len(seeds), link[:, 0].astype(np.int64), link[:, 1].astype(np.int64))
    seeds = seeds[comp == np.bincount(comp).argmax()]
    geo = dijkstra(graph, directed=False, indices=seeds, min_only=True)
    # Along the strip: the main axis, unless the run bends round too far for it (its
    # extent along the axis under BENT_RUN x its length: a band of a C-shaped wall turning
    # 300 degrees, which the axis folds); then the geodesic distance from one end of the
    # run (it skews the run's ends, so the teapot's rim quarters keep the axis).
    from_seed = dijkstra(graph, directed=False, indices=int(seeds[0]))
    end = int(seeds[np.argmax(np.where(np.isfinite(from_seed[seeds]), from_seed[seeds], -1.0))])
    run = dijkstra(graph, directed=False, indices=end)
    length = float(np.max(np.where(np.isfinite(run[seeds]), run[seeds], 0.0)))
    if float(np.ptp(own[seeds] @ along)) >= BENT_RUN * length:
        run = own @ along
    reached = np.isfinite(geo) & np.isfinite(run)
    if reached.mean() < UNFOLD_REACHED:
        return None
    # Crumbs apart from the strip (a few points a cut left beyond a neighbour) sit where
    # their nearest strip point does: the loop is the strip's.
    _, near = cKDTree(own[reached]).query(own[~reached])
    uv = np.column_stack([run, geo])
    uv[~reached] = uv[reached][near]
    return uv


def _loop_candidates(
    pts: NDArray[np.float64],
    members: NDArray[np.int64],
    is_border: NDArray[np.bool_],
    radius: float,
    tree: cKDTree | None = None,
    lab: NDArray[np.int64] | None = None,
    memo: dict[tuple[object, ...], object] | None = None,
) -> tuple[
    NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_],
    NDArray[np.bool_], NDArray[np.int64],
]:
    """Open-boundary loop points and corner candidates (b), (c) of one segment.

    Returns indices into ``pts``: the open loop points (loop order), the (b) candidates, the
    (c) candidates (turns), whether each turn lies on the open boundary (not on a border),
    whether it turns by CORNER_ANGLE at the coarse scale too, and the whole loop. The frame
    and the loop of a segment that is not folded depend on its points alone and are kept
    in ``memo`` (:func:`cloud_memo`).
    """
    key = ("loop", members.tobytes())
    if memo is not None and key in memo:
        uv, local = cast("tuple[NDArray[np.float64], NDArray[np.int64]]", memo[key])
    else:
        origin, axes, folded = _frame(pts, members, tree)
        uv = (pts[members] - origin) @ axes[:2].T
        if folded and tree is not None and lab is not None:
            unfolded = _unfold(pts, members, lab, tree, radius, axes[0], is_border)
            uv = uv if unfolded is None else unfolded
        local = boundary_loop(uv)
        if memo is not None and not folded:
            memo[key] = (uv, local)
    loop = members[local]
    n = len(loop)
    border = is_border[loop]
    # Runs of the border/open state shorter than RUN_FACTOR x radius (arc length) are noise:
    # the alpha shape dips up to ~2.5 radii into a randomly sampled segment, leaving loop
    # points without a neighbour of the other label in the middle of a border. Short open
    # runs become border first (joining the border), then short border runs become open.
    step_len = np.linalg.norm(np.roll(pts[loop], -1, axis=0) - pts[loop], axis=1)
    border = _drop_short_runs(border, step_len, RUN_FACTOR * radius, False)
    border = _drop_short_runs(border, step_len, RUN_FACTOR * radius, True)
    change = np.flatnonzero(border != np.roll(border, 1))
    # (b): both loop points at each switch (one on each side of it).
    trans = np.concatenate([loop[change], loop[change - 1]])
    # (c): sharp turns of the loop, measured on an arc-length resampling.
    loop2d = uv[local]
    closed = np.vstack([loop2d, loop2d[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    m = LOOP_SAMPLES
    s = np.arange(m) * (arc[-1] / m)
    res = np.stack([np.interp(s, arc, closed[:, d]) for d in range(2)], axis=1)
    step = max(1, m // TURN_STEPS)
    angle = _turning(res, step)
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
    tip = height.argmax(axis=1) if len(peaks) else np.zeros(0, dtype=np.int64)
    # A corner turns over any arc around it; the alpha shape of a noisy sample wobbles by a
    # few noise deviations over a few alpha radii, which can turn >= CORNER_ANGLE over
    # +-step but not over COARSE_TURN x as much (where the outline continues straight).
    coarse = _turning(res, min(COARSE_TURN * step, (m - 1) // 2))[peaks] >= CORNER_ANGLE
    return loop[~border], trans, loop[tip], ~border[tip], coarse, loop


# --------------------------------------------------------------------------- main
def build_layout(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    k: int = 12,
    min_points: int = 50,
    check: bool = True,
    crossing: Iterable[tuple[int, int]] = (),
    find_crossing: bool = True,
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
    crossing : iterable of (int, int)
        Label pairs known to cross or touch without sharing a boundary (pieces of segments
        that an earlier layout found crossing), besides those found here.
    find_crossing : bool
        Look for such pairs (``False``: only ``crossing`` cross; pieces of segments bounded
        by sharp edges, where a short border of a hole's wall piece near the corners of the
        face's pieces reads as a wall rising through a face that goes on past it).

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
    The algorithm and its constants are described in the module docstring. 10^6 points in
    6-16 segments take ~3-4 s on 2 cores: the k-d tree, voxel binning and one alpha shape
    per segment (on a band of ~25 % of its points, the segments on parallel threads).
    """
    pts, lab = _inputs(points, labels)
    known = list(crossing)
    if k < 3:
        raise InputError(f"k must be >= 3 neighbours, got {k}")
    present, counts = np.unique(lab, return_counts=True)
    if len(pts) <= k:
        raise InputError(f"the cloud has {len(pts)} points; it needs more than k = {k}")
    tree, spacing, radius = _neighbours(pts, k)
    vox = _voxels(pts, radius)
    _check_segments(lab, present, counts, vox, min_points)
    memo = cloud_memo(pts)
    order = np.argsort(lab, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(counts)])
    digest = {int(label): zlib.crc32(order[bounds[s] : bounds[s + 1]].tobytes())
              for s, label in enumerate(present)}

    # k-NN only of the points that can have a neighbour of another label (near borders): the
    # cross edges and the (a) candidates are the same as from the k-NN of every point.
    near = _mixed_points(vox, lab)
    dist, idx = tree.query(pts[near], k=k + 1, workers=-1)
    dist, idx = dist[:, 1:], idx[:, 1:].astype(np.int64)
    valid = dist <= radius

    adjacency, borders, is_border, crossing, short = _borders(
        pts, tree, lab, present, near, idx, valid, radius, memo, digest, find_crossing)
    weak = crossing[crossing.index((-1, -1)) + 1 :]
    crossing = crossing[: crossing.index((-1, -1))] + [
        (a, b) for a, b in known if a in present and b in present
    ]
    cut = np.zeros((len(present),) * 2, dtype=bool)
    if crossing:
        # Segments that cross or touch without sharing a boundary (the teapot's handle and
        # spout pierce its body): no border, their points are no border points either.
        rank = np.searchsorted(present, lab)
        for a, b in crossing:
            cut[np.searchsorted(present, a), np.searchsorted(present, b)] = True
        cut |= cut.T
        # ... nor with the neighbours of those: where the handle's end crosses a seam of
        # the body, one side of it may read as a touch in the plane (no rise).
        adj = np.zeros_like(cut)
        for a, b in adjacency:
            adj[np.searchsorted(present, a), np.searchsorted(present, b)] = True
        adj &= ~cut
        adj |= adj.T
        spread = (adj.astype(np.int64) @ cut.astype(np.int64)) > 0
        # (unless they share a border that ends the surface on both sides).
        loose = np.zeros_like(cut)
        for a, b in weak:
            loose[np.searchsorted(present, a), np.searchsorted(present, b)] = True
        cut |= (spread | spread.T) & (~adj | loose | loose.T)
        valid &= ~cut[rank[near][:, None], rank[idx]]
        adjacency, borders, is_border, _, short = _borders(pts, tree, lab, present, near, idx, valid, radius, memo, digest)

    # (a) points whose neighbourhood (with themselves) holds >= 3 labels ...
    own = lab[near]
    hood = np.where(valid, lab[idx], own[:, None])
    hood = np.sort(np.column_stack([own, hood]), axis=1)
    n_distinct = 1 + (np.diff(hood, axis=1) != 0).sum(axis=1)
    # ... or whose neighbourhood holds 2 labels and that of one of its neighbours 2 others: a
    # sparse random sample can leave no point that sees all three segments of a junction.
    rank = np.searchsorted(present, hood[:, [0, -1]])
    pair = np.where(n_distinct == 2, rank[:, 0] * len(present) + rank[:, 1], -1)
    pair_of = np.full(len(pts), -1, dtype=np.int64)
    pair_of[near] = pair
    other = np.where(valid, pair_of[idx], -1)
    junction = near[n_distinct >= 3]
    sparse = near[(pair >= 0) & ((other >= 0) & (other != pair[:, None])).any(axis=1)]
    if junction.size and sparse.size:
        # Only where the neighbourhoods miss the junction: next to one they would spread its
        # candidates by a radius each way, and close junctions would chain into one.
        far, _ = cKDTree(pts[junction]).query(
            pts[sparse], distance_upper_bound=BORDER_SPAN * radius
        )
        sparse = sparse[np.isinf(far)]
    junction = np.concatenate([junction, sparse])

    # (b), (c) and the open boundary from each segment's loop.
    open_boundary: dict[int, NDArray[np.float64]] = {}
    loops: dict[int, NDArray[np.int64]] = {}

    def segment_loop(
        s: int,
    ) -> tuple[
        NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_],
        NDArray[np.bool_], NDArray[np.int64],
    ]:
        members = order[bounds[s] : bounds[s + 1]]  # increasing: the sort is stable
        try:
            return _loop_candidates(pts, members, is_border, radius, tree, lab, memo)
        except InputError as exc:
            raise InputError(f"segment {int(present[s])}: {exc}") from exc

    # Threads: Delaunay (qhull) and most of numpy release the GIL. map() yields in segment
    # order and re-raises the first failing segment's error.
    workers = min(len(present), os.cpu_count() or 1, MAX_THREADS)
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        ends, turns, turns_open, turns_coarse = [], [], [], []
        for label, (open_pts, trans, turn, turn_open, coarse, loop) in zip(
            present, pool.map(segment_loop, range(len(present)))
        ):
            open_boundary[int(label)] = pts[open_pts]
            loops[int(label)] = loop
            ends.append(trans)
            turns.append(turn)
            turns_open.append(turn_open)
            turns_coarse.append(coarse)
    end = np.concatenate(ends)
    fixed = np.concatenate([junction, end])  # (a) and (b)
    turn, turn_open = _confirm_turns(
        pts, lab, np.concatenate(turns), np.concatenate(turns_open),
        np.concatenate(turns_coarse), CLUSTER_FACTOR * radius,
    )
    if fixed.size and turn.size:
        # A turn this close to a junction or to a border's end is that corner (already a
        # candidate) or a noise kink of a border next to it, which would merge into it and
        # move it; either way it adds nothing.
        far, _ = cKDTree(pts[fixed]).query(pts[turn], distance_upper_bound=BORDER_SPAN * radius)
        turn, turn_open = turn[np.isinf(far)], turn_open[np.isinf(far)]
    # Candidates on the open boundary: (b), and (c) on an open run of a loop.
    cand, inverse = np.unique(np.concatenate([fixed, turn]), return_inverse=True)
    on_open = np.r_[np.zeros(len(junction), dtype=bool), np.ones(len(end), dtype=bool), turn_open]
    on_open = np.bincount(inverse.reshape(-1), weights=on_open, minlength=len(cand)) > 0

    # The segments each candidate touches: its own and its neighbours' within the radius.
    seen = np.zeros((len(cand), len(present)), dtype=bool)
    if cand.size:
        _, hood_idx = tree.query(pts[cand], k=k + 1, distance_upper_bound=radius, workers=-1)
        row = np.repeat(np.arange(len(cand)), k + 1)
        hit = hood_idx.reshape(-1) < len(pts)
        seen[row[hit], np.searchsorted(present, lab[hood_idx.reshape(-1)[hit]])] = True
        # Not the segments its own crosses: the spout's rim corners are none of the body's.
        seen &= ~cut[np.searchsorted(present, lab[cand])]
    # ... and the segments adjacent to those (a sparse junction's candidates can miss one).
    near_seg = np.eye(len(present), dtype=bool)
    for a, b in adjacency:
        ia, ib = np.searchsorted(present, [a, b])
        near_seg[ia, ib] = near_seg[ib, ia] = True
    corners, open_corners, touched = _cluster(
        pts, tree, cand, CLUSTER_FACTOR * radius, BORDER_SPAN * radius, on_open, seen, near_seg,
        radius,
    )
    touches = (touched.astype(np.int64) @ near_seg.astype(np.int64)) > 0
    segment_corners = _assign(
        tree, lab, present, corners, CLUSTER_FACTOR * radius, touches, radius, touched
    )
    # A border too short for the span test is one all the same where the two segments share
    # two distinct corners, its ends (the teapot rim's 0.3-long seams, sparsely sampled).
    for (a, b), (count, border) in short.items():
        common = sorted(set(segment_corners[a].tolist()) & set(segment_corners[b].tolist()))
        if len(common) == 2 and np.linalg.norm(corners[common[0]] - corners[common[1]]) >= CLUSTER_FACTOR * radius:
            adjacency[(a, b)] = count
            borders[(a, b)] = border
    _end_borders(borders, corners, segment_corners, radius)
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
        loops=loops,
        tree=tree,
        open_corners=open_corners,
        crossing=frozenset(
            (int(present[i]), int(present[j])) for i, j in zip(*np.nonzero(np.triu(cut)))
        ),
    )


def _end_borders(
    borders: dict[tuple[int, int], NDArray[np.float64]], corners: NDArray[np.float64],
    segment_corners: dict[int, NDArray[np.int64]], radius: float,
) -> None:
    """Give each border that ends at only one corner of both its segments its other end
    (in place): the corner of either segment nearest the border's far end, within
    ``BORDER_SPAN`` radii of it, is made a corner of the other segment too.

    Where a sliver meets a junction (two junctions of four segments a border's span apart,
    merged into one corner), the corner goes to the segments seen around one junction only,
    and the side of a segment across the sliver then ends at no corner: "found 3 edges for
    its 4 corners" on k-means capsules and split sphere layouts. A border shorter than
    ``BORDER_SPAN`` radii beyond its one common corner (diagonal pieces touching at a
    corner) is left alone."""
    reach = BORDER_SPAN * radius
    for (a, b), border in borders.items():
        common = set(segment_corners[a].tolist()) & set(segment_corners[b].tolist())
        if len(common) != 1 or not len(border):
            continue
        here = corners[next(iter(common))]
        far = border[int(np.argmax(np.linalg.norm(border - here, axis=1)))]
        if np.linalg.norm(far - here) < reach:
            continue
        own = sorted((set(segment_corners[a].tolist()) | set(segment_corners[b].tolist())) - common)
        if not own:
            continue
        gap = np.linalg.norm(corners[own] - far, axis=1)
        if gap.min() > reach or np.linalg.norm(corners[own[int(np.argmin(gap))]] - here) < reach:
            continue
        c = own[int(np.argmin(gap))]
        for label in (a, b):
            if c not in segment_corners[label]:
                segment_corners[label] = np.sort(np.r_[segment_corners[label], c])


def _confirm_turns(
    pts: NDArray[np.float64],
    lab: NDArray[np.int64],
    turn: NDArray[np.int64],
    turn_open: NDArray[np.bool_],
    coarse: NDArray[np.bool_],
    reach: float,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """The (c) candidates that are corners, and whether each lies on the open boundary.

    A turn of an open run must turn at the coarse scale too (``coarse``). A turn on a border
    is a corner of the segments on both sides, so the loop of another segment must turn
    within ``reach`` as well (noise bends one loop at a time), and at the coarse scale (the
    projection of a strongly curved segment can bend both loops a little); or the loops of
    two other segments must turn there: a junction of three, whatever the scale.
    """
    kink = np.flatnonzero(~turn_open)
    keep = turn_open & coarse
    if kink.size:
        pairs = cKDTree(pts[turn[kink]]).query_pairs(reach, output_type="ndarray")
        i = kink[np.concatenate([pairs[:, 0], pairs[:, 1], np.arange(len(kink))])]
        j = kink[np.concatenate([pairs[:, 1], pairs[:, 0], np.arange(len(kink))])]
        # Distinct labels of the border turns within reach of each (itself included).
        seen = np.unique(np.column_stack([i, lab[turn[j]]]), axis=0)
        n_seen = np.bincount(seen[:, 0], minlength=len(turn))
        keep[kink] = ((n_seen[kink] >= 2) & coarse[kink]) | (n_seen[kink] >= 3)
    return turn[keep], turn_open[keep]


def _cluster(
    pts: NDArray[np.float64], tree: cKDTree, cand: NDArray[np.int64], dist: float,
    merge: float = 0.0, mark: NDArray[np.bool_] | None = None,
    seen: NDArray[np.bool_] | None = None,
    near_seg: NDArray[np.bool_] | None = None,
    radius: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """One corner per cluster of candidate points (single linkage within ``dist``, then
    clusters whose centroids lie within ``merge`` joined; either only when related, see
    ``near_seg``).

    Parameters
    ----------
    pts : (N, 3) float
    tree : cKDTree
        Of ``pts``.
    cand : (M,) int
        Candidate points.
    dist, merge : float
        Linkage and merge distances.
    mark : (M,) bool, optional
        A flag per candidate (default none).
    seen : (M, S) bool, optional
        The segments each candidate touches (default: all).
    near_seg : (S, S) bool, optional
        Which segments are the same or adjacent (default: the identity). Candidates are
        linked, and clusters merged, only when one touches a segment that the other touches
        or is adjacent to: two corners
        of unrelated segments, such as the lid's and the rim's of the Utah teapot across
        their 0.1 gap, are no ends of one short border.
    radius : float, optional
        The neighbour radius: when given, candidates are linked only when a path along the
        surface joins them within ``GEODESIC_SLACK`` x their distance
        (:func:`surface_distances`).

    Returns
    -------
    corners : (C, 3) float
        The cloud point nearest each cluster's centroid.
    marked : (C,) bool
        Whether the cluster holds a candidate with ``mark`` set.
    touched : (C, S) bool
        The segments the cluster's candidates touch (within the radius of one of them).
    """
    n_seg = 1 if seen is None else seen.shape[1]
    if not cand.size:
        return np.zeros((0, 3)), np.zeros(0, dtype=bool), np.zeros((0, n_seg), dtype=bool)
    mark = np.zeros(len(cand), dtype=bool) if mark is None else np.asarray(mark, dtype=bool)
    seen = np.ones((len(cand), 1), dtype=bool) if seen is None else seen
    near_seg = np.eye(seen.shape[1], dtype=bool) if near_seg is None else near_seg
    pairs = cKDTree(pts[cand]).query_pairs(dist, output_type="ndarray")
    if len(pairs) and seen.shape[1] > 1:
        # Linked only when related (see ``near_seg``), like the merge below.
        reach_of = (seen.astype(np.int64) @ near_seg.astype(np.int64)) > 0
        pairs = pairs[(seen[pairs[:, 0]] & reach_of[pairs[:, 1]]).any(axis=1)]
    if len(pairs) and radius is not None:
        along = surface_distances(
            pts, tree, cand[pairs[:, 0]], cand[pairs[:, 1]], GEODESIC_SLACK * dist, radius
        )
        chord = np.linalg.norm(pts[cand[pairs[:, 0]]] - pts[cand[pairs[:, 1]]], axis=1)
        keep = along <= np.maximum(GEODESIC_SLACK * chord, chord + 0.5 * radius)
        # An open-boundary candidate and another (see the merge below) only when close.
        keep &= (mark[pairs[:, 0]] == mark[pairs[:, 1]]) | (chord <= MIXED_LINK * radius)
        pairs = pairs[keep]
    comp = _components(len(cand), pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64))

    def centroids(comp: NDArray[np.int64]) -> NDArray[np.float64]:
        n = int(comp.max()) + 1
        size = np.bincount(comp, minlength=n)
        sums = np.stack([np.bincount(comp, pts[cand, d], minlength=n) for d in range(3)], axis=1)
        return sums / size[:, None]

    def touching(comp: NDArray[np.int64]) -> NDArray[np.bool_]:
        out = np.zeros((int(comp.max()) + 1, seen.shape[1]), dtype=bool)
        np.logical_or.at(out, comp, seen)
        return out

    centroid = centroids(comp)
    if merge > dist and len(centroid) > 1:
        close = cKDTree(centroid).query_pairs(merge, output_type="ndarray")
        if len(close):
            touch = touching(comp)
            reach = (touch.astype(np.int64) @ near_seg.astype(np.int64)) > 0
            close = close[(touch[close[:, 0]] & reach[close[:, 1]]).any(axis=1)]
            # A marked (open-boundary) corner and an unmarked one are both corners: the
            # teapot rim's inner corners lie 0.1 (< 4 r at 300k points) from its outer ones,
            # at the ends of its 0.3-long seams.
            flag = np.bincount(comp, weights=mark, minlength=len(centroid)) > 0
            close = close[flag[close[:, 0]] == flag[close[:, 1]]]
        if len(close):
            joined = _components(len(centroid), close[:, 0].astype(np.int64), close[:, 1].astype(np.int64))
            comp = joined[comp]
            centroid = centroids(comp)
    _, nearest = tree.query(centroid)
    marked = np.bincount(comp, weights=mark, minlength=len(centroid)) > 0
    return pts[nearest], marked, touching(comp)


def _assign(
    tree: cKDTree,
    lab: NDArray[np.int64],
    present: NDArray[np.int64],
    corners: NDArray[np.float64],
    dist: float,
    touches: NDArray[np.bool_] | None = None,
    radius: float | None = None,
    touched: NDArray[np.bool_] | None = None,
) -> dict[int, NDArray[np.int64]]:
    """Corners within ``dist`` of at least one point of each segment (and, with ``touches``,
    (C, S) bool, among the segments the corner's candidates touch or that are adjacent to
    those: a corner of the teapot's rim lies within ``dist`` of the lid across their gap,
    but is none of the lid's). With ``radius``, ``dist`` is measured along the surface
    (:func:`surface_reach`): the rim's inner corners are no corners of the body 0.1 below.
    With ``touched`` (C, S) bool, also the segments a candidate of the corner touched itself,
    however far the merged cluster's centroid lies: two junctions of four segments a border
    apart merge into one corner that lay 2.5 radii from one of them (k-means capsule), whose
    sides then met at no corner."""
    out: dict[int, list[int]] = {int(label): [] for label in present}
    if touched is not None:
        for c, s in zip(*np.nonzero(touched)):
            out[int(present[s])].append(int(c))
    if len(corners):
        if radius is None:
            near = tree.query_ball_point(corners, dist)
        else:
            near = surface_reach(tree.data, tree, corners, dist, radius)
        for c, rows in enumerate(near):  # one small list per corner, not per point
            for label in np.unique(lab[np.asarray(rows, dtype=np.int64)]):
                if touches is None or touches[c, np.searchsorted(present, label)]:
                    out[int(label)].append(c)
    return {label: np.asarray(sorted(set(v)), dtype=np.int64) for label, v in out.items()}
