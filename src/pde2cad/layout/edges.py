"""Edge network of a segmented cloud: refined corners and one smooth curve per edge.

:func:`~pde2cad.layout.adjacency.build_layout` finds which segments touch and roughly where
their corners are (cloud points, up to a neighbour radius off). This module turns that into
the curves the patches share:

1. **Corners.** Layout corners on a border between exactly two segments, away from the open
   boundary, are kinks of a border, not patch corners: they are dropped.
2. **Topology.** Two adjacent segments share exactly two corners: the ends of their common
   edge. A segment's open edges are the runs of its open-boundary loop between its corners.
   Each segment's edges must form one cycle through all its corners (its side loop).
3. **Edge data.** A shared edge is fitted to the *midline* of the border band: the midpoint
   of each border point and its nearest border point of the other segment. An open edge is
   fitted to its rim, estimated from the segment's samples near its open-boundary run
   (:mod:`pde2cad.surfaces.rim`: the run itself lies about half a spacing inside).
4. **Free fits.** Each edge gets a clamped cubic B-spline with ``2**j`` uniform spans, the
   count chosen by the Bayesian information criterion (enough spans for the shape, not so
   many that it follows the sampling noise), with closest-point reparameterization.
5. **Corner refinement.** A corner is moved to the least-squares meeting point of the end
   tangent lines of its edges' free fits, then projected onto a quadric fitted to the cloud
   around it, which also gives the corner's normal. On random samples this puts corners well
   inside a sample spacing of the truth, where the nearest cloud point may be a spacing off.
6. **Joint fit.** All edges are refitted together with their ends on the refined corners and
   their end tangents in the corner's tangent plane. Where the edges through a corner pair
   up (four patches meeting, or two patches meeting the open boundary), opposite edges leave
   it in opposite directions, each at a speed scaled to its own length (a short edge made
   to start at a long one's speed overshoots and folds back), with the speed ratio of a pair
   kept equal along each line of paired edges (:func:`_pair_scales`): the layout that lets
   :mod:`pde2cad.layout.ribbons` build G1 joins. Where an odd number of patches meet
   (three on a cube-sphere) no such pairing exists (the vertex-enclosure problem).

Uniform spans with a power-of-two count give dyadic breaks, so an edge reversed for the
neighbour has the exact same breaks and both faces carry bitwise-identical edge poles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline
from scipy.sparse import coo_matrix, identity
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.layout.adjacency import CLUSTER_FACTOR, Layout
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.rim import locate_rim, sample_spacing
from pde2cad.surfaces.sheets import SHEET_STRETCH, one_sheet, same_sheet

Key = tuple[int, int]

#: Fewest rim stations along an open edge (closer than RIM_STEP spacings on short edges:
#: the end tangent lines are quadratics through the stations near each end). With under
#: half of them (windows too sparse) the edge keeps its loop run.
RIM_STATIONS = 12
#: Candidate span counts of an edge curve (powers of two keep the breaks dyadic).
SPAN_CHOICES = (1, 2, 4, 8, 16)
#: Most edge data points the span choice looks at (an even subsample of the rest).
SPAN_SAMPLE = 1500
#: Fewest data points per span.
POINTS_PER_SPAN = 6
#: A corner is an end of an open run when the segment's open-boundary loop passes within
#: OPEN_REACH x the gap (CLUSTER_FACTOR x radius) of it: a noisy tube cut into sectors rotated
#: off the sampling axes had a rim corner at 1.0004 x the gap from its sparse loop (its open
#: edge went missing). Below BORDER_SPAN / CLUSTER_FACTOR = 1.6: a corner that far from the
#: open boundary lies a border's length inside.
OPEN_REACH = 1.25
INNER_REACH = 0.5
#: Edge data whose chord parameters differ from their share of the path along the data by
#: more than FOLDED_EDGE somewhere are parameterized along the data (points ARC_LINK radii
#: apart linked).
FOLDED_EDGE = 0.2
ARC_LINK = 1.0
#: Closest-point reparameterization rounds per fit.
REPARAM_ROUNDS = 3
#: Border data closer than this many neighbour radii to a rough corner is ignored by the
#: free fits (near a junction the midline of one pair is disturbed by the third segment).
END_TRIM = 1.0
#: End tangent lines come from the edge data within max(END_REACH x radius,
#: END_SHARE x chord) of the corner.
END_REACH = 6.0
END_SHARE = 0.1
#: Most turn of an end's quadratic over its reach (degrees), and the shortest reach (radii)
#: it is shortened to when it turns more.
END_TURN = 60.0
END_LEAST = 2.0
#: Corners move at most this many neighbour radii in the refinement.
MAX_CORNER_MOVE = 3.0
#: Reweighting rounds of the robust meeting point of the end tangent lines, and its scale
#: (neighbour radii): a line further than this from the meeting point counts at most half.
LINE_ROUNDS = 5
LINE_SCALE = 0.25
#: An end tangent line extrapolated over a data gap ``g`` to its corner (no data within
#: ``g`` of it) gets weight ``min(1, (EXTRAPOLATION x radius / g)**2)`` in the meeting point.
EXTRAPOLATION = 2.0
#: Quadric fitted to the cloud within this many neighbour radii of a corner.
QUADRIC_RADIUS = 3.0
#: Edges through a corner are paired when their free fits turn by less than this (degrees).
PAIR_ANGLE = 60.0
#: Edge data points averaged per station of the edge's length (:func:`_data_length`).
LENGTH_BIN = 8
#: Pairs linked along a line of regular edges share their mean length ratio when their own
#: ratios lie within this factor of each other (each then runs within sqrt(2) of its own
#: ratio, far from the 3x overshoot of :func:`_pair_scales`); wider spreads keep their own
#: (k-means capsule: a 3.75 ratio averaged to 0.83 and the short edge turned 90 deg).
PAIR_SPREAD = 2.0
#: A pair's speed ratio is its length ratio divided by up to PAIR_SLACK (1 below it): each
#: edge then runs within 1.5x of its own length's speed, half the 3x at which it folds, and
#: near-equal pairs keep one speed (C1, not only G1: automatic torus_npm layout, 138
#: patches, seam 0.76 deg with one speed, 0.98 with every pair scaled).
PAIR_SLACK = 1.5
#: A corner is smooth when its segments' own local quadrics give normals at the corner within
#: SMOOTH_ANGLE degrees, or when one quadric over all its segments' nearby points leaves an RMS
#: residual below SMOOTH_RATIO x that of a quadric per segment (or below SMOOTH_FLOOR x the
#: reach: clean smooth data leave both near zero). Its edges are then paired by topology alone
#: (the end directions of the free fits can be wrong where four borders crowd together).
SMOOTH_ANGLE = 40.0
SMOOTH_RATIO = 1.5
SMOOTH_FLOOR = 0.01
#: Border points are paired with the nearest point across the border when it lies within
#: this many spacings; their midpoints trace the border. A point deeper in the band pairs with
#: a point near the border's foot and its midpoint sits half its depth off the border.
#: The median pair is ~3 spacings long: 2.5 kept a third of the pairs (10-15 midpoints per
#: edge on a 3000-point cube-sphere, the nearest up to 70 % of the edge from a corner, so the
#: end lines were extrapolated and corners moved 3 radii off). 4.5 keeps ~90 %; measured at
#: 20k points it also moves corners closer to the truth (sphere6: max 0.011 -> 0.007 of the
#: diagonal).
PAIR_REACH = 4.5
#: A shared edge is a crease when its two segments' own surfaces (local quadrics) meet at more
#: than this angle (degrees) along it (median over its data): its samples go onto their
#: intersection, not onto one quadric fitted across both (which rounds the crease off).
#: Measured medians: smooth seams <= 15 deg at 0.4 % noise, the pot's 56-deg crease >= 50.
CREASE_ANGLE = 25.0
#: ... and, between two corners that are both smooth (``_smooth_corners``), more than this
#: (a crease lost in the noise at both corners still reads 50-90 deg along its length).
CREASE_SURE = 50.0
#: The one-sided surfaces use the segment's points within this many radii of the queries.
SHEET_REACH = 4.0
#: Cloud neighbours of the one-sided quadrics that test an edge for a crease.
CREASE_NEIGHBOURS = 120
#: Data points per edge (at most) used to test it for a crease.
CREASE_SAMPLES = 32
#: Newton rounds of the projection onto the intersection of the segments' surfaces.
CREASE_ROUNDS = 4
#: Relative singular value below which two segments' tangent planes count as one (a smooth
#: pair of segments at a crease corner constrains one direction, not two).
PLANE_RCOND = 0.2
#: Cloud neighbours of the quadric that projects edge samples onto the surface.
MLS_NEIGHBOURS = 40
#: Edge samples per span projected onto the surface for the final fit.
SAMPLES_PER_SPAN = 24
#: Most spans of the first fit of a seam cut through a smooth segment (see build_edges): a
#: cut has no shape of its own to follow, and the spans its wandering border data buy bend
#: the patches on both sides (a filleted box's side band: cut edges wandering 0.09 across
#: a flat face with 16 spans, Coons normals tilted up to 60 deg).
CUT_SPANS = 2
#: Polyline points per edge that measure its arc length (see _arc_params).
ARC_SAMPLES = 512
#: Crease edges (fitted at arc-length parameters) get this many times the spans of a free
#: fit: a cubic keeps a quarter circle to ~1e-6 of its radius over 4 spans when free to
#: choose its speed, only ~1e-4 at arc length (a can's rims: 1.3e-4 of the diagonal; with
#: 8 spans, 5e-5).
ARC_SPAN_FACTOR = 2
#: Fewest spans of the final (projected) edge fit: its data are smooth samples on the surface.
MIN_FINAL_SPANS = 4
#: Weight of the squared third-derivative jumps at an edge's end knots in the joint fit of
#: the border data, per data point per control point (see :func:`_joint_fit`). Sparse
#: cube-spheres (3000 points): end hooks 15-28 deg -> <= 5 deg, seams 7.0 -> 0.5 deg; no
#: effect above 0.3 on dense clouds. The final fit of the projected samples (smooth samples
#: of the fitted curve) needs none.
FAIRNESS = 1.0
#: Relative ridge of the joint least squares (keeps spans without data well defined).
RIDGE = 1e-9


@dataclass
class EdgeNetwork:
    """Corners, side loops and the shared curve of every edge.

    Attributes
    ----------
    corners : (C, 3) float
        Refined corner positions.
    normals : (C, 3) float
        Unit surface normal at each corner (orientation arbitrary).
    loops : dict[int, list[int]]
        Per segment label, its corner ids in side-loop order.
    curves : dict[(int, int), PiecewiseBezier]
        Per edge (sorted corner-id pair), the curve from the smaller id to the larger.
    users : dict[(int, int), list[int]]
        Segment labels using each edge (one for an open edge, two for a shared one).
    errors : dict[(int, int), float]
        Largest distance of the edge's data (border midline or open run) to its curve.
    rms : dict[(int, int), float]
        Root-mean-square of the same distances.
    pairs : dict[int, list[((int, int), (int, int))]]
        Per corner, the edges paired across it (opposite end directions; speeds in the
        ratio ``scales`` gives).
    regular : dict[int, bool]
        Whether each corner admits the pairing (every edge in at most one pair).
    spans : dict[(int, int), int]
        Uniform spans of each edge curve.
    creases : set of (int, int)
        Shared edges whose two segments' own surfaces (fitted to their points) meet at more
        than ``CREASE_ANGLE`` along them.
    scales : dict[(int, (int, int)), float]
        Per (corner, edge) of a pair, the factor on the pair's shared end derivative
        (:func:`_pair_scales`; the two factors of a pair multiply to 1).
    """

    corners: NDArray[np.float64]
    normals: NDArray[np.float64]
    loops: dict[int, list[int]]
    curves: dict[Key, PiecewiseBezier]
    users: dict[Key, list[int]]
    errors: dict[Key, float]
    rms: dict[Key, float]
    pairs: dict[int, list[tuple[Key, Key]]]
    regular: dict[int, bool]
    spans: dict[Key, int] = field(default_factory=dict)
    creases: set[Key] = field(default_factory=set)
    scales: dict[tuple[int, Key], float] = field(default_factory=dict)

    def sides(self, label: int) -> list[PiecewiseBezier]:
        """The segment's sides as a head-to-tail loop (edges reversed where needed)."""
        ids = self.loops[label]
        out = []
        for k in range(len(ids)):
            a, b = ids[k], ids[(k + 1) % len(ids)]
            curve = self.curves[(min(a, b), max(a, b))]
            out.append(curve if a < b else curve.reversed())
        return out


def key_of(a: int, b: int) -> Key:
    """Sorted corner-id pair naming an edge."""
    return (min(a, b), max(a, b))


# --------------------------------------------------------------------------- topology
def filter_corners(
    layout: Layout, tree: cKDTree, labels: NDArray[np.int64]
) -> tuple[NDArray[np.float64], dict[int, list[int]]]:
    """Drop border kinks (two segments, no open boundary near, not a sharp turn); renumber
    the corners."""
    reach = CLUSTER_FACTOR * layout.radius
    opened = [b for b in layout.open_boundary.values() if len(b)]
    open_tree = cKDTree(np.vstack(opened)) if opened else None
    keep = []
    for i, corner in enumerate(layout.corners):
        near = tree.query_ball_point(corner, reach)
        n_labels = len(np.unique(labels[near]))
        if layout.open_corners is not None:
            # The layout knows which corners lie on the open boundary (a border meeting it,
            # or a confirmed turn of it): counting open-loop points near a rim corner missed
            # some (the loop has a point only every ~1.3 radii there).
            near_open = bool(layout.open_corners[i])
        else:
            # Several open-boundary points: a single one can be a border point whose
            # neighbours happen to share its label (random sampling), not the open boundary.
            near_open = open_tree is not None and len(open_tree.query_ball_point(corner, reach)) >= 3
        sharp = layout.sharp_corners is not None and bool(layout.sharp_corners[i])
        keep.append(n_labels >= 3 or near_open or n_labels == 1 or sharp)
    keep_ids = np.flatnonzero(keep)
    new_id = {int(old): new for new, old in enumerate(keep_ids)}
    seg = {
        int(label): [new_id[int(c)] for c in ids if int(c) in new_id]
        for label, ids in layout.segment_corners.items()
    }
    return layout.corners[keep_ids].copy(), seg


def _border_runs(
    border: NDArray[np.float64], corners: NDArray[np.float64], common: list[int], a: int,
    b: int, gap: float,
) -> list[tuple[tuple[int, int], NDArray[np.float64]]]:
    """The edges two segments share: their border points with the two ``common`` corners it
    ends at; where they share 4 (the two halves of a tube, meeting along two borders), each
    connected run of the border (points ``gap`` apart) with the 2 corners nearest its ends;
    none where they share fewer than 2."""
    if len(common) == 2:
        return [((common[0], common[1]), border)]
    if len(common) < 2:
        # Diagonal pieces of a grid touching at a corner (a wide contact where the surface
        # bends tightly): no edge; a real side left without one fails the side loop.
        return []
    if len(common) == 4:
        pairs = cKDTree(border).query_pairs(gap, output_type="ndarray")
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(border),) * 2)
        comp = connected_components(graph, directed=False)[1]
        big = np.argsort(np.bincount(comp))[::-1][:2]
        runs = [border[comp == c] for c in big]
        near = np.array([[cKDTree(run).query(corners[c])[0] for c in common] for run in runs])
        own = [tuple(sorted(np.asarray(common)[np.argsort(row)[:2]].tolist())) for row in near]
        if len(runs) == 2 and len(set(own[0]) | set(own[1])) == 4:
            return [((int(e[0]), int(e[1])), run) for e, run in zip(own, runs)]
    raise InputError(
        f"segments {a} and {b} touch but share {len(common)} corners (need the 2 ends of "
        "each common edge); a border ending without a corner cannot become a patch side — "
        "split one of them"
    )


def _midline(
    border: NDArray[np.float64], tree: cKDTree, lab: NDArray[np.int64], a: int, b: int,
    reach: float,
) -> NDArray[np.float64]:
    """Edge data of a shared edge: the midpoints of the border points of either segment and
    their nearest across (within ``reach``)."""
    _, idx = tree.query(border)
    side_a = border[lab[idx] == a]
    side_b = border[lab[idx] == b]
    if len(side_a) < 2 or len(side_b) < 2:
        raise InputError(f"segments {a} and {b}: border too thin to fit an edge")
    d_ab, j = cKDTree(side_b).query(side_a)
    d_ba, i = cKDTree(side_a).query(side_b)
    return np.vstack([
        (side_a + side_b[j])[d_ab <= reach] / 2,
        (side_b + side_a[i])[d_ba <= reach] / 2,
    ])


def _edge_params(
    data: NDArray[np.float64], p0: NDArray[np.float64], p1: NDArray[np.float64], radius: float
) -> NDArray[np.float64]:
    """First parameters of an edge's data: the projection on the chord between its corners,
    or, where the edge bends back over itself so that this folds it (the teapot rim's seams
    run 0.3 over a lip whose ends lie 0.1 apart), the share ``d0 / (d0 + d1)`` of the
    shortest paths along the data (graph of points ``ARC_LINK`` radii apart) from each end."""
    chord = p1 - p0
    t = np.clip((data - p0) @ chord / (chord @ chord), 0.0, 1.0)
    if len(data) < 8:
        return t
    pairs = cKDTree(data).query_pairs(ARC_LINK * radius, output_type="ndarray")
    if not len(pairs):
        return t
    length = np.linalg.norm(data[pairs[:, 0]] - data[pairs[:, 1]], axis=1)
    graph = coo_matrix((length, (pairs[:, 0], pairs[:, 1])), shape=(len(data),) * 2).tocsr()
    ends = [int(np.argmin(np.linalg.norm(data - p, axis=1))) for p in (p0, p1)]
    d0, d1 = dijkstra(graph, directed=False, indices=ends)
    if not (np.isfinite(d0).all() and np.isfinite(d1).all()):
        return t
    arc = d0 / np.maximum(d0 + d1, 1e-300)
    return arc if np.abs(arc - t).max() > FOLDED_EDGE else t


def _arc_params(spline: BSpline, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """The share of ``spline``'s length up to each parameter ``t`` (its arc-length
    parameters, from a fine polyline of it)."""
    fine = np.linspace(0.0, 1.0, ARC_SAMPLES)
    run = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(spline(fine), axis=0), axis=1))])
    return np.interp(t, fine, run / max(float(run[-1]), 1e-300))


def _data_length(
    data: NDArray[np.float64], t: NDArray[np.float64], p0: NDArray[np.float64], p1: NDArray[np.float64]
) -> float:
    """Length of an edge: the polyline from ``p0`` through the means of its data in runs of
    ``LENGTH_BIN`` points along their parameters ``t`` to ``p1`` (the means average the
    band's width out; a free fit of a few points can loop and be many times longer)."""
    order = np.argsort(t)
    runs = np.array_split(order, max(1, len(order) // LENGTH_BIN))
    path = np.vstack([p0, [data[r].mean(axis=0) for r in runs], p1])
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def _open_flags(layout: Layout, corners: NDArray[np.float64]) -> NDArray[np.bool_] | None:
    """Whether each of the (filtered) ``corners`` is one the layout put on the open
    boundary; None when the layout does not say."""
    if layout.open_corners is None or not len(corners):
        return None
    dist, idx = cKDTree(layout.corners).query(corners)
    return np.asarray(layout.open_corners, dtype=bool)[idx] & (dist == 0.0)


def _open_runs(
    boundary: NDArray[np.float64], corner_xyz: NDArray[np.float64], corner_ids: list[int],
    gap: float, on_open: NDArray[np.bool_] | None = None,
) -> list[tuple[int, int, NDArray[np.float64]]]:
    """Runs of a segment's open-boundary loop between consecutive corners near it (within
    ``OPEN_REACH x gap``: the loop can be sparse at a rim corner). With ``on_open`` (whether
    the layout put each corner on the open boundary), a corner it did not is near only within
    ``INNER_REACH x gap``: the teapot rim's outer corners lie 1.9 radii from its inner rim
    in space (across the lip) at 112k points."""
    if len(boundary) < 2:
        return []
    dist, where = cKDTree(boundary).query(corner_xyz)
    near = dist <= OPEN_REACH * gap
    if on_open is not None:
        near &= on_open | (dist <= INNER_REACH * gap)
    if near.sum() < 2:
        return []
    ids = np.asarray(corner_ids)[near]
    at = where[near]
    order = np.argsort(at)
    ids, at = ids[order], at[order]
    step = np.linalg.norm(np.diff(np.vstack([boundary, boundary[:1]]), axis=0), axis=1)
    runs = []
    n = len(boundary)
    for k in range(len(ids)):
        i0, i1 = int(at[k]), int(at[(k + 1) % len(ids)])
        if ids[k] == ids[(k + 1) % len(ids)]:
            continue
        idx = np.arange(i0, i1 + 1) if i1 > i0 else np.r_[np.arange(i0, n), np.arange(0, i1 + 1)]
        # A run crossing a border (points removed from the loop) jumps: not an open edge.
        if len(idx) >= 3 and step[idx[:-1]].max() <= gap:
            runs.append((int(ids[k]), int(ids[(k + 1) % len(ids)]), boundary[idx]))
    return runs


def _rim_data(own: NDArray[np.float64], run: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Data of an open edge: its rim estimated from the segment's samples ``own`` near the
    loop run (:func:`~pde2cad.surfaces.rim.locate_rim`), not the run itself, whose points
    lie about half a spacing inside the true rim and zigzag; None (keep the run) where the
    edge is too short for a window depth at both ends or its windows hold too few samples."""
    tree = cKDTree(own)
    est = locate_rim(own, run, sample_spacing(own, tree), tree, least=RIM_STATIONS)
    if est is None or len(est.points) < RIM_STATIONS // 2:
        return None
    return est.points


def _cycle(label: int, corner_ids: list[int], edges: list[Key]) -> list[int]:
    """Order a segment's corners along its edges; the edges must form one cycle."""
    count = len(corner_ids)
    if len(edges) != count:
        raise InputError(
            f"segment {label}: found {len(edges)} edges for its {count} corners "
            f"{sorted(corner_ids)} (edges {sorted(edges)}); each side must be a border with one "
            "neighbour or a run of the open boundary — check that the segment does not touch a "
            "neighbour along two separate borders and that its corners are not merged"
        )
    nxt: dict[int, list[int]] = {c: [] for c in corner_ids}
    for a, b in edges:
        if a not in nxt or b not in nxt:
            raise InputError(f"segment {label}: edge {(a, b)} ends at a corner it does not have")
        nxt[a].append(b)
        nxt[b].append(a)
    if any(len(v) != 2 for v in nxt.values()):
        raise InputError(
            f"segment {label}: its sides do not close into one loop (corner degrees "
            f"{ {c: len(v) for c, v in nxt.items()} }); the segment is probably not 3- or 4-sided"
        )
    loop = [corner_ids[0]]
    prev = -1
    while len(loop) < count:
        here = loop[-1]
        step = nxt[here][0] if nxt[here][0] != prev else nxt[here][1]
        prev = here
        loop.append(step)
    if len(set(loop)) != count:
        raise InputError(f"segment {label}: its sides form more than one loop")
    return loop


# --------------------------------------------------------------------------- curve fitting
def _knots(spans: int) -> NDArray[np.float64]:
    return np.r_[[0.0] * 3, np.linspace(0.0, 1.0, spans + 1), [1.0] * 3]


def _design(t: NDArray[np.float64], spans: int) -> NDArray[np.float64]:
    return BSpline.design_matrix(np.clip(t, 0.0, 1.0), _knots(spans), 3).toarray()


def _project(spline: BSpline, points: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Closest parameters in [0, 1] of ``points`` on ``spline``, from dense samples + Newton."""
    grid = np.linspace(0.0, 1.0, 1025)
    _, idx = cKDTree(spline(grid)).query(points)
    t = grid[idx]
    d1, d2 = spline.derivative(1), spline.derivative(2)
    for _ in range(2):
        r = spline(t) - points
        g = d1(t)
        step = np.einsum("ij,ij->i", r, g) / np.maximum(
            np.einsum("ij,ij->i", g, g) + np.einsum("ij,ij->i", r, d2(t)), 1e-300
        )
        t = np.clip(t - step, 0.0, 1.0)
    return t


def _free_fit(
    data: NDArray[np.float64], t: NDArray[np.float64], spans: int
) -> tuple[BSpline, NDArray[np.float64], float]:
    """Least-squares spline with free ends; returns it, the parameters and the RSS."""
    for _ in range(REPARAM_ROUNDS):
        basis = _design(t, spans)
        ctrl = np.linalg.lstsq(basis, data, rcond=None)[0]
        spline = BSpline(_knots(spans), ctrl, 3)
        t = _project(spline, data, t)
    rss = float(((spline(t) - data) ** 2).sum())
    return spline, t, rss


def _choose_spans(data: NDArray[np.float64], t: NDArray[np.float64]) -> tuple[int, BSpline, NDArray[np.float64]]:
    """Span count by the Bayesian information criterion over ``SPAN_CHOICES``.

    The sample size is the number of data points, not of coordinates: after closest-point
    reparameterization the residuals have no component along the curve, and the border
    midpoints share their points pairwise, so counting 3 per point made the criterion buy
    spans for noise (8-span edges with hooks at the corners on 0.2 % noise)."""
    n = len(data)
    best = None
    for spans in SPAN_CHOICES:
        if spans > 1 and len(data) < POINTS_PER_SPAN * spans:
            break
        spline, tt, rss = _free_fit(data, t.copy(), spans)
        bic = n * np.log(max(rss, 1e-300) / n) + 3 * (spans + 3) * np.log(n)
        if best is None or bic < best[0]:
            best = (bic, spans, spline, tt)
    assert best is not None
    return best[1], best[2], best[3]


def _quadric(
    points: NDArray[np.float64], centre: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Project ``centre`` onto a quadric height field fitted to ``points``; return it and the
    unit normal there. ``None`` when the points do not determine the quadric."""
    if len(points) < 12:
        return None
    origin = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - origin, full_matrices=False)
    local = (points - origin) @ vt.T
    x, y, z = local.T
    design = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    coef, *_ = np.linalg.lstsq(design, z, rcond=None)
    cx, cy, _ = (centre - origin) @ vt.T
    cz = coef @ [1.0, cx, cy, cx * cx, cx * cy, cy * cy]
    fx = coef[1] + 2 * coef[3] * cx + coef[4] * cy
    fy = coef[2] + coef[4] * cx + 2 * coef[5] * cy
    normal = np.array([-fx, -fy, 1.0]) @ vt
    return np.array([cx, cy, cz]) @ vt + origin, normal / np.linalg.norm(normal)


def mls_project(
    queries: NDArray[np.float64], cloud: NDArray[np.float64], tree: cKDTree, k: int = MLS_NEIGHBOURS
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Project points onto the cloud's surface: a quadric height field over each query's ``k``
    nearest cloud points on its own sheet (:func:`~pde2cad.surfaces.sheets.same_sheet`; in
    their PCA frame), evaluated below the query. Batched, no loops.

    Returns the projected points (Q, 3) and unit normals (Q, 3) (orientation arbitrary).
    """
    k = min(k, len(cloud))
    _, idx = tree.query(queries, k=k)
    hood = cloud[idx]  # (Q, k, 3)
    # The query's own sheet only (a thin lip's far side is in the ball, not on the surface).
    w = same_sheet(cloud, idx).astype(float)
    count = w.sum(axis=1)
    origin = np.einsum("qk,qki->qi", w, hood) / count[:, None]
    centred = (hood - origin[:, None]) * w[..., None]
    _, vecs = np.linalg.eigh(np.einsum("qki,qkj->qij", centred, centred))
    frame = vecs[:, :, ::-1].transpose(0, 2, 1)  # rows: major, minor, normal
    local = np.einsum("qki,qji->qkj", centred, frame)
    x, y, z = local[..., 0], local[..., 1], local[..., 2]
    design = np.stack([w, x, y, x * x, x * y, y * y], axis=-1)  # (Q, k, 6), 0 off the sheet
    # Scale columns to the neighbourhood size so the 6 x 6 normal equations stay well posed.
    h = np.sqrt((x * x + y * y).sum(axis=1) / count)[:, None]
    powers = np.array([0, 1, 1, 2, 2, 2])
    design = design / h[..., None] ** powers
    gram = np.einsum("qki,qkj->qij", design, design) + 1e-10 * np.eye(6)
    coef = np.linalg.solve(gram, np.einsum("qki,qk->qi", design, z)[..., None])[..., 0]
    coef = coef / h**powers
    q = np.einsum("qi,qji->qj", queries - origin, frame)
    cx, cy = q[:, 0], q[:, 1]
    cz = coef[:, 0] + coef[:, 1] * cx + coef[:, 2] * cy + coef[:, 3] * cx * cx
    cz += coef[:, 4] * cx * cy + coef[:, 5] * cy * cy
    fx = coef[:, 1] + 2 * coef[:, 3] * cx + coef[:, 4] * cy
    fy = coef[:, 2] + coef[:, 4] * cx + 2 * coef[:, 5] * cy
    normal = np.einsum("qj,qji->qi", np.stack([-fx, -fy, np.ones_like(fx)], 1), frame)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    projected = np.einsum("qj,qji->qi", np.stack([cx, cy, cz], 1), frame) + origin
    return projected, normal


def _end_line(
    data: NDArray[np.float64], corner: NDArray[np.float64], other: NDArray[np.float64],
    radius: float, length: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Tangent line of the edge data at one end: (point, unit direction away from the corner,
    distance of the nearest datum to the corner, i.e. how far the line is extrapolated).

    A quadratic in the principal-axis coordinate is fitted to the data near the end and
    evaluated at the corner's coordinate, so a curved edge does not tilt the line (a chord
    over the same data would, by half the turn)."""
    dist = np.linalg.norm(data - corner, axis=1)
    reach = max(END_REACH * radius, END_SHARE * length)
    while True:
        near = data[dist <= reach]
        if len(near) < 6:
            near = data[np.argsort(dist)[: min(len(data), 12)]]
        centre = near.mean(axis=0)
        axis = np.linalg.svd(near - centre, full_matrices=False)[2][0]
        s = (near - centre) @ axis
        s0 = float((corner - centre) @ axis)
        design = np.column_stack([np.ones_like(s), s, s * s])
        coef = np.linalg.lstsq(design, near, rcond=None)[0]
        # A quadratic over the axis follows an end that turns little within the reach;
        # one turning round a lip (the teapot rim's cross-section, 175 deg over 7 radii)
        # folds over the axis: a shorter reach then.
        tips = coef[1][None] + 2 * coef[2][None] * np.array([s.min(), s.max()])[:, None]
        tips /= np.maximum(np.linalg.norm(tips, axis=1, keepdims=True), 1e-300)
        if tips[0] @ tips[1] >= np.cos(np.radians(END_TURN)) or reach <= END_LEAST * radius:
            break
        reach = max(0.5 * reach, END_LEAST * radius)
    point = coef[0] + coef[1] * s0 + coef[2] * s0 * s0
    direction = coef[1] + 2 * coef[2] * s0
    direction = direction / np.linalg.norm(direction)
    # Oriented towards the edge's other corner (the data near the end may straddle it).
    if direction @ (other - corner) < 0:
        direction = -direction
    return point, direction, float(dist.min())


def _line_point(
    points: list[NDArray[np.float64]], dirs: list[NDArray[np.float64]], guess: NDArray[np.float64],
    weight: float, trust: NDArray[np.float64] | None = None, scale: float | None = None,
) -> NDArray[np.float64]:
    """Least-squares meeting point of lines ``points[i] + s dirs[i]``, pulled to ``guess``.

    Parameters
    ----------
    points, dirs : list of (3,) float
        A point on each line and its direction.
    guess : (3,) float
        Prior position; ``weight`` is its pull relative to one line of unit trust.
    weight : float
        Pull of ``guess``.
    trust : (L,) float, optional
        Per-line weights (1 when omitted).
    scale : float, optional
        When given, the lines are reweighted ``LINE_ROUNDS`` times by
        ``1 / (1 + (r / scale)**2)`` of their distance ``r`` to the current point (a Cauchy
        M-estimator): one line extrapolated far from its data cannot drag the corner away.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    d = np.asarray(dirs, dtype=float).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    proj = np.eye(3)[None] - np.einsum("li,lj->lij", d, d)  # (L, 3, 3)
    base = np.ones(len(p)) if trust is None else np.asarray(trust, dtype=float)
    w = base.copy()
    x = guess
    for _ in range(1 + (LINE_ROUNDS if scale is not None else 0)):
        a = weight * np.eye(3) + np.einsum("l,lij->ij", w, proj)
        b = weight * guess + np.einsum("l,lij,lj->i", w, proj, p)
        x = np.linalg.solve(a, b)
        if scale is not None:
            r = np.linalg.norm(np.einsum("lij,lj->li", proj, x[None] - p), axis=1)
            w = base / (1.0 + (r / scale) ** 2)
    return x


def _onto_sheet(
    pts: NDArray[np.float64], tree: cKDTree, guess: NDArray[np.float64],
    moved: NDArray[np.float64], radius: float, spacing: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A refined corner and its normal: ``moved`` (the end lines' meeting point) projected
    onto the quadric of the sheet the layout's corner ``guess`` lies on.

    1. The points within the quadric's reach of ``moved`` that lie on ``guess``'s own sheet
       (:func:`~pde2cad.surfaces.sheets.one_sheet`: a thin lip's far side is left out).
    2. ``moved`` onto their quadric; where that lands off their data (the end lines of a
       short edge round a lip met over its far side), ``guess`` onto the quadric of its
       own sheet around it instead.
    3. No quadric (too few points): ``moved`` and the points' plane normal.
    """
    reach = max(QUADRIC_RADIUS * radius, 4 * spacing)
    near = pts[tree.query_ball_point(moved, reach)]
    if len(near) >= 12:
        near = near[one_sheet(near, moved[None], radius, SHEET_STRETCH * reach, 12)]
    fit = _quadric(near, moved)
    if fit is not None and np.min(np.linalg.norm(near - fit[0], axis=1)) > radius:
        near = pts[tree.query_ball_point(guess, reach)]
        if len(near) >= 12:
            near = near[one_sheet(near, guess[None], radius, reach, 12)]
        fit = _quadric(near, guess)
    if fit is not None and np.linalg.norm(fit[0] - guess) <= MAX_CORNER_MOVE * radius:
        return fit
    normal = np.linalg.svd(near - near.mean(axis=0))[2][-1] if len(near) >= 3 else np.array([0.0, 0, 1])
    return moved, normal


# --------------------------------------------------------------------------- main
def build_edges(
    points: NDArray[np.float64],
    labels: NDArray[np.int64],
    layout: Layout,
    tree: cKDTree | None = None,
    cuts: set[frozenset[int]] | None = None,
) -> EdgeNetwork:
    """Refined corners, side loops and one fitted curve per edge of a segmented cloud.

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
    layout : Layout
        From :func:`~pde2cad.layout.adjacency.build_layout` on the same points
        (``check=False`` is fine: border kinks are dropped here, then every segment must
        have 3 or 4 corners).
    tree : cKDTree, optional
        Of ``points`` (built when omitted).
    cuts : set of frozenset of two labels, optional
        Neighbours whose shared edges are seams the layout cut through one smooth segment
        (:func:`~pde2cad.layout.split.split_segments`): their border data only trace where
        the cut happened to fall, so they are fitted with at most ``CUT_SPANS`` spans (a
        fair curve on the surface) instead of following its wander.

    Returns
    -------
    EdgeNetwork

    Raises
    ------
    InputError
        A segment without 3 or 4 corners, two neighbours sharing other than two corners,
        sides that do not form one loop (each message names the segment).
    """
    pts = np.asarray(points, dtype=float)
    lab = np.asarray(labels).astype(np.int64)
    tree = cKDTree(pts) if tree is None else tree
    radius, spacing = layout.radius, layout.spacing
    corners, seg_corners = filter_corners(layout, tree, lab)
    for label, ids in seg_corners.items():
        if len(ids) not in (3, 4):
            raise InputError(
                f"segment {label} has {len(ids)} corners; a patch needs 3 or 4 — split or "
                "merge segments so each is a 3- or 4-sided region"
            )

    # Topology: shared edges from common corners, open edges from open-boundary runs.
    data: dict[Key, NDArray[np.float64]] = {}
    users: dict[Key, list[int]] = {}
    seg_edges: dict[int, list[Key]] = {label: [] for label in seg_corners}
    for (a, b), whole in layout.borders.items():
        common = sorted(set(seg_corners[a]) & set(seg_corners[b]))
        for pair_ends, border in _border_runs(whole, corners, common, a, b, CLUSTER_FACTOR * radius):
            key = key_of(*pair_ends)
            if key in users:
                raise InputError(
                    f"segments {users[key]} and {[a, b]} all claim the edge between corners "
                    f"{key}; check the segmentation near that edge"
                )
            data[key] = _midline(border, tree, lab, a, b, PAIR_REACH * spacing)
            users[key] = [a, b]
            seg_edges[a].append(key)
            seg_edges[b].append(key)
    gap = CLUSTER_FACTOR * radius
    on_open = _open_flags(layout, corners)
    for label, ids in seg_corners.items():
        boundary = layout.open_boundary.get(label, np.zeros((0, 3)))
        own = None
        flags = None if on_open is None else on_open[ids]
        for c0, c1, run in _open_runs(boundary, corners[ids], ids, gap, flags):
            key = key_of(c0, c1)
            if key in users:
                continue
            own = pts[lab == label] if own is None else own
            rim = _rim_data(own, run)
            run = run if rim is None else rim
            data[key] = run if c0 < c1 else run[::-1]
            users[key] = [label]
            seg_edges[label].append(key)
    loops = {label: _cycle(label, seg_corners[label], seg_edges[label]) for label in seg_corners}
    loops = _orient(loops, users, corners)

    # Free fits per edge (span count, end tangent lines), on data away from the corners.
    at_corner: dict[int, list[tuple[Key, int]]] = {c: [] for c in range(len(corners))}
    spans: dict[Key, int] = {}
    params: dict[Key, NDArray[np.float64]] = {}
    lengths: dict[Key, float] = {}
    ends: dict[tuple[Key, int], tuple[NDArray[np.float64], NDArray[np.float64], float]] = {}
    for key, pts_e in data.items():
        p0, p1 = corners[key[0]], corners[key[1]]
        chord = p1 - p0
        t = _edge_params(pts_e, p0, p1, radius)
        trim = (np.linalg.norm(pts_e - p0, axis=1) > END_TRIM * radius) & (
            np.linalg.norm(pts_e - p1, axis=1) > END_TRIM * radius
        )
        if trim.sum() < 8:
            trim[:] = True
        if len(pts_e) < 4:
            raise InputError(f"edge between corners {key} has only {len(pts_e)} points to fit")
        # The span count only needs the edge's shape: on dense clouds (thousands of
        # midpoints per edge) an even subsample of SPAN_SAMPLE gives the same choice.
        pick = np.flatnonzero(trim)
        pick = pick[np.linspace(0, len(pick) - 1, min(len(pick), SPAN_SAMPLE)).astype(np.int64)]
        n, _, _ = _choose_spans(pts_e[pick], t[pick])
        spans[key] = min(n, CUT_SPANS) if cuts and frozenset(users[key]) in cuts else n
        lengths[key] = _data_length(pts_e, t, p0, p1)
        length = float(np.linalg.norm(chord))
        for end in (0, 1):
            ends[(key, end)] = _end_line(
                pts_e[trim], corners[key[end]], corners[key[1 - end]], radius, length
            )
            at_corner[key[end]].append((key, end))

    # Corner refinement: meeting point of the end tangent lines, onto a local quadric.
    normals = np.zeros_like(corners)
    for c, incident in at_corner.items():
        guess = corners[c]
        lines = [ends[e] for e in incident]
        gaps = np.maximum([g for *_, g in lines], 1e-300)
        trust = np.minimum(1.0, (EXTRAPOLATION * radius / gaps) ** 2)
        moved = _line_point(
            [p for p, *_ in lines], [d for _, d, _ in lines], guess, 0.05 * len(lines), trust,
            LINE_SCALE * radius,
        )
        if np.linalg.norm(moved - guess) > MAX_CORNER_MOVE * radius:
            moved = guess
        corners[c], normals[c] = _onto_sheet(pts, tree, guess, moved, radius, spacing)

    away = {(key[end], key): ends[(key, end)][1] for key, end in ends}
    smooth = _smooth_corners(pts, lab, tree, corners, at_corner, users,
                             max(QUADRIC_RADIUS * radius, 4 * spacing), radius)
    # Creases: shared edges whose two segments' own surfaces meet at an angle along them (a
    # median over the edge's data survives noise that hides the crease at one corner).
    sheets = _Sheets(pts, lab, tree, SHEET_REACH * radius, _sheet_neighbours(pts, tree, spacing))
    creases = set()
    at_ends = dict(smooth)
    for key, who in users.items():
        if len(who) == 2:
            step = max(1, len(data[key]) // CREASE_SAMPLES)
            angle = sheets.angle(data[key][::step], sorted(who))
            # Smooth at both ends and a mild angle: one-sided quadrics misread a tight bend
            # (the teapot rim's crest, ~2 radii round: 26 deg), not a crease.
            mild = at_ends.get(key[0], False) and at_ends.get(key[1], False) and angle <= CREASE_SURE
            if angle > CREASE_ANGLE and not mild:
                creases.add(key)
                smooth[key[0]] = smooth[key[1]] = False
    pairs, regular = _pairs(loops, users, len(corners), away, smooth, creases)
    scales = _pair_scales(pairs, regular, loops, users, lengths)
    # At a crease corner the quadric over all segments rounds the corner off: put it on the
    # intersection of the segments' own surfaces instead (nearest point to the estimate).
    for c, incident in at_corner.items():
        if smooth.get(c, True):
            continue
        segs = sorted({u for key, _ in incident for u in users[key]})
        moved = sheets.intersect(corners[c][None], segs)[0]
        if np.linalg.norm(moved - corners[c]) <= MAX_CORNER_MOVE * radius:
            corners[c] = moved
    for key, pts_e in data.items():
        p0, p1 = corners[key[0]], corners[key[1]]
        chord = p1 - p0
        params[key] = _edge_params(pts_e, p0, p1, radius)
    legs = _leg_bases(corners, normals, smooth, users, sheets)
    splines = _joint_fit(data, params, spans, corners, legs, pairs, scales, FAIRNESS)
    # The midline fixes where an edge runs ALONG the surface; its height above the surface is
    # better taken from the whole cloud: project samples of each edge onto a local quadric
    # and refit them (noise-free samples afford more spans).
    final = {key: max(spans[key], MIN_FINAL_SPANS) * (ARC_SPAN_FACTOR if key in creases else 1)
             for key in data}
    samples, sample_t = {}, {}
    for key, spline in splines.items():
        t = np.linspace(0.0, 1.0, SAMPLES_PER_SPAN * final[key] + 1)[1:-1]
        samples[key], sample_t[key] = spline(t), t
    for key in data:
        # Onto the edge's own segments' surface: a quadric over every point near a cut
        # that ends on a crease also fits the far side and lifts the cut off its face (a
        # bracket's L-shaped faces: 2-21 deg seams across the flat).
        raw, samples[key] = samples[key], sheets.project(samples[key], sorted(users[key]))[0]
        if key in creases:
            # A crease's samples belong on the intersection of the two segments' surfaces.
            samples[key] = sheets.intersect(raw, sorted(users[key]))
        if key in creases or (cuts and frozenset(users[key]) in cuts):
            # Arc-length parameters: the patches on both sides of a crease or a cut take
            # their parameterization from it (a band's top and bottom edges, fitted with
            # speeds varying 20x along them, skewed its Coons rulings across a fillet).
            sample_t[key] = _arc_params(splines[key], sample_t[key])
    splines = _joint_fit(samples, sample_t, final, corners, legs, pairs, scales)
    curves, errors, rms = {}, {}, {}
    for key, spline in splines.items():
        t = _project(spline, data[key], params[key])
        dist = np.linalg.norm(spline(t) - data[key], axis=1)
        errors[key], rms[key] = float(dist.max()), float(np.sqrt((dist**2).mean()))
        curves[key] = _to_bezier(spline, final[key], corners[key[0]], corners[key[1]])
    return EdgeNetwork(corners, normals, loops, curves, users, errors, rms, pairs, regular, final,
                       creases, scales)


def _orient(
    loops: dict[int, list[int]], users: dict[Key, list[int]], corners: NDArray[np.float64]
) -> dict[int, list[int]]:
    """Orient the side loops consistently (neighbours run their shared edge in opposite
    directions, so all patch normals point to one side); on a closed surface, outwards."""

    def runs(label: int, a: int, b: int) -> bool:
        ids = loops[label]
        i = ids.index(a)
        return ids[(i + 1) % len(ids)] == b

    done: set[int] = set()
    for seed in sorted(loops):
        if seed in done:
            continue
        done.add(seed)
        stack = [seed]
        while stack:
            label = stack.pop()
            ids = loops[label]
            for k in range(len(ids)):
                a, b = ids[k], ids[(k + 1) % len(ids)]
                for other in users[key_of(a, b)]:
                    if other in done:
                        continue
                    if runs(other, a, b):
                        loops[other] = loops[other][::-1]
                    done.add(other)
                    stack.append(other)
    # Divergence theorem on the corner polygons: sum of centroid . vector area ~ 3 x volume.
    flux = 0.0
    for ids in loops.values():
        ring = corners[ids]
        area = 0.5 * np.cross(ring, np.roll(ring, -1, axis=0)).sum(axis=0)
        flux += float(ring.mean(axis=0) @ area)
    if flux < 0:
        loops = {label: ids[::-1] for label, ids in loops.items()}
    return loops


def _other_sides(loops: dict[int, list[int]]) -> dict[tuple[int, int], dict[Key, Key]]:
    """Per (segment, corner), each of its two sides there mapped to the other one."""
    other: dict[tuple[int, int], dict[Key, Key]] = {}
    for label, ids in loops.items():
        c = len(ids)
        for k in range(c):
            prev_key = key_of(ids[k - 1], ids[k])
            next_key = key_of(ids[k], ids[(k + 1) % c])
            other[(label, ids[k])] = {prev_key: next_key, next_key: prev_key}
    return other


def _pairs(
    loops: dict[int, list[int]],
    users: dict[Key, list[int]],
    n_corners: int,
    away: dict[tuple[int, Key], NDArray[np.float64]],
    smooth: dict[int, bool],
    creases: set[Key] | None = None,
) -> tuple[dict[int, list[tuple[Key, Key]]], dict[int, bool]]:
    """Edges paired across each corner: for a shared edge, the two patches' other edges,
    when the surface is smooth at the corner or they run on smoothly through it (a crease
    keeps its kink). The other edges of a crease edge's two patches lie on the two sides of
    the crease: never a pair (two cuts meeting a 90-deg crease from both sides, their free
    fits turning by 57 deg, were paired and flattened the crease at their corner to 0 deg)."""
    other = _other_sides(loops)
    pairs: dict[int, list[tuple[Key, Key]]] = {c: [] for c in range(n_corners)}
    wanted: dict[int, set[tuple[Key, Key]]] = {c: set() for c in range(n_corners)}
    for key, who in users.items():
        if len(who) != 2 or (creases and key in creases):
            continue
        for corner in key:
            ea = other[(who[0], corner)][key]
            eb = other[(who[1], corner)][key]
            if ea != eb:
                wanted[corner].add((min(ea, eb), max(ea, eb)))
    regular: dict[int, bool] = {}
    for corner, candidates in wanted.items():
        seen = [e for p in candidates for e in p]
        # Each edge in at most one pair (even valence, or the open boundary) ...
        ok = len(seen) == len(set(seen))
        for ea, eb in sorted(candidates):
            da, db = away[(corner, ea)], away[(corner, eb)]
            cos = -float(da @ db) / max(float(np.linalg.norm(da) * np.linalg.norm(db)), 1e-300)
            # ... and the paired edges run on smoothly (a crease keeps its kink).
            if ok and (smooth.get(corner, False) or cos >= np.cos(np.radians(PAIR_ANGLE))):
                pairs[corner].append((ea, eb))
        regular[corner] = ok and len(pairs[corner]) == len(candidates)
    return pairs, regular


def _pair_scales(
    pairs: dict[int, list[tuple[Key, Key]]],
    regular: dict[int, bool],
    loops: dict[int, list[int]],
    users: dict[Key, list[int]],
    lengths: dict[Key, float],
) -> dict[tuple[int, Key], float]:
    """Speed factors on the shared end derivative of each pair ``(ea, eb)`` at a corner:
    ``sqrt(r)`` for ``ea``, ``1 / sqrt(r)`` for ``eb``, ``r`` near their length ratio.

    A cubic of chord L leaving both ends along it at speed m runs backwards at its middle
    once m > 3 L (Hermite: x'(1/2) = 1.5 L - 0.5 m), so one speed for a short and a long
    edge folds the short one. The ribbons across a shared edge between two regular corners
    are ``lambda_A D`` and ``-lambda_B D`` (:mod:`pde2cad.layout.ribbons`), in one plane with
    the edge everywhere only when ``lambda_A / lambda_B`` is constant; at either end it is
    the speed ratio of the pair there (the two patches' other sides). So all pairs crossing
    one line of such edges take one ratio, when they roughly agree; where they do not, each
    keeps its own and the ribbons blend between the ends (one tangent plane at the nodes).

    1. Nodes: the pairs, each with its log length ratio (``lengths``, first edge over second),
       less ``PAIR_SLACK``.
    2. Links: a shared edge with both ends regular ties the pairs at its ends (signed by
       which of each pair is the first user's side).
    3. Per linked set, the signed mean log ratio if the raw (unslacked) signed ratios lie
       within ``PAIR_SPREAD`` (and the signs agree around the set); else each pair its own.
       Judging the spread after the slack would call 1.0 and 2.9 alike (0 and 0.66 after
       a 1.5 slack) and average pairs that the ribbons must blend between.
    """
    want = {(c, p): float(np.log(max(lengths[p[0]], 1e-300) / max(lengths[p[1]], 1e-300)))
            for c, plist in pairs.items() for p in plist}
    slack = np.log(PAIR_SLACK)
    raw = dict(want)
    want = {n: float(np.sign(q) * max(abs(q) - slack, 0.0)) for n, q in raw.items()}
    links: dict[tuple[int, tuple[Key, Key]], list[tuple[tuple[int, tuple[Key, Key]], float]]] = {
        n: [] for n in want}
    other = _other_sides(loops)
    for key, who in users.items():
        if len(who) != 2 or not all(regular.get(c, False) for c in key):
            continue
        ends = []
        for c in key:
            ea, eb = other[(who[0], c)][key], other[(who[1], c)][key]
            pair = (min(ea, eb), max(ea, eb))
            if (c, pair) in want:
                ends.append(((c, pair), 1.0 if pair[0] == ea else -1.0))
        if len(ends) == 2:
            (n0, s0), (n1, s1) = ends
            links[n0].append((n1, s0 * s1))
            links[n1].append((n0, s0 * s1))
    log_ratio: dict[tuple[int, tuple[Key, Key]], float] = {}
    for seed in want:
        if seed in log_ratio:
            continue
        sign, stack, conflict = {seed: 1.0}, [seed], False
        while stack:
            n = stack.pop()
            for m, s in links[n]:
                if m not in sign:
                    sign[m] = sign[n] * s
                    stack.append(m)
                conflict |= sign[m] != sign[n] * s
        signed = np.array([sign[n] * want[n] for n in sign])
        spread = np.ptp([sign[n] * raw[n] for n in sign])
        if conflict or spread > np.log(PAIR_SPREAD):
            log_ratio.update({n: want[n] for n in sign})
        else:
            log_ratio.update({n: sign[n] * float(signed.mean()) for n in sign})
    out: dict[tuple[int, Key], float] = {}
    for (c, (ea, eb)), q in log_ratio.items():
        out[(c, ea)], out[(c, eb)] = float(np.exp(0.5 * q)), float(np.exp(-0.5 * q))
    return out


class _Sheets:
    """Each segment's own surface (its points' moving quadrics), for creases: where two
    segments meet at an angle, the edge is where their surfaces intersect."""

    def __init__(
        self, points: NDArray[np.float64], labels: NDArray[np.int64], tree: cKDTree, reach: float,
        k: int = MLS_NEIGHBOURS,
    ) -> None:
        self.points, self.labels, self.tree, self.reach, self.k = points, labels, tree, reach, k

    def project(
        self, q: NDArray[np.float64], label: int | list[int], k: int | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:func:`mls_project` of ``q`` onto the points of segment ``label`` (or of the
        segments listed), over ``k`` neighbours (default: the sheets' own)."""
        # The segment's points within ``reach`` of the queries only: a tree over a whole
        # segment of a 1e6-point cloud costs more than every query on it.
        rows = self.tree.query_ball_point(q, self.reach)
        idx = np.unique(np.concatenate([np.asarray(r, dtype=np.int64) for r in rows]))
        idx = idx[np.isin(self.labels[idx], label)]
        k = self.k if k is None else k
        if len(idx) < k:
            idx = np.flatnonzero(np.isin(self.labels, label))
        own = self.points[idx]
        return mls_project(q, own, cKDTree(own), k)

    def angle(self, q: NDArray[np.float64], labels: list[int]) -> float:
        """Median angle (degrees) between two segments' surface normals below ``q`` (wider
        quadrics than the projection's: one-sided normals at a noisy border scatter)."""
        (_, na), (_, nb) = (self.project(q, label, CREASE_NEIGHBOURS) for label in labels[:2])
        cos = np.abs(np.einsum("ij,ij->i", na, nb))
        return float(np.degrees(np.arccos(np.clip(np.median(cos), 0.0, 1.0))))

    def intersect(self, q: NDArray[np.float64], labels: list[int]) -> NDArray[np.float64]:
        """Points on every listed segment's surface nearest to ``q`` (Q, 3): Newton steps on
        the tangent planes (min-norm step; near-parallel planes count as one)."""
        x = np.array(q, dtype=float)
        for _ in range(CREASE_ROUNDS):
            fits = [self.project(x, label) for label in labels]
            a = np.stack([n for _, n in fits], axis=1)  # (Q, k, 3)
            r = np.stack([np.einsum("ij,ij->i", n, p - x) for p, n in fits], axis=1)  # (Q, k)
            u, sv, vt = np.linalg.svd(a, full_matrices=False)
            inv = np.where(sv > PLANE_RCOND * sv[:, :1], 1.0 / np.maximum(sv, 1e-300), 0.0)
            x = x + np.einsum("qji,qj->qi", vt, inv * np.einsum("qkj,qk->qj", u, r))
        return x


def _sheet_neighbours(points: NDArray[np.float64], tree: cKDTree, spacing: float) -> int:
    """Neighbours of the one-sided quadrics that put edge samples on the surface: enough
    that their own noise, about ``sigma sqrt(6 / k)`` for 6 coefficients over ``k`` points
    of noise ``sigma`` (:func:`~pde2cad.layout.creases.surface_noise`), stays within
    ``SHEET_NOISE`` spacings; ``MLS_NEIGHBOURS`` to ``SHEET_MOST`` (a crease's samples sit
    at the rim of both quadrics, where a 40-point fit's noise at 0.4 spacings tilted a
    bracket's sharp edges by 10-80 deg off their 90; 120 kept them within 13)."""
    from pde2cad.layout.creases import surface_noise

    sigma = surface_noise(points, tree)
    need = 6.0 * (sigma / (SHEET_NOISE * max(spacing, 1e-300))) ** 2
    return int(np.clip(np.ceil(need), MLS_NEIGHBOURS, SHEET_MOST))


#: Largest noise of a one-sided quadric's projection, in point spacings.
SHEET_NOISE = 0.08
#: Most neighbours of a one-sided quadric (its reach, ~sqrt(k / pi) spacings, rounds off
#: fillets).
SHEET_MOST = 160


def _quadric_rms(points: NDArray[np.float64], frame: NDArray[np.float64], origin: NDArray[np.float64]) -> float:
    """RMS residual of a quadric height field over ``frame``'s first two axes."""
    x, y, z = ((points - origin) @ frame.T).T
    design = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    coef = np.linalg.lstsq(design, z, rcond=None)[0]
    return float(np.sqrt(np.mean((design @ coef - z) ** 2)))


def _smooth_corners(
    points: NDArray[np.float64],
    labels: NDArray[np.int64],
    tree: cKDTree,
    corners: NDArray[np.float64],
    at_corner: dict[int, list[tuple[Key, int]]],
    users: dict[Key, list[int]],
    reach: float,
    link: float,
) -> dict[int, bool]:
    """Whether the surface is smooth at each corner: the incident segments' own quadrics
    (points within ``reach``) agree on the normal at the corner to ``SMOOTH_ANGLE``, or one
    quadric over all of them fits about as well as one per segment (a crease makes the common
    one miss by a multiple of its angle x reach; noise affects both alike, so a crease lost in
    the noise counts as smooth). Only the points on the corner's own sheet count (links of at
    most ``link``: a thin lip's far side is no crease)."""
    cos_min = np.cos(np.radians(SMOOTH_ANGLE))
    out: dict[int, bool] = {}
    for c, incident in at_corner.items():
        segs = sorted({u for key, _ in incident for u in users[key]})
        idx = np.asarray(tree.query_ball_point(corners[c], reach), dtype=np.int64)
        idx = idx[np.isin(labels[idx], segs)]
        if len(idx) >= 12:
            idx = idx[one_sheet(points[idx], corners[c][None], link, reach, 12)]
        near = points[idx]
        groups = [near[labels[idx] == label] for label in segs]
        if len(segs) < 2 or min(len(g) for g in groups) < 6:
            out[c] = False
            continue
        # Test 1: each segment's own quadric, evaluated AT the corner, gives one normal
        # (exact on clean data; plane normals of the sectors would differ by the curvature
        # across the reach).
        fits = [_quadric(g, corners[c]) for g in groups]
        normals = np.array([
            f[1] if f is not None else np.linalg.svd(g - g.mean(axis=0), full_matrices=False)[2][-1]
            for f, g in zip(fits, groups)
        ])
        if np.abs(normals @ normals.T).min() >= cos_min:
            out[c] = True
            continue
        # Test 2 (noise makes extrapolated normals scatter): one quadric fits about as well
        # as one per segment.
        origin = near.mean(axis=0)
        frame = np.linalg.svd(near - origin, full_matrices=False)[2]
        common = _quadric_rms(near, frame, origin)
        own = np.sqrt(np.mean([_quadric_rms(g, frame, origin) ** 2 for g in groups]))
        out[c] = common <= max(SMOOTH_RATIO * own, SMOOTH_FLOOR * reach)
    return out


def _plane_basis(normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """(2, 3) orthonormal basis of the plane with this normal."""
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(normal, t1)])


def _leg_bases(
    corners: NDArray[np.float64],
    normals: NDArray[np.float64],
    smooth: dict[int, bool],
    users: dict[Key, list[int]],
    sheets: _Sheets,
) -> dict[tuple[int, Key], NDArray[np.float64]]:
    """The directions each edge may leave each of its corners in, (k, 3) per (corner, edge).

    At a smooth corner: the corner's tangent plane. At a crease corner each segment has its
    own tangent plane there, and an edge lies in those of all its segments: one plane for an
    edge inside a smooth pair of segments (or an open edge), the line where the two planes
    meet for a crease edge. (Free 3-D legs let noise kink two crease edges through a corner
    and fold the patch between them, e.g. a cap whose corners are straight angles.)"""
    cos_max = np.cos(np.radians(CREASE_ANGLE))
    at: dict[int, set[int]] = {}
    for key, who in users.items():
        for c in key:
            at.setdefault(c, set()).update(who)
    own: dict[tuple[int, int], NDArray[np.float64]] = {}
    for c, labels in at.items():
        if smooth.get(c, True):
            continue
        # Segments that continue smoothly into each other through the corner share one
        # (averaged) plane, so the crease edges on either side of a smooth seam leave the
        # corner along exactly one line, not two noisy ones.
        found = {label: sheets.project(corners[c][None], label)[1][0] for label in sorted(labels)}
        groups: list[list[int]] = []
        for label, n in found.items():
            for group in groups:
                if abs(float(found[group[0]] @ n)) >= cos_max:
                    group.append(label)
                    break
            else:
                groups.append([label])
        for group in groups:
            ref = found[group[0]]
            mean = np.sum([found[g] * np.sign(found[g] @ ref) for g in group], axis=0)
            for label in group:
                own[(c, label)] = mean / np.linalg.norm(mean)

    def normal_of(c: int, label: int) -> NDArray[np.float64]:
        return own[(c, label)]

    out: dict[tuple[int, Key], NDArray[np.float64]] = {}
    for key, who in users.items():
        for c in key:
            if smooth.get(c, True):
                out[(c, key)] = _plane_basis(normals[c])
                continue
            planes = [normal_of(c, label) for label in who]
            if len(planes) == 2 and abs(float(planes[0] @ planes[1])) < cos_max:
                line = np.cross(planes[0], planes[1])
                out[(c, key)] = (line / np.linalg.norm(line))[None]
            else:
                out[(c, key)] = _plane_basis(planes[0])
    return out


def _end_jumps(spans: int) -> NDArray[np.float64]:
    """Rows (1 or 2, spans + 3) mapping a uniform clamped cubic's control points to the jumps
    of its third derivative at the first and last interior knots, scaled to unit largest
    entry. Zero for a curve that is one cubic over its two end spans: only a hook (an end
    span bending unlike its neighbour) is penalized, not the curvature itself."""
    d3 = BSpline(_knots(spans), np.eye(spans + 3), 3).derivative(3)
    h = 1.0 / spans
    mids = np.array([0.5 * h, 1.5 * h, 1.0 - 1.5 * h, 1.0 - 0.5 * h])
    v = d3(mids)
    rows = np.stack([v[1] - v[0], v[3] - v[2]])
    rows = rows[:1] if spans == 2 else rows
    return rows / np.abs(rows).max(axis=1, keepdims=True)


def _joint_fit(
    data: dict[Key, NDArray[np.float64]],
    params: dict[Key, NDArray[np.float64]],
    spans: dict[Key, int],
    corners: NDArray[np.float64],
    legs: dict[tuple[int, Key], NDArray[np.float64]],
    pairs: dict[int, list[tuple[Key, Key]]],
    scales: dict[tuple[int, Key], float],
    fairness: float = 0.0,
) -> dict[Key, BSpline]:
    """All edges at once: ends on the corners, end legs along ``legs`` (the corner's tangent
    plane, or a crease line), paired edges with opposite end derivatives, ``scales`` times
    one shared vector (where no edge is in two pairs).

    ``fairness`` > 0 adds the squared jumps of each edge's third derivative at its end knots
    (:func:`_end_jumps`), weighted ``fairness x`` (data points per control point), as
    zero-valued pseudo data: a curve that is one cubic over its end spans is not affected,
    but an end span cannot hook towards a few noisy points near a corner (measured on sparse
    cube-spheres: end hooks of 15-28 deg)."""
    basis = dict(legs)
    # Leg unknowns: one k-vector per (corner, edge end), shared (with a signed scale) by a pair.
    leg_var: dict[tuple[int, Key], tuple[int, float]] = {}
    n_var = 0
    for c, plist in pairs.items():
        seen = [e for p in plist for e in p]
        if len(seen) != len(set(seen)):
            continue  # irregular corner: no pairing
        for ea, eb in plist:
            basis[(c, eb)] = basis[(c, ea)]  # one shared leg, so one set of directions
            leg_var[(c, ea)] = (n_var, scales.get((c, ea), 1.0))
            leg_var[(c, eb)] = (n_var, -scales.get((c, eb), 1.0))
            n_var += len(basis[(c, ea)])
    offsets: dict[Key, int] = {}
    for key in data:
        for c in key:
            if (c, key) not in leg_var:
                leg_var[(c, key)] = (n_var, 1.0)
                n_var += len(basis[(c, key)])
    for key in data:
        offsets[key] = n_var
        n_var += 3 * (spans[key] - 1)

    splines: dict[Key, BSpline] = {}
    for _ in range(REPARAM_ROUNDS):
        rows, cols, vals, rhs = [], [], [], []
        row0 = 0
        for key, pts_e in data.items():
            s = spans[key]
            b = _design(params[key], s)  # (K, s + 3)
            if fairness > 0 and s > 1:
                # Third-derivative jumps at the end knots as extra rows with target 0.
                jumps = _end_jumps(s) * np.sqrt(fairness * len(b) / (s + 3))
                b = np.vstack([b, jumps])
                pts_e = np.vstack([pts_e, np.zeros((len(jumps), 3))])
            k = len(pts_e)
            p0, p1 = corners[key[0]], corners[key[1]]
            target = pts_e - np.outer(b[:, 0], p0) - np.outer(b[:, -1], p1)
            target -= np.outer(b[:, 1], p0) + np.outer(b[:, -2], p1)
            # Legs: P1 = p0 + sign/(3 s) G t, the derivative away from the corner being G t
            # (dP/dt = 3 s (P1 - P0) on a uniform clamped cubic with s spans).
            for col, c in ((1, key[0]), (s + 1, key[1])):
                var, sign = leg_var[(c, key)]
                scale = sign / (3.0 * s)
                for d in range(3):
                    for j in range(len(basis[(c, key)])):
                        rows.append(row0 + d * k + np.arange(k))
                        cols.append(np.full(k, var + j))
                        vals.append(b[:, col] * scale * basis[(c, key)][j, d])
            for i in range(s - 1):
                for d in range(3):
                    rows.append(row0 + d * k + np.arange(k))
                    cols.append(np.full(k, offsets[key] + 3 * i + d))
                    vals.append(b[:, 2 + i])
            rhs.append(target.T.reshape(-1))
            row0 += 3 * k
        a = coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(row0, n_var)
        ).tocsr()
        normal = (a.T @ a).tocsc()
        scale = max(float(normal.diagonal().max()), 1e-300)
        z = spsolve(normal + RIDGE * scale * identity(n_var, format="csc"), a.T @ np.concatenate(rhs))
        for key, pts_e in data.items():
            s = spans[key]
            ctrl = np.zeros((s + 3, 3))
            p0, p1 = corners[key[0]], corners[key[1]]
            ctrl[0], ctrl[-1] = p0, p1
            for col, c, p in ((1, key[0], p0), (s + 1, key[1], p1)):
                var, sign = leg_var[(c, key)]
                leg = basis[(c, key)]
                ctrl[col] = p + sign / (3.0 * s) * (z[var : var + len(leg)] @ leg)
            if s > 1:
                ctrl[2 : s + 1] = z[offsets[key] : offsets[key] + 3 * (s - 1)].reshape(-1, 3)
            splines[key] = BSpline(_knots(s), ctrl, 3)
            params[key] = _project(splines[key], pts_e, params[key])
    return splines


def _to_bezier(
    spline: BSpline, spans: int, start: NDArray[np.float64], end: NDArray[np.float64]
) -> PiecewiseBezier:
    """Exact Bézier pieces of a uniform clamped cubic spline, ends set bitwise to the corners."""
    breaks = np.linspace(0.0, 1.0, spans + 1)
    values = spline(breaks)
    values[0], values[-1] = start, end
    d = spline.derivative(1)
    h = 1.0 / spans
    left, right = d(breaks[:-1]), d(breaks[1:])  # a C2 spline: one derivative per break
    ctrl = np.stack([values[:-1], values[:-1] + h / 3 * left, values[1:] - h / 3 * right, values[1:]], 1)
    return PiecewiseBezier(ctrl, breaks)


__all__ = ["EdgeNetwork", "build_edges", "key_of"]
