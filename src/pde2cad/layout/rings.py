"""Cut segments with several boundary loops (rings, tubes, sheets with a hole) into quads.

The layout keeps one boundary loop per segment, so a segment whose boundary falls into two
loops (an annulus of a torus labelled as rings, a tube given as one segment, a sheet with a
hole) cannot become one patch. :func:`split_rings` cuts each such segment into 4-sided
pieces along seams chosen on the surface:

1. **Boundary loops.** The segment's points (at most ``SCAN_POINTS`` of them, a random subset)
   next to another label or on the open boundary
   (the directions to their ``OPEN_NEIGHBOURS`` nearest neighbours leave a gap wider than
   ``OPEN_GAP`` in the tangent plane), grouped into connected components; those spanning
   more than ``BORDER_SPAN`` radii are loops.
2. **Coordinates.** With two loops, ``t = d0 / (d0 + d1)`` from the shortest-path distances
   on the surface to each loop runs across the ring; an angle ``theta`` runs round it, about
   the centroid of the points of equal ``t`` in the plane of their ring (PCA), with frames
   carried along ``t`` by parallel transport and interpolated between ``RING_BINS`` bins.
3. **Cuts.** On each loop, 4 cut angles: where the loop already has corners (3 or 4 kept
   corners of the layout, or the cut ends of a ring cut before it across that loop) at
   those, otherwise evenly round (the other loop's if it has them). Cut ``k`` runs from its
   angle on loop 0 to the matched one on loop 1, linear in ``t``; a ring whose length
   across is ``ASPECT`` times its pieces' width or more is also cut at levels of ``t``.

Rings are cut in turn, so a ring next to one already cut ends its cuts where that ring's
cuts end: the pieces meet at 4-valent corners on the shared loop.

Segments with 3 or more loops (a face with several holes) are cut first, by
:func:`~pde2cad.layout.holes.cut_holes`; a ring with 2 or more of their cut ends on a loop
cuts there, at every one of them (the wall of a bolt hole, the rim of a flange).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.layout.adjacency import BORDER_SPAN, CLUSTER_FACTOR, Layout
from pde2cad.layout.holes import cut_holes

#: Neighbours per point whose directions tell an open-boundary point.
OPEN_NEIGHBOURS = 30
#: An open-boundary point leaves a gap this wide (degrees) between the directions to its
#: neighbours in its tangent plane. Measured on random samples: 99 % of the points within
#: half a spacing of a rim over 150, 1 in 6000 inside over 120 (isolated: no loop).
OPEN_GAP = 120.0
#: Neighbours (within the layout's radius) per point that tell a point next to another label.
BORDER_NEIGHBOURS = 12
#: Points of a segment scanned for boundary loops (a random subset of larger segments; the
#: loops are linked over the subset's wider spacing).
SCAN_POINTS = 20000
#: Boundary points closer than this many neighbour radii are one loop.
LINK_RADII = 2.0
#: Neighbours per point of the graph whose shortest paths measure distances on the surface.
GRAPH_NEIGHBOURS = 8
#: A loop's points surround their centroid: in at least LOOP_COVER of LOOP_SECTORS equal
#: sectors round it in their PCA plane (noise leaves chains and clusters of rim-like points
#: inside a segment, seen in 1-30 point groups at 0.5 % noise).
LOOP_SECTORS = 16
LOOP_COVER = 14
#: Bins of ``t`` whose centroids and planes carry the angle round a ring.
RING_BINS = 12
#: Cuts round a ring without corners.
CUTS = 4
#: ... or 3 where a piece's side along the shorter loop would be under MIN_SIDE neighbour
#: radii (the teapot's handle at 112k points: 4.5; its corners merged).
MIN_SIDE = 6.0
#: A ring this many times longer across than its pieces are wide is cut across too (at 2,
#: a quarter torus tube, 2.7 times, went into 3 slices of ~400 points each, and with 0.2 %
#: noise one of them folded: 71 degrees; uncut it fits at 0.000).
ASPECT = 3.0
#: ... but into no more slices than leave RING_PIECE_POINTS points a piece (the teapot's
#: handle at 112k points: 5 slices of 180-point pieces, whose corners the layout merged).
RING_PIECE_POINTS = 400


def surface_graph(points: NDArray[np.float64]) -> csr_matrix:
    """Symmetric k-NN graph (CSR, edge lengths) of ``points``: its shortest paths measure
    distances along the surface."""
    k = min(GRAPH_NEIGHBOURS + 1, len(points))
    dist, idx = cKDTree(points).query(points, k=k)
    rows = np.repeat(np.arange(len(points)), k - 1)
    graph = coo_matrix((dist[:, 1:].ravel(), (rows, idx[:, 1:].ravel())), shape=(len(points),) * 2)
    return graph.tocsr().maximum(graph.T.tocsr())


def open_gaps(rel: NDArray[np.float64]) -> NDArray[np.float64]:
    """Widest gap (degrees) between the directions from each point to its neighbours in its
    tangent plane (PCA of the neighbours); ``rel``: (P, k, 3) neighbour offsets."""
    cov = np.transpose(rel, (0, 2, 1)) @ rel
    axes = np.linalg.eigh(cov)[1]
    ang = np.sort(np.arctan2(
        np.einsum("pki,pi->pk", rel, axes[:, :, 1]), np.einsum("pki,pi->pk", rel, axes[:, :, 2])
    ), axis=1)
    gaps = np.diff(np.concatenate([ang, ang[:, :1] + 2 * np.pi], axis=1), axis=1)
    return np.degrees(gaps.max(axis=1))


def _surrounds(pts: NDArray[np.float64]) -> bool:
    """Whether points (a component of boundary points) run round their centroid: a loop,
    not a chain or a cluster (``LOOP_COVER`` of ``LOOP_SECTORS`` sectors hold points)."""
    if len(pts) < 2 * LOOP_SECTORS:
        return False
    c = pts.mean(axis=0)
    axes = np.linalg.svd(pts - c, full_matrices=False)[2]
    rel = (pts - c) @ axes[:2].T
    sector = ((np.arctan2(rel[:, 1], rel[:, 0]) + np.pi) / (2 * np.pi) * LOOP_SECTORS).astype(np.int64)
    return int(np.unique(np.clip(sector, 0, LOOP_SECTORS - 1)).size) >= LOOP_COVER


def boundary_loops(
    points: NDArray[np.float64], labels: NDArray[np.int64], tree: cKDTree, label: int,
    radius: float, crossed: set[int] | None = None,
) -> list[tuple[NDArray[np.int64], bool]]:
    """Step 1: the boundary loops of a segment (next to no segment of ``crossed``: those
    that cross it, as the teapot's body its spout, see ``Layout.crossing``).

    Returns
    -------
    list of ((m,) int, bool)
        Each loop's points (indices into ``points``) and whether it is open (most of its
        points lie on the open boundary, not next to another label); largest first.
    """
    members = np.flatnonzero(labels == label)
    step = max(1, len(members) // SCAN_POINTS)
    if step > 1:
        members = np.sort(np.random.default_rng(0).choice(members, len(members) // step, replace=False))
    dist, idx = tree.query(points[members], k=min(BORDER_NEIGHBOURS + 1, len(points)),
                           distance_upper_bound=radius)
    hit = idx < len(points)
    other = labels[np.where(hit, idx, 0)]
    border = (hit & (other != label) & ~np.isin(other, list(crossed or ()))).any(axis=1)
    own = points[members]
    idx = cKDTree(own).query(own, k=min(OPEN_NEIGHBOURS + 1, len(own)))[1]
    rim = open_gaps(own[idx[:, 1:]] - own[:, None]) > OPEN_GAP
    edge, on_rim = members[border | rim], rim[border | rim] & ~border[border | rim]
    if len(edge) < 2:
        return []
    pairs = cKDTree(points[edge]).query_pairs(LINK_RADII * radius * np.sqrt(step), output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(edge),) * 2)
    n, comp = connected_components(graph, directed=False)
    loops = []
    for c in range(n):
        pts = points[edge[comp == c]]
        if np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)) > BORDER_SPAN * radius and _surrounds(pts):
            loops.append((edge[comp == c], bool(on_rim[comp == c].mean() > 0.5)))
    return sorted(loops, key=lambda lp: len(lp[0]), reverse=True)


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def ring_coordinates(
    points: NDArray[np.float64], near: list[NDArray[np.int64]]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Step 2: ``t`` (0 on loop 0, 1 on loop 1) and ``theta`` (radians) of a ring's
    ``points``; ``near[j]``: indices of the points on loop ``j``.

    Returns
    -------
    t, theta : (P,) float
    length : float
        Mean distance across the ring (``d0 + d1``).
    """
    graph = surface_graph(points)
    d = np.stack([dijkstra(graph, indices=np.unique(n), min_only=True) for n in near])
    finite = np.isfinite(d)
    d = np.where(finite, d, d[finite].max() if finite.any() else 1.0)
    t = d[0] / np.maximum(d[0] + d[1], 1e-300)
    edges = np.linspace(0.0, 1.0, RING_BINS + 1)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, RING_BINS - 1)
    centre: list[NDArray[np.float64]] = []
    normal: list[NDArray[np.float64]] = []
    first: list[NDArray[np.float64]] = []
    for b in range(RING_BINS):
        ring = points[which == b]
        if len(ring) < 3:
            continue
        c = ring.mean(axis=0)
        n = np.linalg.svd(ring - c, full_matrices=False)[2][-1]
        if normal:
            n = n if n @ normal[-1] >= 0 else -n
            e = first[-1] - (first[-1] @ n) * n
        else:
            e = np.linalg.svd(ring - c, full_matrices=False)[2][0]
        centre.append(c)
        normal.append(n)
        first.append(_unit(e))
    mid = np.array([t[which == b].mean() for b in range(RING_BINS) if (which == b).sum() >= 3])
    frame = [np.column_stack([np.interp(t, mid, np.asarray(a)[:, k]) for k in range(3)])
             for a in (centre, normal, first)]
    n, e1 = _unit(frame[1]), frame[2]
    e1 = _unit(e1 - np.sum(e1 * n, axis=1, keepdims=True) * n)
    e2 = np.cross(n, e1)
    rel = points - frame[0]
    theta = np.arctan2(np.sum(rel * e2, axis=1), np.sum(rel * e1, axis=1))
    return t, theta, float(np.mean(d[0] + d[1]))


def _wrap(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angles into [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def _match(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cut angles ``b`` (sorted, as many as ``a``) in the cyclic order that twists least
    from ``a``, unwrapped to lie within pi of them."""
    shifts = [np.roll(b, s) for s in range(len(b))]
    best = min(shifts, key=lambda s: float(np.abs(_wrap(s - a)).sum()))
    return a + _wrap(best - a)


def ring_pieces(
    t: NDArray[np.float64], theta: NDArray[np.float64], cuts: tuple[NDArray[np.float64], ...],
    slices: int,
) -> NDArray[np.int64]:
    """Step 3: piece index of each point: its sector between consecutive cuts (cut ``k`` at
    ``cuts[0][k]`` on loop 0, at the matched angle of ``cuts[1]`` on loop 1, linear in
    ``t``) times ``slices`` equal steps of ``t``."""
    a = np.sort(cuts[0])
    b = _match(a, np.sort(cuts[1]))
    at = a[None, :] + t[:, None] * (b - a)[None, :]  # (P, K)
    behind = (theta[:, None] - at) % (2 * np.pi)
    sector = np.argmin(behind, axis=1)
    step = np.minimum((t * slices).astype(np.int64), slices - 1)
    return sector * slices + step


def _marks_on(
    loop_pts: NDArray[np.float64], marks: NDArray[np.float64], reach: float
) -> NDArray[np.float64] | None:
    """The ``marks`` (corners, cut ends) within ``reach`` of a loop's points; None unless
    there are 3 or 4 (a cut per mark)."""
    if not len(marks):
        return None
    dist, _ = cKDTree(loop_pts).query(marks)
    on = marks[dist <= reach]
    return on if len(on) in (3, 4) else None


def _loop_marks(
    loop_pts: NDArray[np.float64], marks: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    rim: bool, reach: float,
) -> NDArray[np.float64] | None:
    """The marks a ring's cuts end at on one loop (:func:`_cut_angles`), or None."""
    ends = _ends_on(loop_pts, marks[2], reach)
    if ends is not None:
        return ends
    return _marks_on(loop_pts, np.vstack([marks[0], marks[1]]) if rim else marks[0], reach)


def _ends_on(loop_pts: NDArray[np.float64], ends: NDArray[np.float64], reach: float) -> NDArray[np.float64] | None:
    """The ``ends`` (of the cuts of a segment with holes) within ``reach`` of a loop's
    points; None unless there are 2 or more."""
    if not len(ends):
        return None
    on = ends[cKDTree(loop_pts).query(ends)[0] <= reach]
    return on if len(on) >= 2 else None


def junction_corners(
    layout: Layout, tree: cKDTree, labels: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The layout's corners that a ring's cuts must end at: within ``CLUSTER_FACTOR`` radii
    of 3 segments, and (second) those it puts on the open boundary, which count only on an
    open loop (a ring's folded projected loop makes spurious corners, taken for rim ones)."""
    keep = np.zeros(len(layout.corners), dtype=bool)
    for i, c in enumerate(layout.corners):
        near = tree.query_ball_point(c, CLUSTER_FACTOR * layout.radius)
        keep[i] = len(np.unique(labels[near])) >= 3
    rim = np.zeros_like(keep) if layout.open_corners is None else layout.open_corners & ~keep
    return layout.corners[keep], layout.corners[rim]


def _cut_angles(
    points: NDArray[np.float64], members: NDArray[np.int64],
    loops: list[tuple[NDArray[np.int64], bool]], theta: NDArray[np.float64],
    marks: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], reach: float,
) -> list[NDArray[np.float64]]:
    """Step 3's cut angles on both loops: at the ends of the cuts of a segment with holes
    on a loop (``marks[2]``, 2 or more: every one is a corner there), else at the marks on
    it (``marks``: junctions and cut ends; rim corners, counted on open loops), else the
    other loop's, else ``CUTS`` evenly round from the first loop point."""
    tree = cKDTree(points[members])
    found = [_loop_marks(points[lp], marks, rim, reach) for lp, rim in loops]
    c0, c1 = (None if f is None else theta[tree.query(f)[1]] for f in found)
    if c0 is None and c1 is None:
        start = theta[np.searchsorted(members, loops[0][0][0])]
        # Fewer pieces round a tube too thin for 4 sides the layout can tell apart.
        shortest = min(_loop_length(points[lp]) for lp, _ in loops)
        cuts = CUTS if shortest >= CUTS * MIN_SIDE * reach / CLUSTER_FACTOR else 3
        c0 = _wrap(start + np.arange(cuts) * 2 * np.pi / cuts)
    if c0 is None or (c1 is not None and len(c1) > len(c0)):
        c0 = c1
    assert c0 is not None
    if c1 is None or len(c1) != len(c0):
        c1 = c0
    return [c0, c1]


def split_rings(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    first_new: int,
) -> tuple[NDArray[np.int64], dict[int, list[int]], dict[int, int]]:
    """Cut every segment with two boundary loops into 4-sided pieces (module docstring),
    and before them every segment with 3 or more (:func:`~pde2cad.layout.holes.cut_holes`).

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
    layout : Layout
        Of ``points``, ``labels``.
    tree : cKDTree
        Of ``points``.
    first_new : int
        Smallest label for a new piece.

    Returns
    -------
    labels : (N,) int
        The input array when no segment has two loops.
    pieces : dict[int, list[int]]
        Per cut segment, its pieces' labels (the first is the segment's own).
    holed : dict[int, int]
        The cut segments with 3 or more loops, and how many.

    Raises
    ------
    InputError
        A segment with 3 or more boundary loops that
        :func:`~pde2cad.layout.holes.cut_holes` cannot cut into rings.
    """
    reach = CLUSTER_FACTOR * layout.radius
    junctions, rims = junction_corners(layout, tree, labels)
    out, pieces = labels, dict[int, list[int]]()
    loops_of = {label: boundary_loops(points, labels, tree, label, layout.radius, layout.crossed(label))
                for label in (int(v) for v in layout.labels_present)}
    # Segments with holes first: the rings beyond their loops (the holes' walls) end their
    # cuts where theirs end.
    ends = np.zeros((0, 3))
    for label, loops in loops_of.items():
        if len(loops) > 2:
            # Rim corners count on open loops only (as for rings: a folded projected loop
            # makes spurious ones).
            rim = [lp for lp, is_open in loops if is_open]
            near = np.zeros(len(rims), dtype=bool)
            if rim and len(rims):
                near = cKDTree(points[np.concatenate(rim)]).query(rims)[0] <= reach
            known = np.vstack([junctions, rims[near], ends])
            out, ends = _cut_holed(points, labels, out, label, loops, known, layout.radius, pieces,
                                   first_new, ends)
    for label, loops in loops_of.items():
        if len(loops) != 2:
            continue
        members = np.flatnonzero(labels == label)
        t, theta, length = ring_coordinates(points[members], [np.searchsorted(members, lp) for lp, _ in loops])
        cut = _cut_angles(points, members, loops, theta, (junctions, rims, ends), reach)
        width = float(np.mean([_loop_length(points[lp]) for lp, _ in loops])) / len(cut[0])
        slices = int(round(length / width)) if length >= ASPECT * width else 1
        # Pieces too small for the layout to tell their corners apart are worse than long ones.
        slices = max(1, min(slices, len(members) // (len(cut[0]) * RING_PIECE_POINTS)))
        cell = np.unique(ring_pieces(t, theta, (cut[0], cut[1]), slices), return_inverse=True)[1]
        out = out.copy() if out is labels else out
        start = max(int(out.max()) + 1, first_new)
        names = [label] + list(range(start, start + int(cell.max())))
        out[members] = np.asarray(names)[cell.reshape(-1)]
        pieces[label] = names
        junctions = np.vstack([junctions, _cut_ends(points[members], t, theta, cut)])
    return out, pieces, {label: len(loops) for label, loops in loops_of.items() if len(loops) > 2}


def _cut_holed(
    points: NDArray[np.float64], labels: NDArray[np.int64], out: NDArray[np.int64], label: int,
    loops: list[tuple[NDArray[np.int64], bool]], known: NDArray[np.float64], radius: float,
    pieces: dict[int, list[int]], first_new: int, ends: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Cut a segment with 3 or more loops into quads (:func:`~pde2cad.layout.holes.cut_holes`,
    ending at the ``known`` corners on its loops); returns the labels (a copy of ``labels``
    on the first cut) and ``ends`` with its cuts' ends added; records its pieces' labels."""
    members = np.flatnonzero(labels == label)
    local = [np.searchsorted(members, lp) for lp, _ in loops]
    reach = CLUSTER_FACTOR * radius
    if len(known):
        near = cKDTree(points[np.concatenate([lp for lp, _ in loops])]).query(known)[0] <= reach
        known = known[near]
    try:
        piece, new = cut_holes(points[members], local, radius, known)
    except InputError as err:
        raise InputError(f"segment {label} has {len(loops)} boundary loops and could not be cut "
                         f"into quads ({err}); split it so that no piece has more than one hole") from err
    out = out.copy() if out is labels else out
    start = max(int(out.max()) + 1, first_new)
    names = [label] + list(range(start, start + int(piece.max())))
    out[members] = np.asarray(names)[piece]
    pieces[label] = names
    return out, np.vstack([ends, new])


def _loop_length(loop_pts: NDArray[np.float64]) -> float:
    """Length of a loop given as an unordered band of points: its points' spread round
    their centroid in their PCA plane, 2 pi x the mean distance from the centroid."""
    c = loop_pts.mean(axis=0)
    axes = np.linalg.svd(loop_pts - c, full_matrices=False)[2]
    rel = (loop_pts - c) @ axes[:2].T
    return float(2 * np.pi * np.linalg.norm(rel, axis=1).mean())


def _cut_ends(
    points: NDArray[np.float64], t: NDArray[np.float64], theta: NDArray[np.float64],
    cut: list[NDArray[np.float64]],
) -> NDArray[np.float64]:
    """The points where a ring's cuts meet its two loops (the nearest point in angle among
    those of the lowest and highest ``t``)."""
    out = []
    for j, side in enumerate((t <= np.quantile(t, 0.02), t >= np.quantile(t, 0.98))):
        idx = np.flatnonzero(side)
        for c in cut[j]:
            out.append(points[idx[np.argmin(np.abs(_wrap(theta[idx] - c)))]])
    return np.array(out)


__all__ = [
    "boundary_loops", "junction_corners", "ring_coordinates", "ring_pieces", "split_rings",
    "surface_graph",
]
