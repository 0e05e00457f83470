"""Cut segments with 3 or more boundary loops (a face with several holes) into quads.

:func:`~pde2cad.layout.rings.split_rings` cuts a segment of two loops (a ring) into
4-sided pieces; a segment with ``k >= 2`` holes (``k + 1`` loops: a flange's face with its
bore and bolt holes, a plate with two holes) is cut here, directly into quads whose cut
ends the neighbouring rings (the holes' walls, the rim) then take as their own
(:func:`cut_holes`):

1. **Cells.** Every loop gets the points closer to it than to any other loop, by shortest
   paths on the surface (one multi-source Dijkstra run on a k-NN graph; each point keeps
   its *foot*, the loop point its path starts from, and the next point on that path). A
   cell holds its shortest paths, so it is a ring round its loop whose outer side runs
   along bisectors with other cells, unless the distance to the outer loop has a ridge
   inside it (a plate with two holes: the outer loop's cell then has 3 sides). Then the
   longest loop (the outer one) is no cell and the holes' cells are rings whose outer side
   runs along bisectors and along the outer loop.
2. **Vertices.** Where the outer side of a cell changes what it runs along: points whose
   neighbours (two steps out) lie in 3 cells, or in 2 next to the outer loop. Each group
   of such points is one *mark*, cut to the loop of every cell it touches. A bisector
   gets a mark in its middle too (the shortest cut between its two loops), where that cut
   leaves ``ROOM_RADII`` from the others.
3. **Known corners.** Corners of the layout on the outer loop become marks; corners on
   another loop become marks on its cell's outer side where the feet point the same way.
4. **Gaps.** Round each loop, where consecutive cuts' feet lie more than ``GAP_DEGREES``
   apart, marks in between on the cell's outer side (a mark on a bisector cuts both cells,
   so no T-node), where they leave room.
5. **Pieces.** Each cut is the shortest path from its mark to its cell's loop, its foot
   moved along the loop where feet lie closer than ``ROOM_RADII`` (paths from beyond a
   small hole converge on it). Without the points along the cuts, a cell falls into one
   piece between each two consecutive cuts, bounded by a loop arc, two cuts and one
   stretch of bisector or outer loop: a quad. The cuts' ends on the loops are returned
   for the rings beyond (walls of the holes, the rim), which cut there too.

Known limits: feet are ordered by angle round their loop's centroid in its PCA plane (a
loop that does not run round its centroid once in that plane, e.g. a long curved slot,
gets cuts in the wrong order); the cells are rings only on a segment of genus 0; a web
between a hole and the rim or another hole only a few neighbour radii wide is split by the
bisector into pieces too thin for the layout (a sheet at 20k points with a hole 3 radii
from its rim is refused) or gets a cut across it with a side of 4 radii, which can fold in
the fit; a piece wrapping far round a small hole can fold too.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

from pde2cad.errors import InputError

#: Neighbours per point of the graph whose shortest paths measure distances on the surface,
#: and whose cells tell a vertex.
NEIGHBOURS = 8
#: Vertex points closer than this many neighbour radii are one mark.
LINK_RADII = 3.0
#: Points within this many neighbour radii of a cut's shortest path part the pieces beside it.
BAND_RADII = 1.0
#: Parts of a cell under this many points (crumbs between cuts) join their neighbours.
MIN_PART = 20
#: Rounds of pushing feet apart (:func:`spread`).
SPREAD_ROUNDS = 200
#: Rounds of averaging the foot angles over neighbours (:func:`smooth_angles`).
SMOOTH_ROUNDS = 3
#: Feet of a cell closer than this many neighbour radii (along their hole) are one cut (one
#: vertex seen as two groups of points).
MERGE_RADII = 2.0
#: A cut that no vertex asks for (a bisector's middle, a gap's) is made only where its feet
#: lie this many neighbour radii or more from the other cuts of its cells (the layout merges
#: corners closer than ``BORDER_SPAN``, 4, radii; pieces narrower than a few radii fit badly).
ROOM_RADII = 8.0
#: Largest angle (degrees) round a hole between consecutive cuts: wider gaps get
#: ``ceil(gap / GAP_DEGREES)`` pieces (a half ring is a sound quad). Not 120: a plate's two
#: holes (plate2, 100k samples) then got 3 pieces each where 2 do, 30 faces instead of 22,
#: two of them folded (seams 59-141 deg instead of <= 3.3); not 90, a ring's 4 cuts, nor
#: 150: gaps between vertices and saddles come out at 240-300 degrees (a flange's bolt holes,
#: a plate's two holes), and where one face of a part gets an extra cut and the face across
#: its holes' walls not, the walls get T-nodes.
GAP_DEGREES = 180.0


def _graph(points: NDArray[np.float64]) -> tuple[coo_matrix, NDArray[np.int64]]:
    """Symmetric k-NN graph of ``points`` (edge lengths) and the (P, k+1) neighbour
    indices (each point first)."""
    k = min(NEIGHBOURS + 1, len(points))
    dist, idx = cKDTree(points).query(points, k=k)
    rows = np.repeat(np.arange(len(points)), k - 1)
    graph = coo_matrix((dist[:, 1:].ravel(), (rows, idx[:, 1:].ravel())), shape=(len(points),) * 2)
    return graph.tocsr().maximum(graph.T.tocsr()), idx


def hole_cells(
    points: NDArray[np.float64], holes: list[NDArray[np.int64]]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.int64],
           NDArray[np.int64]]:
    """Step 1: each point's cell (index into ``holes``) and foot (index into ``points``).

    1. Multi-source Dijkstra from every hole point on the k-NN graph.
    2. Cell of a point: the hole of its foot; points no path reaches take their nearest
       reached point's cell and foot.

    Returns
    -------
    cell, foot : (P,) int
    dist : (P,) float
        Length of the shortest path to the foot.
    pred : (P,) int
        The next point on that path (negative at the holes' points).
    idx : (P, k+1) int
        Each point's neighbours (itself first).
    """
    graph, idx = _graph(points)
    sources = np.concatenate(holes)
    owner = np.full(len(points), -1, dtype=np.int64)
    for h, lp in enumerate(holes):
        owner[lp] = h
    dist, pred, foot = dijkstra(graph, indices=np.unique(sources), min_only=True, return_predecessors=True)
    foot = np.asarray(foot, dtype=np.int64)
    reached = foot >= 0
    if not reached.all():
        near = np.flatnonzero(reached)[cKDTree(points[reached]).query(points[~reached])[1]]
        foot[~reached], dist[~reached], pred[~reached] = foot[near], dist[near], near
    return owner[foot], foot, np.asarray(dist, dtype=np.float64), np.asarray(pred, dtype=np.int64), idx


def loop_angles(points: NDArray[np.float64], loop: NDArray[np.int64]) -> tuple[
    NDArray[np.float64], NDArray[np.float64]
]:
    """Centre and (2, 3) PCA axes of a loop's points: angles round it are
    ``arctan2((p - c) @ axes[1], (p - c) @ axes[0])``."""
    c = points[loop].mean(axis=0)
    axes = np.linalg.svd(points[loop] - c, full_matrices=False)[2][:2]
    return c, axes


def _angle(points: NDArray[np.float64], frame: tuple[NDArray[np.float64], NDArray[np.float64]]) -> NDArray[np.float64]:
    rel = (points - frame[0]) @ frame[1].T
    return np.arctan2(rel[:, 1], rel[:, 0])


def _distinct(rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """Number of distinct values per row."""
    s = np.sort(rows, axis=1)
    return 1 + (np.diff(s, axis=1) != 0).sum(axis=1)


def _groups(points: NDArray[np.float64], cand: NDArray[np.int64], radius: float) -> list[NDArray[np.int64]]:
    """``cand`` (indices into ``points``) in groups: chains of points closer than
    ``LINK_RADII`` radii."""
    if not len(cand):
        return []
    pairs = cKDTree(points[cand]).query_pairs(LINK_RADII * radius, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(cand),) * 2)
    n, group = connected_components(graph, directed=False)
    order = np.argsort(group, kind="stable")
    return np.split(cand[order], np.cumsum(np.bincount(group, minlength=n))[:-1])


def vertex_marks(
    points: NDArray[np.float64], cell: NDArray[np.int64], idx: NDArray[np.int64],
    near_outer: NDArray[np.bool_], radius: float,
) -> NDArray[np.int64]:
    """Step 2: the marks (indices into ``points``) where a cell's outer loop changes what it
    runs along.

    1. Candidates: points whose neighbours (two steps out: the cells interleave along a
       bisector) lie in 3 or more cells, or in 2 next to the outer loop.
    2. Candidates within ``LINK_RADII`` radii are one group; its mark is the point nearest
       the group's centroid (next to the outer loop if any group point is).
    """
    ncell = _distinct(cell[idx[idx]].reshape(len(points), -1))
    cand = np.flatnonzero((ncell >= 3) | ((ncell >= 2) & near_outer))
    marks = []
    for members in _groups(points, cand, radius):
        outer = members[near_outer[members]]
        pool = outer if len(outer) else members
        centre = points[members].mean(axis=0)
        marks.append(pool[np.argmin(np.linalg.norm(points[pool] - centre, axis=1))])
    return np.asarray(marks, dtype=np.int64)


def saddle_marks(
    points: NDArray[np.float64], cell: NDArray[np.int64], idx: NDArray[np.int64],
    near_outer: NDArray[np.bool_], dist: NDArray[np.float64], vertices: NDArray[np.int64],
    radius: float,
) -> NDArray[np.int64]:
    """Step 2b: a mark in the middle of every bisector between two cells (each piece then
    has one half of a bisector as its outer side, and the cut there is the shortest path
    between the two holes), so that a cell with two vertices still gets 4 pieces.

    1. Bisector points: next to another cell, not next to the outer loop, farther than
       ``LINK_RADII`` radii from every vertex; chains of them are the bisectors.
    2. Per bisector, the point farthest from the vertices (its middle), or, on a bisector
       that closes round a cell without vertices, the point nearest the holes.
    """
    bis = (cell[idx] != cell[:, None]).any(axis=1) & ~near_outer
    far = np.full(len(points), np.inf)
    if len(vertices):
        far = cKDTree(points[vertices]).query(points)[0]
    cand = np.flatnonzero(bis & (far > 2 * LINK_RADII * radius))
    marks = []
    for run in _groups(points, cand, radius):
        if np.isfinite(far[run]).any() and far[run].min() < 3 * LINK_RADII * radius:
            marks.append(run[np.argmax(far[run])])
        else:
            marks.append(run[np.argmin(dist[run])])
    return np.asarray(marks, dtype=np.int64)


def _wrap(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angles into [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def smooth_angles(angle: NDArray[np.float64], cell: NDArray[np.int64], idx: NDArray[np.int64],
                  rounds: int) -> NDArray[np.float64]:
    """Angles averaged (as unit vectors) over each point's neighbours of its own cell,
    ``rounds`` times: the foot of a shortest path on a k-NN graph wobbles by several
    degrees from point to point (measured: 2 median, 6 at the 95th percentile, 13 at a
    flange's vertex), which would leave a cut ending far from its mark."""
    same = cell[idx] == cell[:, None]
    z = np.exp(1j * angle)
    for _ in range(rounds):
        z = np.where(same, z[idx], 0).sum(axis=1)
        z = z / np.maximum(np.abs(z), 1e-300)
    return np.asarray(np.angle(z), dtype=np.float64)


class _Cells:
    """The cells of a segment's holes (step 1) and what steps 2-5 ask of them."""

    def __init__(self, points: NDArray[np.float64], holes: list[NDArray[np.int64]],
                 outer: NDArray[np.int64], radius: float) -> None:
        self.points, self.radius, self.k, self.holes = points, radius, len(holes), holes
        self.cell, self.foot, self.dist, self.pred, self.idx = hole_cells(points, holes)
        self.graph = _graph(points)[0]
        on_outer = np.zeros(len(points), dtype=bool)
        on_outer[outer] = True
        self.near_outer: NDArray[np.bool_] = np.asarray(on_outer[self.idx].any(axis=1))
        self.frames = frames = [loop_angles(points, lp) for lp in holes]
        fa = np.zeros(len(points))  # angle of each point's foot round its hole
        for h, frame in enumerate(frames):
            at = self.cell == h
            fa[at] = _angle(points[self.foot[at]], frame)
        self.fa = smooth_angles(fa, self.cell, self.idx, SMOOTH_ROUNDS)
        self.span = np.array([np.linalg.norm((points[lp] - f[0]) @ f[1].T, axis=1).mean() for lp, f in
                              zip(holes, frames)])  # mean hole radius: angle -> arc length
        # Points on a cell's outer loop: next to another cell or to the outer loop.
        self.rim = (_distinct(self.cell[self.idx]) >= 2) | self.near_outer
        self.members = [np.flatnonzero(self.cell == h) for h in range(self.k)]
        self.marks = np.zeros(0, dtype=np.int64)
        self.feet = np.zeros((0, self.k))  # foot angle of each mark's cut in each cell, or nan

    def starts(self, marks: NDArray[np.int64]) -> NDArray[np.int64]:
        """(m, k) where each mark's cut into each cell starts: the point of that cell within
        two neighbour steps nearest the mark; -1 where there is none."""
        ring = self.idx[self.idx[marks]].reshape(len(marks), -1)
        gap = np.linalg.norm(self.points[ring] - self.points[marks][:, None], axis=2)
        out = np.full((len(marks), self.k), -1, dtype=np.int64)
        for h in range(self.k):
            mine = np.where(self.cell[ring] == h, gap, np.inf)
            best = np.argmin(mine, axis=1)
            ok = np.isfinite(mine[np.arange(len(marks)), best])
            out[ok, h] = ring[ok, best[ok]]
        return out

    def _feet(self, marks: NDArray[np.int64]) -> NDArray[np.float64]:
        """(m, k) foot angle of each mark's cut in each cell (where its shortest path from
        :meth:`starts` meets the hole); nan where it touches none."""
        start = self.starts(marks)
        out = np.full(start.shape, np.nan)
        for h in range(self.k):
            ok = start[:, h] >= 0
            out[ok, h] = _angle(self.points[self.foot[start[ok, h]]], self.frames[h])
        return out

    def add(self, marks: NDArray[np.int64], room: bool = False) -> None:
        """Marks and their feet in the cells they touch (:meth:`_feet`). With ``room``, one
        at a time and only where its feet lie ``ROOM_RADII`` radii or more from the cuts
        there."""
        marks = np.setdiff1d(np.unique(marks), self.marks)
        if room:
            for m in marks:
                if self._roomy(int(m)):
                    self.add(np.array([m]))
            return
        if len(marks):
            self.marks = np.concatenate([self.marks, marks])
            self.feet = np.vstack([self.feet, self._feet(marks)])

    def _roomy(self, mark: int) -> bool:
        """Whether a mark's feet lie ``ROOM_RADII`` radii or more (along its holes) from the
        feet of the cuts already in every cell it touches."""
        feet = self._feet(np.array([mark]))[0]
        for h in np.flatnonzero(np.isfinite(feet)).tolist():
            ang = self.bounds(h)[0]
            if len(ang) and np.abs(_wrap(ang - feet[h])).min() * self.span[h] < ROOM_RADII * self.radius:
                return False
        return True

    def bounds(self, h: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Sorted foot angles of cell ``h``'s cuts (those closer than ``MERGE_RADII`` radii
        along the hole are one) and the hole points there."""
        ang = np.sort(self.feet[:, h][np.isfinite(self.feet[:, h])])
        if len(ang) > 1:
            gap = np.diff(np.append(ang, ang[0] + 2 * np.pi)) * self.span[h]
            keep = np.ones(len(ang), dtype=bool)
            keep[1:] = gap[:-1] >= MERGE_RADII * self.radius
            keep[-1] &= bool(gap[-1] >= MERGE_RADII * self.radius)
            ang = ang[keep]
        loop = self.holes[h]
        at = _angle(self.points[loop], self.frames[h])
        return ang, loop[np.argmin(np.abs(_wrap(at[None, :] - ang[:, None])), axis=1)] if len(ang) else loop[:0]

    def is_ring(self, h: int) -> bool:
        """Whether cell ``h``'s outer loop (its points next to other cells or the outer loop)
        is one connected run: the cell is a ring, not a disc with islands of other cells."""
        rim = self.members[h][self.rim[self.members[h]]]
        if len(rim) < 2:
            return False
        pairs = cKDTree(self.points[rim]).query_pairs(LINK_RADII * self.radius, output_type="ndarray")
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(rim),) * 2)
        return bool(connected_components(graph, directed=False)[0] == 1)

    def nearest_rim(self, h: int, targets: NDArray[np.float64]) -> NDArray[np.int64]:
        """The points on cell ``h``'s outer loop whose feet point nearest each target angle."""
        pool = self.members[h][self.rim[self.members[h]]]
        if not len(pool):
            return np.zeros(0, dtype=np.int64)
        off = np.abs(_wrap(self.fa[pool][None, :] - targets[:, None]))
        return pool[np.argmin(off, axis=1)]


def _known_marks(cells: _Cells, known: NDArray[np.float64]) -> NDArray[np.int64]:
    """Step 3: marks for the layout's corners ``known`` on the segment's loops: the nearest
    point when it lies next to the outer loop, else the point on its cell's outer loop whose
    foot points where the corner does round its hole."""
    if not len(known):
        return np.zeros(0, dtype=np.int64)
    at = cKDTree(cells.points).query(known)[1]
    out = list(at[cells.near_outer[at]])
    for p in at[~cells.near_outer[at]]:
        out.extend(cells.nearest_rim(int(cells.cell[p]), cells.fa[[p]]).tolist())
    return np.asarray(out, dtype=np.int64)


def _fill_gaps(cells: _Cells) -> None:
    """Step 4: marks where consecutive cuts round a hole lie more than ``GAP_DEGREES``
    apart, ``ceil(gap / GAP_DEGREES)`` pieces per gap, one hole after the other (a mark
    on a bisector cuts the cell beyond too, narrowing its gaps)."""
    step = np.radians(GAP_DEGREES)
    for h in range(cells.k):
        ang = cells.bounds(h)[0]
        if not len(ang):
            ang = cells.fa[cells.members[h][:1]]
        gaps = np.diff(np.append(ang, ang[0] + 2 * np.pi))
        parts = np.maximum(np.ceil(gaps / step).astype(np.int64), 1)
        targets = [a + g * np.arange(1, n) / n for a, g, n in zip(ang, gaps, parts) if n > 1]
        if targets:
            cells.add(cells.nearest_rim(h, _wrap(np.concatenate(targets))), room=True)


def cut_paths(pred: NDArray[np.int64], starts: NDArray[np.int64]) -> NDArray[np.int64]:
    """The points of the shortest paths from ``starts`` to the holes (``pred`` of
    :func:`hole_cells`), followed for all cuts at once, one step a round."""
    out = [starts]
    cur = starts[starts >= 0]
    while len(cur):
        cur = pred[cur]
        cur = cur[cur >= 0]
        out.append(cur)
    return np.unique(np.concatenate(out))


def spread(angles: NDArray[np.float64], least: float) -> NDArray[np.float64]:
    """Sorted angles round a loop moved apart (each pair pushed by halves of what it lacks,
    ``SPREAD_ROUNDS`` times) until consecutive ones lie ``least`` apart or as far as their
    number allows; angles already far enough apart stay."""
    n = len(angles)
    if n < 2:
        return angles
    least = min(least, 2 * np.pi / n * 0.9)
    a = angles.copy()
    for _ in range(SPREAD_ROUNDS):
        gap = np.diff(np.append(a, a[0] + 2 * np.pi))
        push = np.maximum(least - gap, 0.0) / 2
        if not push.any():
            break
        a = a - push + np.roll(push, 1)
    return _wrap(a)


def _routed(cells: _Cells, h: int, start: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The cuts of cell ``h`` from ``start`` (its points next to the marks): their feet on
    the hole, spread ``ROOM_RADII`` radii apart (:func:`spread`; the shortest paths from
    marks on the far side of a small hole converge on it, and a hole arc of a few radii is
    no side the edge network finds), and the points of the shortest paths to them."""
    loop = cells.holes[h]
    natural = _angle(cells.points[cells.foot[start]], cells.frames[h])
    order = np.argsort(natural)
    start, natural = start[order], natural[order]
    goal = spread(natural, ROOM_RADII * cells.radius / cells.span[h])
    at = _angle(cells.points[loop], cells.frames[h])
    feet = loop[np.argmin(np.abs(_wrap(at[None, :] - goal[:, None])), axis=1)]
    moved = np.abs(_wrap(goal - natural)) > 1e-9
    path = [cut_paths(cells.pred, start[~moved])]
    if moved.any():
        m = cells.members[h]
        sub = cells.graph[m][:, m]
        local = np.searchsorted(m, np.concatenate([feet[moved], start[moved]]))
        _, pred = dijkstra(sub, indices=local[: moved.sum()], return_predecessors=True)
        for row, s in enumerate(local[moved.sum():]):
            path.append(m[cut_paths(np.asarray(pred[row], dtype=np.int64), np.array([s]))])
    feet[~moved] = cells.foot[start[~moved]]
    return feet, np.unique(np.concatenate(path))


def _pieces(cells: _Cells) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Step 5: each point's piece and the feet of all cuts.

    1. Per cell, its cuts (:func:`_routed`); the points within ``BAND_RADII`` radii of
       their paths (and ``LINK_RADII`` of their ends) are taken out; the rest falls into
       pieces (connected on the k-NN graph).
    2. Pieces under ``MIN_PART`` points join the band; band points join the piece of their
       nearest other point.
    """
    piece = np.zeros(len(cells.points), dtype=np.int64)
    start = cells.starts(cells.marks) if len(cells.marks) else np.zeros((0, cells.k), dtype=np.int64)
    feet, first = [], 0
    for h in range(cells.k):
        m = cells.members[h]
        mine = start[:, h][start[:, h] >= 0]
        part = np.zeros(len(m), dtype=np.int64)
        if len(mine) >= 2:
            foot, path = _routed(cells, h, mine)
            feet.append(foot)
            ends = np.concatenate([cells.marks[start[:, h] >= 0], foot])
            part = _split_cell(cells.points[m], cells.idx, m, cells.points[path], cells.points[ends],
                               cells.radius)
        piece[m] = first + part
        first += int(part.max()) + 1
    return piece, np.concatenate(feet) if feet else np.zeros(0, dtype=np.int64)


def _split_cell(
    pts: NDArray[np.float64], idx: NDArray[np.int64], members: NDArray[np.int64],
    path: NDArray[np.float64], marks: NDArray[np.float64], radius: float,
) -> NDArray[np.int64]:
    """Step 5 for one cell (``members``; ``idx``: the whole segment's neighbours): parts
    ``0..n-1`` of its points, apart across the cuts' points ``path`` and round their ends
    ``marks`` (a cut starts a point or two inside the cell and ends inside the band of its
    hole: no gap to leak through)."""
    band = (cKDTree(path).query(pts)[0] <= BAND_RADII * radius) | (
        cKDTree(marks).query(pts)[0] <= LINK_RADII * radius)
    local = np.full(int(idx.shape[0]), -1, dtype=np.int64)
    local[members] = np.arange(len(members))
    nb = local[idx[members]]
    keep = (nb >= 0) & ~band[:, None] & ~band[np.maximum(nb, 0)]
    rows = np.repeat(np.arange(len(members)), idx.shape[1])[keep.ravel()]
    graph = coo_matrix((np.ones(len(rows)), (rows, nb.ravel()[keep.ravel()])), shape=(len(members),) * 2)
    comp = connected_components(graph, directed=False)[1]
    size = np.bincount(comp)
    solid = ~band & (size[comp] >= MIN_PART)
    if not solid.any():
        return np.zeros(len(members), dtype=np.int64)
    out = np.unique(comp[solid], return_inverse=True)[1].reshape(-1)
    full = np.empty(len(members), dtype=np.int64)
    full[solid] = out
    full[~solid] = out[cKDTree(pts[solid]).query(pts[~solid])[1]]
    return full


def cut_holes(
    points: NDArray[np.float64], loops: list[NDArray[np.int64]], radius: float,
    known: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Cut a segment with 3 or more boundary loops into quads (module docstring).

    1. Cells round every loop (no loop is special: no narrow cell of a large hole reaches
       out to the outer loop between small ones, as a flange's bore between its bolt holes).
    2. Where those are not all rings, cells round all loops but the longest.

    Parameters
    ----------
    points : (P, 3) float
        The segment's points.
    loops : list of (m,) int
        Its boundary loops (indices into ``points``), 3 or more.
    radius : float
        The layout's neighbour radius.
    known : (C, 3) float, optional
        Corners on the loops that cuts must end at (a neighbour's, or cut ends of a segment
        cut before).

    Returns
    -------
    piece : (P,) int
        Piece of each point, ``0..n-1``.
    ends : (E, 3) float
        Where the cuts meet the loops (feet on the holes, marks on the outer loop): the
        corners the rings beyond them must cut at.

    Raises
    ------
    InputError
        Fewer than 3 loops, or no partition into rings.
    """
    if len(loops) < 3:
        raise InputError(f"cut_holes needs 3 or more boundary loops, got {len(loops)}")
    length = [float(np.ptp(points[lp], axis=0).sum()) for lp in loops]
    o = int(np.argmax(length))
    known = np.zeros((0, 3)) if known is None else known
    piece, ends, rings = _partition(points, loops, np.zeros(0, dtype=np.int64), radius, known)
    if not rings:
        piece, ends, rings = _partition(points, [lp for j, lp in enumerate(loops) if j != o], loops[o],
                                        radius, known)
    if not rings:
        raise InputError(f"the cells round its {len(loops)} boundary loops are no rings")
    return piece, ends


def _partition(
    points: NDArray[np.float64], sources: list[NDArray[np.int64]], outer: NDArray[np.int64],
    radius: float, known: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.float64], bool]:
    """Steps 1-5 with cells round ``sources`` (the holes, or every loop), ``outer`` the loop
    that is no source (or none).

    Returns
    -------
    piece, ends
        As :func:`cut_holes`.
    rings : bool
        Whether every cell is a ring.
    """
    cells = _Cells(points, sources, outer, radius)
    vertices = vertex_marks(points, cells.cell, cells.idx, cells.near_outer, radius)
    cells.add(vertices)
    cells.add(saddle_marks(points, cells.cell, cells.idx, cells.near_outer, cells.dist, vertices, radius),
              room=True)
    cells.add(_known_marks(cells, known))
    _fill_gaps(cells)
    piece, feet = _pieces(cells)
    ends = np.vstack([points[feet], points[cells.marks[cells.near_outer[cells.marks]]]])
    return piece, ends, all(cells.is_ring(h) for h in range(cells.k))


__all__ = ["cut_holes", "hole_cells", "loop_angles", "vertex_marks"]
