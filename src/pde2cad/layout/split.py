"""Split segments that are no 3- or 4-sided region into 3/4-sided sub-segments.

A segmentation made by hand or by region growing rarely gives every segment three or four
corners: two patches merged give a hexagon, and their neighbours keep the old corner on
their side (a T-junction, which makes them pentagons); a tube or a sphere given as one
segment has no corner at all. :func:`split_segments` relabels the points so that every
segment becomes 3/4-sided, and builds the layout again: the new seams are ordinary shared
edges (one curve fitted on the surface, shared ribbons for C1). It works at the label level,
between :func:`~pde2cad.layout.adjacency.build_layout` and
:func:`~pde2cad.layout.edges.build_edges`:

1. **Tubes in halves.** Two neighbours sharing more than the 2 corners of one edge (they
   meet along two borders) are merged when together they have no corner.
2. **No corners.** A segment without corners that touches nothing and is seen from its
   centroid in every direction is closed: cut into the 6 faces of a cube map. Otherwise
   into 4 sectors around the PCA axis it wraps round (a tube's axis; a disc's normal).
3. **Rounds** (up to ``MAX_ROUNDS``, each on a new layout), for every segment with more than
   4 corners (the corners :func:`~pde2cad.layout.edges.build_edges` keeps, in the order of
   its boundary loop):

   a. *Corner angles* on the surface, between the directions in which the sides leave a
      corner (from the boundary loop a little away from the corner, in its tangent plane),
      signed so that a reflex corner reads over 180 degrees. Border kinks (both sides on the
      same neighbour, a straight angle) are dropped from the layout: no T-node.
   b. *Reflex corners* (over ``REFLEX_ANGLE``): cut along the continuations of their sides.
   c. *A quad with T-nodes* (all but 4 corners at straight angles, ``FLAT_ANGLE``): strip
      cuts, level sets of coordinates from the shortest-path distances to the 4 sides (so
      they follow the surface). T-nodes on opposite sides are joined; a lone one is cut
      straight across, which makes a T-node of the neighbour there, cut in the next round:
      the cut runs along the strip of quads until it meets an open boundary or closes, and
      every corner keeps four patches (exact C1).
   d. *Otherwise* chords between corners, chosen recursively so that the pieces' corner
      angles deviate least from 90 (quads) or 60 (triangles) degrees; straight cuts in the
      PCA plane.
   e. *No segment left with more than 4 corners*: the halves of a tube (two sides on one
      neighbour) are cut apart, else every quad whose surface turns ~170 degrees or more
      (``WIDE_COS``: a C-shaped wall's face) is halved across its length; their neighbours'
      new T-nodes are cut in the next rounds. A cut the merges undo lets the segments
      that waited for it go first in the next round.

After every step that cuts (rings, sectors, each round, the parts a cut leaves apart), a
piece with fewer than ``MIN_PIECE_POINTS`` points merges into the neighbour it shares the
longest border with (:func:`_settle`; not into the other half of a cut in two while it has
another neighbour); the corners this moves are split in the next round. A piece still not
3/4-sided after the rounds raises an :class:`~pde2cad.errors.InputError` naming the input
segment.

Before these steps, segments with two boundary loops (rings, tubes, a sheet with a hole) are
cut by :func:`~pde2cad.layout.rings.split_rings`, and segments with more (a face with
several holes) by :func:`~pde2cad.layout.holes.cut_holes` before them, and before every round the layout gets
the corners where two segments' loops turn sharply together (:func:`_add_sharp_turns`: the
ends of the former shared edge of two merged cube-sphere faces touch only two labels, which
the layout drops as kinks). A segment all but 4 of whose corners read straight or wider is
a quad with T-nodes (c), whatever the widest read (240 degrees there).

Limits: the layout must see the corners; a segment with 3 or more boundary loops is cut only
when the cells round its loops are rings (see :mod:`~pde2cad.layout.holes`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.layout.adjacency import (
    Layout,
    build_layout,
    merge_small,
    plane_score,
    separate_pieces,
)
from pde2cad.layout.edges import filter_corners
from pde2cad.layout.rings import boundary_loops, split_rings
from pde2cad.surfaces.region import pca_frame

#: Fewest points of a piece of a split segment (as ``build_layout``'s ``min_points``, which
#: refuses smaller segments: the pipeline fits an edge-curve band and a deformation per
#: patch); smaller pieces join a neighbour (:func:`_settle`).
MIN_PIECE_POINTS = 50
#: Largest corner count split, and the largest split by trying every chord of every piece
#: (larger ones are halved first; a crease-bounded face of a CAD part can have 15-30).
MAX_CORNERS = 40
EXACT_CORNERS = 12
#: Corner normals: PCA of the segment's points within this many neighbour radii.
CORNER_REACH = 4.0
#: Side directions at a corner: from LOOP_FROM to LOOP_TO x CORNER_REACH of loop arc away.
LOOP_FROM = 0.5
LOOP_TO = 1.5
#: A corner whose sides leave it at this angle or more (degrees) is a T-node (a neighbour's
#: corner on a straight side). Measured: T-nodes 150-178, real corners of torus patches
#: 65-125.
FLAT_ANGLE = 145.0
#: Neighbours per point of the graph whose shortest paths measure distances on the surface.
GRAPH_NEIGHBOURS = 8
#: Neighbours per side point that tell which segment lies across a side.
SIDE_NEIGHBOURS = 12
#: A segment without corners is cut into sectors only when each holds this share of it.
MIN_SECTOR_SHARE = 0.05
#: A segment without neighbours is closed when seen from its centroid in every cell of a
#: CLOSED_BINS x CLOSED_BINS grid on each cube-map face (a tube leaves its end faces empty).
CLOSED_BINS = 4
#: Corners above this angle (degrees) are reflex (an L-shape's inner corner: 270); between
#: FLAT_ANGLE and it, T-nodes (sparse random samples: a T-node measured 231 at 8000 points
#: on a torus).
REFLEX_ANGLE = 245.0
#: A corner is reflex when the loop turns clockwise there about a normal within
#: arccos(REFLEX_COS) of the (counter-clockwise oriented) PCA normal.
REFLEX_COS = 0.5
#: Split rounds (each builds the layout again): strip cuts move a T-node along a strip;
#: the main split takes at least as many rounds as there are pieces when it starts.
MAX_ROUNDS = 12
#: A tube (merged halves) whose two boundary loops lie closer than NARROW_RING radii (median)
#: is merged into the neighbour it shares the most border with.
NARROW_RING = 6.0
#: A piece holds the input segments that make up this share of its points.
SOURCE_SHARE = 0.1
#: A quad is halved when no plane sees it within this cosine (FRAME_QUANTILE of its
#: normals): its surface turns by ~170 degrees or more. Measured: bands of a cylinder
#: turning 150 / 180 / 300 deg 0.29 / 0.05 / 0.07; the cube-map faces of a noisy
#: 1 x 0.6 x 0.35 ellipsoid, which fit as they are, 0.18-0.22.
WIDE_COS = 0.12
#: Ideal corner angle (degrees) of a piece with 3 and with 4 corners.
IDEAL_ANGLE = {3: 60.0, 4: 90.0}


@dataclass(frozen=True)
class SplitReport:
    """What :func:`split_segments` did.

    Attributes
    ----------
    pieces : dict[int, list[int]]
        Per split input label, the labels of its pieces (the first is the label itself).
    corners : dict[int, int]
        Per split input label, how many corners it had.
    merged : dict[int, int]
        Input labels merged into another before splitting (two segments meeting along two
        borders, e.g. the halves of a tube, together a segment without corners).
    rings : list[int]
        Input labels with two or more boundary loops (rings, tubes, sheets with holes), cut
        by :func:`~pde2cad.layout.rings.split_rings` (their ``corners``: 0).
    loops : dict[int, int]
        Of those, the ones with 3 or more loops (faces with holes) and how many.
    fenced : bool
        Whether pieces of different input segments were kept from merging (segments bounded
        by sharp edges: a merge would round a crease off).
    """

    pieces: dict[int, list[int]] = field(default_factory=dict)
    corners: dict[int, int] = field(default_factory=dict)
    merged: dict[int, int] = field(default_factory=dict)
    rings: list[int] = field(default_factory=list)
    loops: dict[int, int] = field(default_factory=dict)
    fenced: bool = False

    def apart(self, a: int, b: int) -> bool:
        """Whether labels ``a`` and ``b`` must not merge: ``fenced`` and pieces of
        different input segments."""
        if not self.fenced:
            return False
        origin = {p: first for first, pieces in self.pieces.items() for p in pieces}
        return origin.get(a, a) != origin.get(b, b)

    def summary(self) -> str:
        """One line per split label, e.g. ``segment 3: 6 corners -> 2 pieces [3, 9]``."""
        lines = [f"segment {b}: merged into {a}" for b, a in sorted(self.merged.items())]
        return "\n".join(lines + [
            f"segment {label}: "
            + (f"{self.loops.get(label, 2)} boundary loops" if label in self.rings
               else f"{self.corners[label]} corners")
            + f" -> {len(p)} pieces {p}"
            for label, p in sorted(self.pieces.items())
        ])


def _angle(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Angle (degrees) between two vectors."""
    cos = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-300)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def best_split(directions: dict[tuple[int, int], NDArray[np.float64]], n: int) -> list[tuple[int, ...]]:
    """Pieces (tuples of corner positions ``0 .. n - 1`` in loop order) of 3 or 4 corners.

    Step 2 of the module docstring: recursive chords, cost = the largest deviation of a
    piece's corner angle from its ideal. ``directions[(i, j)]`` is the direction in which
    the side or chord from corner ``i`` to corner ``j`` leaves ``i`` (in its tangent plane);
    a polygon of 3 or 4 corners is one piece.
    """

    def cost(ids: tuple[int, ...]) -> float:
        k = len(ids)
        dev = [
            abs(_angle(directions[(ids[s], ids[s - 1])], directions[(ids[s], ids[(s + 1) % k])])
                - IDEAL_ANGLE[k])
            for s in range(k)
        ]
        return max(dev)

    @lru_cache(maxsize=None)
    def solve(ids: tuple[int, ...]) -> tuple[float, tuple[tuple[int, ...], ...]]:
        if len(ids) in IDEAL_ANGLE:
            return cost(ids), (ids,)
        best: tuple[float, tuple[tuple[int, ...], ...]] = (np.inf, ())
        m = len(ids)
        # Every chord up to EXACT_CORNERS corners; beyond, only the chords that halve the
        # polygon (the exhaustive search grows ~1.7x per corner: 0.8 s at 16).
        chords = ([(i, j) for i in range(m) for j in range(i + 2, m)] if m <= EXACT_CORNERS
                  else [(i, i + m // 2) for i in range((m + 1) // 2)])
        for i, j in chords:
            if i == 0 and j == m - 1:
                continue
            ca, pa = solve(ids[i : j + 1])
            if ca >= best[0]:
                continue
            cb, pb = solve(ids[j:] + ids[: i + 1])
            if max(ca, cb) < best[0]:
                best = (max(ca, cb), pa + pb)
        return best

    return list(solve(tuple(range(n)))[1])


def _directions(
    points: NDArray[np.float64], loop: NDArray[np.float64], xyz: NDArray[np.float64],
    axis: NDArray[np.float64], reach: float,
) -> dict[tuple[int, int], NDArray[np.float64]]:
    """Directions leaving each corner (``xyz``, in loop order) towards every other corner, in
    its tangent plane (PCA of the segment's ``points`` within ``reach``).

    To its loop neighbours: along the boundary loop, from the loop point ``LOOP_FROM x
    reach`` of arc away to the one ``LOOP_TO x reach`` away (at most a quarter and half of
    the way to them): not from the corner itself, which may lie up to a neighbour radius off
    its sides (that tilted a T-node's straight angle to ~150 degrees), and not far along a
    curved side (a chord over it turns with the side). To the others: along the cut that
    :func:`_assign_pieces` makes, the surface's intersection with the plane through both
    corners and the segment's PCA normal ``axis``."""
    n = len(xyz)
    _, at = cKDTree(loop).query(xyz)
    tree = cKDTree(points)
    out: dict[tuple[int, int], NDArray[np.float64]] = {}
    for i in range(n):
        near = points[tree.query_ball_point(xyz[i], reach)]
        if len(near) < 3:
            near = points[tree.query(xyz[i], k=min(len(points), 12))[1]]
        normal = np.linalg.svd(near - near.mean(axis=0), full_matrices=False)[2][-1]
        for j in range(n):
            if j == i:
                continue
            if j in ((i + 1) % n, (i - 1) % n):
                sign = 1 if j == (i + 1) % n else -1
                run = (np.arange(len(loop)) * sign + at[i]) % len(loop)
                stop = int(np.flatnonzero(run == at[j])[0])
                path = loop[run[: stop + 1]]
                arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
                lo = min(int(np.searchsorted(arc, LOOP_FROM * reach)), stop // 4)
                hi = min(max(min(int(np.searchsorted(arc, LOOP_TO * reach)), stop // 2),
                             lo + 1), stop)
                # Two corners on one loop sample (stop 0): the chord is all there is.
                d = path[hi] - path[lo] if hi > lo else xyz[j] - xyz[i]
            else:
                d = np.cross(normal, np.cross(xyz[j] - xyz[i], axis))
                if d @ (xyz[j] - xyz[i]) < 0:
                    d = -d
            out[(i, j)] = d - (d @ normal) * normal
    return out


def _ordered_corners(
    layout: Layout, points: NDArray[np.float64], label: int, ids: list[int], corners: NDArray[np.float64]
) -> list[int]:
    """The segment's corner ids in the order of its boundary loop."""
    loop = points[layout.loops[label]]
    _, where = cKDTree(loop).query(corners[ids])
    return [ids[k] for k in np.argsort(where, kind="stable")]


def _assign_pieces(
    uv: NDArray[np.float64], poly: NDArray[np.float64], pieces: list[tuple[int, ...]]
) -> NDArray[np.int64]:
    """Index of the piece each point (uv, (P, 2)) falls in: for every piece, the chords
    bounding it are lines through two of its corners; a point belongs to the piece on whose
    inner side of all its chords it lies (ties to the piece with the smallest violation)."""
    violation = np.zeros((len(uv), len(pieces)))
    chord_set = _chords(pieces)
    for p, piece in enumerate(pieces):
        inner = poly[list(piece)].mean(axis=0)
        k = len(piece)
        for s in range(k):
            a, b = piece[s], piece[(s + 1) % k]
            if (min(a, b), max(a, b)) not in chord_set:
                continue
            d = poly[b] - poly[a]
            normal = np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-300)
            if (inner - poly[a]) @ normal < 0:
                normal = -normal
            violation[:, p] += np.maximum(0.0, -(uv - poly[a]) @ normal)
    return np.argmin(violation, axis=1)


def _chords(pieces: list[tuple[int, ...]]) -> set[tuple[int, int]]:
    """Piece sides used by two pieces (the cuts)."""
    count: dict[tuple[int, int], int] = {}
    for piece in pieces:
        for s in range(len(piece)):
            a, b = piece[s], piece[(s + 1) % len(piece)]
            key = (min(a, b), max(a, b))
            count[key] = count.get(key, 0) + 1
    return {key for key, c in count.items() if c > 1}


def _side_distances(
    points: NDArray[np.float64], loop: NDArray[np.float64], at: NDArray[np.int64],
    real: NDArray[np.int64],
) -> NDArray[np.float64]:
    """(4, P) distances along the surface (shortest paths in the k-NN graph of ``points``)
    from each point to each side of a quad: side k is the boundary loop from corner
    ``real[k]`` to ``real[k + 1]`` (``at``: the corners' loop indices)."""
    n = len(loop)
    k = min(GRAPH_NEIGHBOURS + 1, len(points))
    tree = cKDTree(points)
    dist, idx = tree.query(points, k=k)
    rows = np.repeat(np.arange(len(points)), k - 1)
    graph = coo_matrix((dist[:, 1:].ravel(), (rows, idx[:, 1:].ravel())), shape=(len(points),) * 2)
    graph = graph.tocsr().maximum(graph.T.tocsr())
    _, nearest = tree.query(loop)
    out = np.empty((4, len(points)))
    for side in range(4):
        i0, i1 = at[real[side]], at[real[(side + 1) % 4]]
        run = np.arange(i0, i1 + (n if i1 < i0 else 0) + 1) % n
        out[side] = dijkstra(graph, indices=np.unique(nearest[run]), min_only=True)
    finite = np.isfinite(out)
    return np.where(finite, out, out[finite].max() if finite.any() else 0.0)


def _strip_cells(
    points: NDArray[np.float64], loop: NDArray[np.float64], xyz: NDArray[np.float64],
    real: NDArray[np.int64], flat: NDArray[np.int64],
) -> NDArray[np.int64]:
    """Cell of each of a quad's ``points`` after its strip cuts (``flat``: T-node positions,
    ``real``: the 4 other corners, in loop order).

    Coordinates from the distances to the sides: ``a = d3 / (d3 + d1)`` runs along sides 0
    and 2, ``b = d0 / (d0 + d2)`` along sides 1 and 3. A T-node on side 0 or 2 cuts along
    ``a`` = const; joined to a T-node on the opposite side (when both sides have as many,
    in order), ``a`` blends linearly in ``b`` between their values. Otherwise it runs
    straight across and makes a T-node of the neighbour on the opposite side, split in the
    next round: the cut runs along the strip of quads until it meets an open boundary or
    closes. T-nodes on sides 1 and 3 cut likewise along ``b``. The cell is the number of
    cuts of each direction a point lies beyond."""
    _, at = cKDTree(loop).query(xyz)
    d = _side_distances(points, loop, at, real)
    a = d[3] / np.maximum(d[3] + d[1], 1e-300)
    b = d[0] / np.maximum(d[0] + d[2], 1e-300)
    _, t_at = cKDTree(points).query(xyz[flat])
    side_of: dict[int, list[int]] = {}
    for row in np.atleast_1d(t_at):
        side_of.setdefault(int(np.argmin(d[:, row])), []).append(int(row))
    cell = np.zeros(len(points), dtype=np.int64)
    for k, (along, across) in enumerate(((a, b), (b, 1.0 - a))):
        mine = sorted(float(along[r]) for r in side_of.get(k, []))
        theirs = sorted(float(along[r]) for r in side_of.get(k + 2, []))
        if len(mine) == len(theirs):
            pairs = list(zip(mine, theirs))
        else:
            pairs = [(v, v) for v in mine + theirs]
        beyond = np.zeros(len(points), dtype=np.int64)
        for v0, v1 in pairs:
            beyond += along > v0 + (v1 - v0) * across
        cell = cell * (len(pairs) + 1) + beyond
    return cell


def _corner_angles(
    points: NDArray[np.float64], loop: NDArray[np.float64], xyz: NDArray[np.float64], reach: float
) -> tuple[dict[tuple[int, int], NDArray[np.float64]], NDArray[np.float64]]:
    """:func:`_directions` of a segment's corners and each corner's interior angle between
    its sides, 0-360 degrees (over 180 at a reflex corner: the loop turns clockwise there
    about the PCA normal oriented so that the loop runs counter-clockwise)."""
    origin, axes = pca_frame(points)
    directions = _directions(points, loop, xyz, axes[2], reach)
    uv = (loop - origin) @ axes[:2].T
    area = float(np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1]))
    normal = axes[2] if area >= 0 else -axes[2]
    n = len(xyz)
    angle = np.empty(n)
    for i in range(n):
        back, ahead = directions[(i, (i - 1) % n)], directions[(i, (i + 1) % n)]
        angle[i] = _angle(back, ahead)
        turn = np.cross(-back, ahead)
        # Only where the corner's tangent plane is near the PCA plane (the sign means
        # nothing where a wide segment turns away from it, e.g. the ends of a half-tube).
        if float(normal @ turn) < -REFLEX_COS * float(np.linalg.norm(turn)):
            angle[i] = 360.0 - angle[i]
    return directions, angle


def _reflex_cells(
    points: NDArray[np.float64], xyz: NDArray[np.float64],
    directions: dict[tuple[int, int], NDArray[np.float64]], reflex: NDArray[np.int64],
) -> NDArray[np.int64]:
    """Cells of a segment cut by the continuations of both sides of each reflex corner
    (lines in its PCA plane): an L-shape becomes three quads.

    The fourth quarter the two lines make at a corner lies outside the segment, between
    its sides; points that fall in it (the corner sits up to a neighbour radius off, and
    the sides' directions are measured with noise) join the quarter across the nearer
    line."""
    origin, axes = pca_frame(points)
    xy = (points - origin) @ axes[:2].T
    n = len(xyz)
    cell = np.zeros(len(points), dtype=np.int64)
    for r in reflex:
        at = (xyz[r] - origin) @ axes[:2].T
        sides = [directions[(r, j)] @ axes[:2].T for j in ((r - 1) % n, (r + 1) % n)]
        normals = np.array([np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-300) for d in sides])
        dist = (xy - at) @ normals.T  # (P, 2) signed distances to the two lines
        outside = sum(d / max(float(np.linalg.norm(d)), 1e-300) for d in sides) @ normals.T
        stray = ((dist > 0) == (outside > 0)).all(axis=1)
        nearer = np.argmin(np.abs(dist), axis=1)
        dist[stray, nearer[stray]] *= -1
        cell = 4 * cell + 2 * (dist[:, 0] > 0) + (dist[:, 1] > 0)
    return cell


def _split_one(
    points: NDArray[np.float64], loop: NDArray[np.float64], xyz: NDArray[np.float64], reach: float
) -> NDArray[np.int64]:
    """Piece index (0, 1, ...) of each of a segment's ``points``, given its boundary ``loop``
    and corners ``xyz`` in loop order.

    1. Cuts from reflex corners (:func:`_reflex_cells`) when there are any; else, for a quad
       with T-nodes, strip cuts (:func:`_strip_cells`).
    2. Those cuts are kept when no cell is a crumb (:func:`_has_crumbs`). A curved
       strip with many neighbours' corners on both sides (a fillet of a CAD part between
       creases: 10-16 corners, most near straight) crosses them into a grid whose cells
       between nearby cuts are crumbs, too small for a patch: merged into a neighbour they
       make it no 3/4-sided region, or one that pinches. Then one cut across its narrowest
       neck (:func:`_neck_cut`); the next round cuts the parts on.
    3. Otherwise (or no neck found) chords between the corners (:func:`best_split`),
       straight lines in the PCA plane.
    """
    directions, angle = _corner_angles(points, loop, xyz, reach)
    flat = np.flatnonzero((angle >= FLAT_ANGLE) & (angle <= REFLEX_ANGLE))
    reflex = np.flatnonzero(angle > REFLEX_ANGLE)
    widest = np.sort(np.argsort(-angle, kind="stable")[: max(len(xyz) - 4, 0)])
    if len(widest) and angle[widest].min() >= FLAT_ANGLE:
        # All but 4 corners straight or wider: a quad with T-nodes, whatever the widest
        # read (two cube-sphere faces merged: 240 where the neighbours have a corner).
        flat, reflex = widest, widest[:0]
    cell = None
    if len(reflex):
        cell = _reflex_cells(points, xyz, directions, reflex)
        cell = cell if len(np.unique(cell)) > 1 else None
    if cell is None and len(xyz) - len(flat) == 4:
        cell = _strip_cells(points, loop, xyz, np.setdiff1d(np.arange(len(xyz)), flat), flat)
    if cell is not None and _has_crumbs(points, loop, cell, reach):
        cell = _neck_cut(points, loop, xyz, reach)
    if cell is None:
        origin, axes = pca_frame(points)
        poly = (xyz - origin) @ axes[:2].T
        cell = _assign_pieces((points - origin) @ axes[:2].T, poly, best_split(directions, len(xyz)))
    return np.unique(cell, return_inverse=True)[1].reshape(-1)


def _neck_cut(
    points: NDArray[np.float64], loop: NDArray[np.float64], xyz: NDArray[np.float64], reach: float
) -> NDArray[np.int64] | None:
    """The segment cut in two along the chord between two corners that is shortest for the
    loop arc it cuts off (``|x_i - x_j| / min(arc_ij, arc_ji)``: a thin strip's width
    across it, small against its length); the next round cuts the halves on. None when no
    chord leaves two parts of ``MIN_PIECE_POINTS`` points.

    1. Candidates: corners ``i, j`` not next to each other on the loop, best ratio first.
    2. The cut: the edges of the k-NN graph of ``points`` that cross the plane through
       both corners along the surface normal (PCA of the points within ``reach`` of the
       chord's middle), between points within ``reach`` of the chord segment; the two
       largest components of the rest are the parts, other points join the nearer.
    """
    n = len(xyz)
    _, at = cKDTree(loop).query(xyz)
    step = np.linalg.norm(np.diff(np.vstack([loop, loop[:1]]), axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(step)]
    pairs = [(i, j) for i in range(n) for j in range(i + 2, n) if not (i == 0 and j == n - 1)]
    if not pairs:
        return None

    def ratio(i: int, j: int) -> float:
        inner = abs(arc[at[j]] - arc[at[i]])
        return float(np.linalg.norm(xyz[i] - xyz[j]) / max(min(inner, arc[-1] - inner), 1e-300))

    k = min(GRAPH_NEIGHBOURS + 1, len(points))
    tree = cKDTree(points)
    idx = tree.query(points, k=k)[1]
    rows, cols = np.repeat(np.arange(len(points)), k - 1), idx[:, 1:].ravel()
    for i, j in sorted(pairs, key=lambda ij: ratio(*ij))[:EXACT_CORNERS]:
        parts = _cut_parts(points, tree, rows, cols, xyz[i], xyz[j], reach)
        if parts is not None:
            return parts
    return None


def _cut_parts(
    points: NDArray[np.float64], tree: cKDTree, rows: NDArray[np.int64], cols: NDArray[np.int64],
    a: NDArray[np.float64], b: NDArray[np.float64], reach: float,
) -> NDArray[np.int64] | None:
    """Step 2 of :func:`_neck_cut` for the chord ``a``-``b`` (0/1 per point, or None)."""
    near = points[tree.query_ball_point((a + b) / 2, max(reach, float(np.linalg.norm(b - a)) / 2))]
    if len(near) < 3:
        return None
    normal = np.linalg.svd(near - near.mean(axis=0), full_matrices=False)[2][-1]
    across = np.cross(b - a, normal)
    across /= max(float(np.linalg.norm(across)), 1e-300)
    side = (points - a) @ across > 0
    t = np.clip((points - a) @ (b - a) / max(float((b - a) @ (b - a)), 1e-300), 0.0, 1.0)
    close = np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1) <= reach
    keep = ~(close[rows] & close[cols] & (side[rows] != side[cols]))
    graph = coo_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(len(points),) * 2)
    comp = connected_components(graph, directed=False)[1]
    sizes = np.bincount(comp)
    if len(sizes) < 2 or np.sort(sizes)[-2] < MIN_PIECE_POINTS:
        return None
    big = np.argsort(-sizes)[:2]
    part = np.full(len(points), -1, dtype=np.int64)
    part[comp == big[0]], part[comp == big[1]] = 0, 1
    rest = part < 0
    if rest.any():
        _, nearest = cKDTree(points[~rest]).query(points[rest])
        part[rest] = part[~rest][nearest]
    return part


def _has_crumbs(
    points: NDArray[np.float64], loop: NDArray[np.float64], cell: NDArray[np.int64], reach: float
) -> bool:
    """Whether a connected part of a cell (parts as
    :func:`~pde2cad.layout.adjacency.separate_pieces` finds them) is too small for a patch:
    fewer than ``MIN_PIECE_POINTS`` points, or no point ``reach / 2`` away from the other
    parts and the loop (narrower than ``reach``: the layout measures a corner's sides from
    ``LOOP_FROM`` to ``LOOP_TO`` x ``reach`` along the loop, so such a part's corners fall
    within each other's reach and cannot be told apart)."""
    cell = np.unique(cell, return_inverse=True)[1].reshape(-1)
    parts = separate_pieces(points, cell, int(cell.max()) + 1, min_points=1)[0]
    names, counts = np.unique(parts, return_counts=True)
    if counts.min() < MIN_PIECE_POINTS:
        return True
    for name in names:
        mine = parts == name
        width = cKDTree(np.vstack([points[~mine], loop])).query(points[mine])[0]
        if float(width.max()) < reach / 2:
            return True
    return False


def _absorb_small(points: NDArray[np.float64], which: NDArray[np.int64], least: int) -> NDArray[np.int64]:
    """Pieces (``which``, 0 .. P-1) of fewer than ``least`` points given to the piece of
    their nearest point in a larger piece; renumbered 0 .. Q-1 (all 0 when no piece is
    that large)."""
    if (np.bincount(which)[which] < least).all():
        return np.zeros_like(which)
    out = merge_small(points, which, least)
    return out if out is which else np.unique(out, return_inverse=True)[1].reshape(-1)


def _side_labels(
    points: NDArray[np.float64], labels: NDArray[np.int64], tree: cKDTree, loop: NDArray[np.int64],
    at: NDArray[np.int64], label: int, reach: float,
) -> list[int]:
    """The neighbour along each side of a segment (its loop, point indices, from corner
    loop index ``at[i]`` to ``at[i + 1]``): the most common other label within ``reach`` of
    the side's middle half, -1 for an open side."""
    out = []
    n = len(loop)
    for i in range(len(at)):
        i0, i1 = at[i], at[(i + 1) % len(at)]
        run = np.arange(i0, i1 + (n if i1 <= i0 else 0) + 1) % n
        run = run[len(run) // 4 : max(len(run) // 4 + 1, 3 * len(run) // 4)]
        _, idx = tree.query(points[loop[run]], k=SIDE_NEIGHBOURS, distance_upper_bound=reach)
        hit = labels[idx[idx < len(points)]]
        hit = hit[hit != label]
        out.append(int(np.bincount(hit - hit.min()).argmax() + hit.min()) if hit.size else -1)
    return out


def _drop_kinks(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree
) -> Layout:
    """The layout without corners that are kinks of a border: a corner of a segment with
    more than 4 corners at a straight angle whose two sides border the same neighbour (a
    wide segment's projection can make the layout see turns along a smooth border; a T-node
    lies between two different neighbours)."""
    corners, seg_corners = filter_corners(layout, tree, labels)
    kinks: set[int] = set()
    for label, ids in seg_corners.items():
        if len(ids) <= 4:
            continue
        order = _ordered_corners(layout, points, label, ids, corners)
        loop = layout.loops[label]
        members = points[labels == label]
        _, angle = _corner_angles(members, points[loop], corners[order], CORNER_REACH * layout.radius)
        _, at = cKDTree(points[loop]).query(corners[order])
        sides = _side_labels(points, labels, tree, loop, at, label, CORNER_REACH * layout.radius)
        for i in range(len(order)):
            if sides[i - 1] == sides[i] >= 0 and FLAT_ANGLE <= angle[i] <= REFLEX_ANGLE:
                kinks.add(order[i])
    if not kinks:
        return layout
    drop = {int(np.flatnonzero((layout.corners == corners[c]).all(axis=1))[0]) for c in kinks}
    keep = np.array([i not in drop for i in range(len(layout.corners))])
    new_id = np.cumsum(keep) - 1
    return dataclasses.replace(
        layout,
        corners=layout.corners[keep],
        segment_corners={
            label: new_id[[i for i in ids if keep[i]]].astype(np.int64)
            for label, ids in layout.segment_corners.items()
        },
        open_corners=None if layout.open_corners is None else layout.open_corners[keep],
        sharp_corners=None if layout.sharp_corners is None else layout.sharp_corners[keep],
    )


def _loop_angles(loop: NDArray[np.float64], reach: float) -> NDArray[np.float64]:
    """Angle (degrees, 0-180) at every point of a closed loop ((n, 3), in order) between the
    directions in which the loop leaves it, measured as :func:`_directions` does at a
    corner (chords from ``LOOP_FROM x reach`` to ``LOOP_TO x reach`` of arc away each way):
    180 along a straight or gently curved side."""
    step = np.linalg.norm(np.diff(np.vstack([loop, loop[:1]]), axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(step[:-1])]
    total = float(step.sum())

    def at(shift: float) -> NDArray[np.float64]:
        return np.column_stack([np.interp(arc + shift, arc, loop[:, k], period=total) for k in range(3)])

    back = at(-LOOP_TO * reach) - at(-LOOP_FROM * reach)
    ahead = at(LOOP_TO * reach) - at(LOOP_FROM * reach)
    cos = np.sum(back * ahead, axis=1) / np.maximum(
        np.linalg.norm(back, axis=1) * np.linalg.norm(ahead, axis=1), 1e-300
    )
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _sharp_turns(loop: NDArray[np.float64], known: NDArray[np.float64], reach: float) -> NDArray[np.float64]:
    """Points of a segment's loop where it turns at a corner angle (below ``FLAT_ANGLE``)
    more than ``2 x LOOP_TO x reach`` from every ``known`` corner: the sharpest of each run
    of such points, at most one per that arc."""
    if len(loop) < 8:
        return np.empty((0, 3))
    angle = _loop_angles(loop, reach)
    gap = 2 * LOOP_TO * reach
    if len(known):
        angle[cKDTree(known).query(loop)[0] <= gap] = 180.0
    found: list[NDArray[np.float64]] = []
    for i in np.argsort(angle):
        if angle[i] >= FLAT_ANGLE:
            break
        if all(np.linalg.norm(loop[i] - f) > gap for f in found):
            found.append(loop[i])
    return np.array(found).reshape(-1, 3)


def _add_sharp_turns(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree
) -> Layout:
    """The layout with corners where the loops of two segments turn sharply together away
    from any corner (:func:`_sharp_turns` of both within ``2 x LOOP_TO x CORNER_REACH``
    radii; at their midpoint), kept whatever labels they touch (``Layout.sharp_corners``)
    and given to every segment within ``CORNER_REACH`` radii. Two cube-sphere faces merged:
    their former shared edge ends at corners of the neighbours (120 degrees there, 240 in
    the merged segment) that touch only two labels, which the layout drops as kinks of a
    border. One loop turning alone is no corner (a tube's or a sphere's single segment
    folds its projected loop)."""
    reach = CORNER_REACH * layout.radius
    corners, _ = filter_corners(layout, tree, labels)
    found = [(label, _sharp_turns(points[loop], corners, reach)) for label, loop in sorted(layout.loops.items())]
    xyz = np.vstack([f for _, f in found] + [np.empty((0, 3))])
    owner = np.concatenate([np.full(len(f), label) for label, f in found] + [np.empty(0, dtype=np.int64)])
    new: list[NDArray[np.float64]] = []
    for i, j in sorted(cKDTree(xyz).query_pairs(2 * LOOP_TO * reach)) if len(xyz) else []:
        mid = points[tree.query((xyz[i] + xyz[j]) / 2)[1]]
        if owner[i] != owner[j] and all(np.linalg.norm(mid - m) > 2 * LOOP_TO * reach for m in new):
            new.append(mid)
    if not new:
        return layout
    added = np.array(new)
    n_old = len(layout.corners)
    segment_corners = {k: list(v) for k, v in layout.segment_corners.items()}
    for c, xyz in enumerate(added):
        for label in np.unique(labels[tree.query_ball_point(xyz, reach)]):
            segment_corners.setdefault(int(label), []).append(n_old + c)
    none, every = np.zeros(len(added), dtype=bool), np.ones(len(added), dtype=bool)
    sharp = np.zeros(n_old, dtype=bool) if layout.sharp_corners is None else layout.sharp_corners
    return dataclasses.replace(
        layout,
        corners=np.vstack([layout.corners, added]),
        segment_corners={k: np.asarray(sorted(v), dtype=np.int64) for k, v in segment_corners.items()},
        open_corners=None if layout.open_corners is None else np.r_[layout.open_corners, none],
        sharp_corners=np.r_[sharp, every],
    )


def _cube_map(local: NDArray[np.float64], bins: int = 1) -> NDArray[np.int64]:
    """Cube-map cell of each direction (rows of ``local``): its face (6) times a ``bins`` x
    ``bins`` grid on that face."""
    big = np.argmax(np.abs(local), axis=1)
    top = local[np.arange(len(local)), big]
    face = 2 * big + (top > 0)
    rest = np.stack([local[np.arange(len(local)), (big + k) % 3] for k in (1, 2)], axis=1)
    grid = np.clip(((rest / np.abs(top)[:, None] + 1) / 2 * bins).astype(np.int64), 0, bins - 1)
    return (face * bins + grid[:, 0]) * bins + grid[:, 1]


def _sectors(points: NDArray[np.float64], alone: bool) -> NDArray[np.int64] | None:
    """Pieces of a segment without corners. Closed (``alone``: no neighbour, and points seen
    from the centroid in every one of the ``CLOSED_BINS``^2 cells of each cube-map face): the
    6 faces of a cube around its centroid (cube map in its PCA frame). Otherwise 4 sectors
    around the PCA axis it wraps round (every sector holds ``MIN_SECTOR_SHARE`` of the
    points; of several, the axis the points keep the most even distance from: a tube's
    axis; a disc's normal, 4 triangles meeting at the centre). ``None`` when none fits."""
    origin, axes = pca_frame(points)
    local = (points - origin) @ axes.T
    if alone and np.unique(_cube_map(local, CLOSED_BINS)).size == 6 * CLOSED_BINS**2:
        return _cube_map(local)
    best: tuple[float, NDArray[np.int64] | None] = (np.inf, None)
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        angle = np.arctan2(local[:, others[1]], local[:, others[0]])
        cell = np.floor((angle + np.pi) / (np.pi / 2)).astype(np.int64) % 4
        radial = np.hypot(local[:, others[0]], local[:, others[1]])
        spread = float(radial.std() / max(float(radial.mean()), 1e-300))
        if np.bincount(cell, minlength=4).min() >= MIN_SECTOR_SHARE * len(points) and spread < best[0]:
            best = (spread, cell)
    return best[1]


Relayout = Callable[[NDArray[np.int64]], Layout]


def _relayouter(
    points: NDArray[np.float64], first: NDArray[np.int64], crossing: frozenset[tuple[int, int]],
    adjacent: set[tuple[int, int]], fenced: bool = False,
) -> Relayout:
    """A function building the layout of new labels of ``points`` whose segments cross where
    the input segments they hold (``first``, at least ``SOURCE_SHARE`` of their points)
    did, unless two of those shared a border (``adjacent``): a piece of the teapot's handle
    still crosses the body, wherever it lies. ``fenced`` (segments bounded by sharp
    edges): no other pieces cross (a flange face's piece read as crossing the wall of the
    bolt hole it ends at, and lost that side)."""

    def relayout(labels: NDArray[np.int64]) -> Layout:
        if not crossing:
            return build_layout(points, labels, check=False, find_crossing=not fenced)
        present = np.unique(labels)
        held: dict[int, set[int]] = {}
        for label in present.tolist():
            ids, counts = np.unique(first[labels == label], return_counts=True)
            held[label] = set(ids[counts >= SOURCE_SHARE * counts.sum()].tolist())
        def pairs(a: int, b: int) -> set[tuple[int, int]]:
            return {(min(x, y), max(x, y)) for x in held[a] for y in held[b]}

        # Crossing where some input segments they hold crossed and none shared a border.
        known = [(a, b) for i, a in enumerate(present.tolist()) for b in present.tolist()[i + 1:]
                 if pairs(a, b) & crossing and not pairs(a, b) & adjacent]
        return build_layout(points, labels, check=False, crossing=known,
                            find_crossing=not fenced)

    return relayout


def _merge_tubes(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    report: SplitReport, relayout: Relayout,
) -> tuple[NDArray[np.int64], Layout]:
    """Labels and layout with each pair of neighbours that share more than the 2 corners of
    one edge merged, when together they form a segment without corners (two halves of a
    tube meeting along two borders; :func:`_split_cornerless` then cuts the union)."""
    _, seg_corners = filter_corners(layout, tree, labels)
    for a, b in sorted(layout.borders):
        if a in report.merged or b in report.merged or report.apart(a, b):
            continue
        if len(set(seg_corners[a]) & set(seg_corners[b])) <= 2:
            continue
        trial = np.where(labels == b, a, labels)
        trial_layout = relayout(trial)
        if len(filter_corners(trial_layout, tree, trial)[1][a]) == 0:
            labels, layout = trial, trial_layout
            report.merged[int(b)] = int(a)
    return labels, layout


def _merge_tube_chain(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    report: SplitReport, relayout: Relayout,
) -> tuple[NDArray[np.int64], Layout] | None:
    """Labels and layout with every pair of neighbours that share more than 2 corners merged
    at once, when each union then has two boundary loops: a tube in halves along a chain of sections
    (the teapot's handle: two sections of two halves, whose corners are where the 4 meet);
    :func:`~pde2cad.layout.rings.split_rings` then cuts the tubes so their cuts meet. None
    when there is no such pair or a union is no tube.

    The corners counted are the layout's own, not the sharp turns of
    :func:`_add_sharp_turns`: a wavy border (jittered cube-map faces of a noisy ellipsoid)
    turns sharply in both loops mid-way, and its 3 common corners merged four quads into a
    ring."""
    _, seg_corners = filter_corners(dataclasses.replace(layout, sharp_corners=None), tree, labels)
    pairs = [(a, b) for a, b in sorted(layout.borders)
             if len(set(seg_corners[a]) & set(seg_corners[b])) > 2 and not report.apart(a, b)]
    if not pairs:
        return None
    trial = labels.copy()
    into: dict[int, int] = {}
    for a, b in pairs:
        a, b = into.get(a, a), into.get(b, b)
        if a != b:
            trial[trial == b] = a
            into.update({k: a for k, v in into.items() if v == b})
            into[b] = a
    trial_layout = relayout(trial)
    for _ in range(2):
        unions = sorted(set(into.values()))
        loops = {a: len(boundary_loops(points, trial, tree, a, trial_layout.radius,
                                       trial_layout.crossed(a))) for a in unions}
        if all(n == 2 for n in loops.values()):
            break
        for a in [a for a, n in loops.items() if n == 1]:
            # A ring so narrow that its two loops join (the spout's lip) goes to the tube
            # it ends (another union).
            around = {(q if p == a else p): n for (p, q), n in trial_layout.adjacency.items()
                      if a in (p, q) and (q if p == a else p) in loops
                      and not report.apart(p, q)}
            if not around:
                return None
            b = max(around, key=lambda k: around[k])
            trial[trial == a] = b
            into = {k: (b if v == a else v) for k, v in into.items()}
            into[a] = b
        trial_layout = relayout(trial)
    else:
        return None
    for b, a in into.items():
        report.merged[int(b)] = int(a)
    return trial, trial_layout


def _merge_narrow_rings(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    report: SplitReport, relayout: Relayout,
) -> tuple[NDArray[np.int64], Layout]:
    """Labels and layout with every segment of two boundary loops closer than
    ``NARROW_RING`` radii (median) merged into the neighbour it shares the most border with:
    a ring too narrow for pieces whose corners the layout can tell apart (the teapot spout's
    lip, 2-3 radii wide at 112k points) joins the tube it ends."""
    for label in sorted(np.unique(labels).tolist()):
        loops = boundary_loops(points, labels, tree, label, layout.radius, layout.crossed(label))
        around = {(b if a == label else a): n for (a, b), n in layout.adjacency.items()
                  if label in (a, b) and not report.apart(a, b)}
        if len(loops) != 2 or not around:
            continue
        width = float(np.median(cKDTree(points[loops[0][0]]).query(points[loops[1][0]])[0]))
        if width < NARROW_RING * layout.radius:
            into = max(around, key=lambda k: around[k])
            labels = np.where(labels == label, into, labels)
            report.merged[int(label)] = int(into)
            report.merged.update({k: int(into) for k, v in report.merged.items() if v == label})
            layout = relayout(labels)
    return labels, layout


def _merge_slivers(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    report: SplitReport, relayout: Relayout,
) -> tuple[NDArray[np.int64], Layout]:
    """Labels and layout with every segment too narrow for the layout to tell its corners
    apart merged into the neighbour it shares the longest border with: a segment of 1 or 2
    corners that has neighbours (the teapot's rim at 30k points, whose inner and outer corners
    merge). Up to ``MAX_ROUNDS`` times, the layout built again after each."""
    for _ in range(MAX_ROUNDS):
        _, seg_corners = filter_corners(layout, tree, labels)
        thin = [label for label, ids in sorted(seg_corners.items()) if 0 < len(ids) < 3]
        best = None
        for label in thin:
            around = {(b if a == label else a): n for (a, b), n in layout.adjacency.items()
                      if label in (a, b) and not report.apart(a, b)}
            if around:
                best = (label, max(around, key=lambda k: around[k]))
                break
        if best is None:
            return labels, layout
        label, into = best
        labels = np.where(labels == label, into, labels)
        report.merged[int(label)] = int(report.merged.get(into, into))
        layout = relayout(labels)
    return labels, layout


def _split_cornerless(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    report: SplitReport, first_new: int,
) -> NDArray[np.int64]:
    """Labels with every segment without corners (a closed surface, a tube, a disc) split
    by :func:`_sectors` (new labels from ``first_new`` up); the input array when there is
    none."""
    _, seg_corners = filter_corners(layout, tree, labels)
    out = labels
    for label, ids in sorted(seg_corners.items()):
        if len(ids):
            continue
        members = np.flatnonzero(labels == label)
        alone = not any(label in pair for pair in layout.borders)
        cell = _sectors(points[members], alone)
        if cell is None:
            continue
        # A sector too small for a segment (a segment of a few hundred points) joins the
        # sector next to it.
        cell = _absorb_small(points[members], np.unique(cell, return_inverse=True)[1].reshape(-1),
                             MIN_PIECE_POINTS)
        if cell.max() == 0:
            continue
        out = out.copy() if out is labels else out
        start = max(int(out.max()) + 1, first_new)
        names = [label] + list(range(start, start + int(cell.max())))
        out[members] = np.asarray(names)[cell]
        report.pieces[int(label)] = names
        report.corners[int(label)] = 0
    return out


def _cut_rings(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    report: SplitReport, first_new: int,
) -> NDArray[np.int64]:
    """Labels with every segment of two boundary loops (a ring, a tube, a sheet with a hole)
    cut into quads by :func:`~pde2cad.layout.rings.split_rings`, recorded in ``report``
    (``rings``)."""
    out, pieces, loops = split_rings(points, labels, layout, tree, first_new)
    report.loops.update(loops)
    for label, names in pieces.items():
        report.pieces[label] = names
        report.corners[label] = 0
        report.rings.append(label)
    out = _separate(points, out, report, max(int(out.max()) + 1, first_new))[0]
    return _settle(points, out, report)


def _settle(
    points: NDArray[np.float64], labels: NDArray[np.int64], report: SplitReport,
    avoid: dict[int, set[int]] | None = None, prefer: dict[int, set[int]] | None = None,
) -> NDArray[np.int64]:
    """The "too small" pass after every split step: each segment of fewer than
    ``MIN_PIECE_POINTS`` points (a sliver between a cut and a side, a ring's piece, a part
    a cut left) merged into the neighbour it shares the longest border with
    (:func:`~pde2cad.layout.adjacency.merge_small`; ``avoid``: the two pieces of a cut in
    two, ``prefer``: the pieces of a cut into more, which keep their slivers). A cut that
    makes such a piece is no reason to refuse the layout: the piece is too small to be a patch, not too small for its neighbour's, and whatever
    corners the merge leaves are split in the next round. Merged labels leave ``report``."""
    out = labels
    for _ in range(MAX_ROUNDS):
        merged = merge_small(points, out, MIN_PIECE_POINTS, avoid, prefer)
        if merged is out:
            break
        # A piece's crumbs apart from it (under COMPONENT_SHARE of it) went with it and may
        # lie apart from their new segment: they become pieces of their own, merged again.
        out = separate_pieces(points, merged, int(merged.max()) + 1, min_points=1)[0]
    if out is labels:
        return labels
    gone = set(np.unique(labels).tolist()) - set(np.unique(out).tolist())
    for first, names in report.pieces.items():
        names[:] = [n for n in names if n == first or n not in gone]
    return out


def _separate(
    points: NDArray[np.float64], labels: NDArray[np.int64], report: SplitReport, first_new: int,
    source: dict[int, int] | None = None,
) -> tuple[NDArray[np.int64], int]:
    """:func:`~pde2cad.layout.adjacency.separate_pieces`, recorded in ``report`` (and in
    ``source``: piece label -> input label): a cut, or a merge before it, can leave a
    segment in two parts (a ring cut where it pinches, a corner cut across a wavy border);
    each part of some size becomes a segment of its own, as the error would ask the user
    to do. Returns the labels and the next free label."""
    # Parts of any size get a label: :func:`_settle` gives the small ones to a neighbour.
    out, apart = separate_pieces(points, labels, first_new, min_points=1)
    for label, names in apart.items():
        owner = (source or {}).get(label, next((k for k, v in report.pieces.items() if label in v), label))
        report.pieces.setdefault(owner, [owner]).extend(names[1:])
        report.corners.setdefault(owner, 0)
        if source is not None:
            source.update({n: owner for n in names})
        first_new = max(first_new, max(names) + 1)
    return out, first_new


def split_segments(
    points: NDArray[np.float64],
    labels: NDArray[np.int64],
    layout: Layout,
    tree: cKDTree,
    fenced: bool = False,
) -> tuple[NDArray[np.int64], Layout, SplitReport]:
    """Split every segment with more than 4 corners into 3/4-sided pieces (in up to
    ``MAX_ROUNDS`` rounds, or one per piece when there are more: a strip cut makes a T-node
    on the next segment of the strip).

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
    layout : Layout
        :func:`~pde2cad.layout.adjacency.build_layout` of ``points``, ``labels``.
    tree : cKDTree
        Of ``points``.
    fenced : bool
        The segments are bounded by sharp edges (crease-bounded regions): pieces of
        different segments never merge (a thin region or a noisy border otherwise reads as
        a sliver or half a tube and joins its neighbour across the crease).

    Returns
    -------
    labels : (N,) int
        The new labels (the input array when nothing is split).
    layout : Layout
        The layout of the new labels (the input one when nothing is split).
    report : SplitReport

    Raises
    ------
    InputError
        A piece of a split segment still not 3/4-sided after the rounds, or a segment with
        more than ``MAX_CORNERS`` corners (the message names the label).
    """
    report = SplitReport(fenced=fenced)
    relayout = _relayouter(points, labels, layout.crossing, set(layout.adjacency), fenced)
    out = labels
    source: dict[int, int] = {}  # piece label -> input label
    out = _cut_rings(points, out, layout, tree, report, int(labels.max()) + 1)
    if out is not labels:
        layout = relayout(out)
    layout = _add_sharp_turns(points, out, layout, tree)
    chained = _merge_tube_chain(points, out, layout, tree, report, relayout)
    if chained is not None:
        out, layout = _merge_narrow_rings(points, *chained, tree, report, relayout)
        out = _cut_rings(points, out, layout, tree, report, int(labels.max()) + 1)
        layout = _add_sharp_turns(points, out, relayout(out), tree)
    out, layout = _merge_tubes(points, out, layout, tree, report, relayout)
    out, layout = _merge_slivers(points, out, layout, tree, report, relayout)
    merged = out
    out = _split_cornerless(points, out, layout, tree, report, max(int(out.max()), int(labels.max())) + 1)
    if out is not merged:
        layout = _add_sharp_turns(points, out, relayout(out), tree)
    source = {p: first for first, pieces in report.pieces.items() for p in pieces}
    stuck: set[int] = set()  # segments whose cuts the merges undid
    # A strip cut moves its T-node on through every piece of the strip, one per round: a
    # tube's faces cut into ~90 pieces (OCCT's sh1.stl) took 20 rounds; halving a wide
    # quad sends T-nodes along the strips of its neighbours, so the bound grows with the
    # pieces.
    rounds = 0
    while rounds < max(MAX_ROUNDS, len(np.unique(out))):
        rounds += 1
        layout = _drop_kinks(points, out, layout, tree)
        corners, seg_corners = filter_corners(layout, tree, out)
        todo = _apart(layout, [(label, ids) for label, ids in sorted(seg_corners.items())
                               if len(ids) > 4 and label not in stuck])
        thin = _merge_thin(out, layout, seg_corners, source)
        if thin is not None:
            out = thin
            layout = _add_sharp_turns(points, out, relayout(out), tree)
            continue
        start, out = out, out.copy()
        next_label = int(out.max()) + 1
        cut: dict[int, set[int]] = {}  # the other piece of a cut in two (avoided)
        kin: dict[int, set[int]] = {}  # the other pieces of a cut into more (preferred)
        if not todo:
            digon = _halve_digon(points, out, layout, tree, corners, seg_corners)
            # Wide quads are halved in crease-bounded regions only: a user's labelled quad
            # (the teapot's rim, a lip turning 175 deg across) is fitted as given.
            halves = [digon] if digon is not None else [] if not fenced else _halve_wide(
                points, out, layout, tree, corners, seg_corners)
            if not halves:
                break
            for label, beyond in halves:
                first = source.get(label, label)
                out[out == label] = np.where(beyond, next_label, label)
                report.pieces.setdefault(first, [first]).append(next_label)
                report.corners.setdefault(first, len(seg_corners[label]))
                source[label] = source[next_label] = first
                next_label += 1
            layout = _add_sharp_turns(points, out, relayout(out), tree)
            continue
        for label, ids in todo:
            first = source.get(label, label)
            if len(ids) > MAX_CORNERS:
                raise InputError(
                    f"segment {first} has {len(ids)} corners (at most {MAX_CORNERS} are split "
                    "automatically); split it into smaller segments"
                )
            members = np.flatnonzero(out == label)
            order = _ordered_corners(layout, points, label, ids, corners)
            which = _split_one(
                points[members], points[layout.loops[label]], corners[order],
                CORNER_REACH * layout.radius,
            )
            counts = np.bincount(which)
            names = [label] + list(range(next_label, next_label + len(counts) - 1))
            for name in names:
                (cut if len(names) == 2 else kin)[name] = set(names) - {name}
            next_label += len(counts) - 1
            out[members] = np.asarray(names)[which]
            pieces = report.pieces.setdefault(first, [first])
            pieces += [n for n in names[1:]]
            report.corners.setdefault(first, len(ids))
            for name in names:
                source[name] = first
        out, next_label = _separate(points, out, report, next_label, source)
        out = _settle(points, out, report, cut, kin)
        if np.array_equal(out, start):
            # Every cut undone by its pieces' merges: the segments that waited for these
            # (their neighbours) get their turn; _check_pieces names any left.
            stuck.update(label for label, _ in todo)
            continue
        stuck.clear()  # new neighbours may let an undone cut stand
        layout = _add_sharp_turns(points, out, relayout(out), tree)
    if rounds >= max(MAX_ROUNDS, len(np.unique(out))):
        layout = _drop_kinks(points, out, layout, tree)
    _check_pieces(layout, tree, out, source, report)
    return out, layout, report


def _merge_thin(
    labels: NDArray[np.int64], layout: Layout, seg_corners: dict[int, list[int]],
    source: dict[int, int],
) -> NDArray[np.int64] | None:
    """Labels with every piece of a split that has 1 or 2 corners (a cut that ran close to a
    side leaves a strip too thin for the layout to tell its corners apart) merged into the
    neighbour it shares the longest border with, as :func:`_merge_slivers` does before the
    rounds; whatever corners that leaves are split in the next round. None when there is
    none."""
    into: dict[int, int] = {}
    for label, ids in sorted(seg_corners.items()):
        around = {(b if a == label else a): n for (a, b), n in layout.adjacency.items()
                  if label in (a, b) and into.get(b if a == label else a) != label}
        if label in source and 0 < len(ids) < 3 and around:
            into[label] = max(around, key=lambda k: around[k])
    if not into:
        return None
    out = labels.copy()
    for label, other in into.items():
        seen = {label}
        while other in into and other not in seen:  # a chain of thin pieces ends at a wide one
            seen.add(other)
            other = into[other]
        out[labels == label] = other
    return out


def _apart(layout: Layout, todo: list[tuple[int, list[int]]]) -> list[tuple[int, list[int]]]:
    """The segments of ``todo`` to split in one round: each unless it borders one taken
    before it (the rest wait for the next round, on the new layout). Two neighbours cut in
    the same round end their cuts on their common border independently, a radius or two
    apart: a sliver between them whose corners merge (a k-means capsule's 5-cornered
    segments left a 2-cornered piece)."""
    taken: list[tuple[int, list[int]]] = []
    for label, ids in todo:
        if not any((min(label, t), max(label, t)) in layout.borders for t, _ in taken):
            taken.append((label, ids))
    return taken


def _halve_digon(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    corners: NDArray[np.float64], seg_corners: dict[int, list[int]],
) -> tuple[int, NDArray[np.bool_]] | None:
    """The first quad that meets one neighbour along two opposite sides (the halves of a
    tube: the teapot's handle and spout), and which of its points lie beyond its middle
    between those sides (``a`` or ``b`` of :func:`_strip_cells` over 0.5): its edges with the
    segments at its ends run between the same two corners as the other half's, which no edge
    network can tell apart. Cut there, the ends get T-nodes that the next rounds carry along
    the strip. None when there is no such quad."""
    reach = CORNER_REACH * layout.radius
    for (a, b) in sorted(layout.borders):
        if len(set(seg_corners[a]) & set(seg_corners[b])) <= 2:
            continue
        for label, other in ((a, b), (b, a)):
            ids = seg_corners[label]
            if len(ids) != 4:
                continue
            order = _ordered_corners(layout, points, label, ids, corners)
            loop = layout.loops[label]
            _, at = cKDTree(points[loop]).query(corners[order])
            sides = _side_labels(points, labels, tree, loop, at, label, reach)
            seams = [k for k in range(4) if sides[k] == other]
            if seams not in ([0, 2], [1, 3]):
                continue
            members = labels == label
            d = _side_distances(points[members], points[loop], at, np.arange(4))
            k = seams[0]
            which = np.zeros(len(points), dtype=bool)
            which[members] = d[k] / np.maximum(d[k] + d[k + 2], 1e-300) > 0.5
            if min(int(which.sum()), int(members.sum() - which.sum())) >= MIN_PIECE_POINTS:
                return label, which[members]
    return None


def _halve_wide(
    points: NDArray[np.float64], labels: NDArray[np.int64], layout: Layout, tree: cKDTree,
    corners: NDArray[np.float64], seg_corners: dict[int, list[int]],
) -> list[tuple[int, NDArray[np.bool_]]]:
    """Every quad whose surface turns too far for one patch (no plane sees it within
    ``WIDE_COS``: a C-shaped wall's 300-degree face, a half cylinder), and
    which of its points lie beyond its middle between the two opposite sides whose cut
    leaves the flatter halves (:func:`_side_distances`). The neighbours get T-nodes that
    the next rounds carry along their strips."""
    out = []
    for label, ids in sorted(seg_corners.items()):
        members = np.flatnonzero(labels == label)
        if len(ids) != 4 or len(members) < 4 * MIN_PIECE_POINTS:
            continue
        whole = plane_score(points, members, tree)
        if whole >= WIDE_COS:
            continue
        order = _ordered_corners(layout, points, label, ids, corners)
        loop = layout.loops[label]
        _, at = cKDTree(points[loop]).query(corners[order])
        d = _side_distances(points[members], points[loop], at, np.arange(4))
        best: tuple[float, NDArray[np.bool_]] | None = None
        for k in (0, 1):
            beyond = d[k] / np.maximum(d[k] + d[k + 2], 1e-300) > 0.5
            if min(int(beyond.sum()), int((~beyond).sum())) < MIN_PIECE_POINTS:
                continue
            score = min(plane_score(points, members[beyond], tree),
                        plane_score(points, members[~beyond], tree))
            if best is None or score > best[0]:
                best = (score, beyond)
        if best is not None and best[0] > whole:  # halves that turn no less: left as is
            out.append((label, best[1]))
    return out


def _check_pieces(
    layout: Layout, tree: cKDTree, labels: NDArray[np.int64], source: dict[int, int],
    report: SplitReport,
) -> None:
    """Raise, naming the input segment, when a piece of a split is still no 3/4-sided region
    (the message of a later stage would name a label the user never gave)."""
    _, seg_corners = filter_corners(layout, tree, labels)
    for label, ids in sorted(seg_corners.items()):
        if label in source and len(ids) not in (3, 4):
            first = source[label]
            raise InputError(
                f"segment {first} has {report.corners[first]} corners; a patch needs 3 or 4 "
                f"and the automatic split into 3/4-sided pieces left one with {len(ids)} "
                "(e.g. at a reflex corner, which the layout sees as no corner) — split or "
                "merge segments by hand so each is a 3- or 4-sided region"
            )


__all__ = ["SplitReport", "best_split", "split_segments"]
