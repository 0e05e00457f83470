"""Pixel-boundary ("crack") loops of a binary mask, with their nesting.

Coordinates: x to the right, y downwards; pixel (row i, column j) is the unit square
[j, j+1] x [i, i+1]. A loop runs along the cracks between foreground and background
pixels, so its vertices are integer lattice points, never pixel centres.

Topology: foreground is 8-connected (pixels touching at a corner form one shape),
background 4-connected. At a saddle vertex (two foreground pixels touching diagonally, two
background pixels on the other diagonal) a loop passes through the vertex twice, turning
so that the two foreground pixels stay on the same loop.

Orientation
-----------
Every loop keeps the foreground on its LEFT in the mathematical sense of the (x, y)
coordinates: for a step ``d = (dx, dy)`` from vertex ``p``, the foreground pixel next to
that step is the one whose centre is ``p + d/2 + (-dy, dx)/2``. Equivalently, with the
shoelace formula ``A = 1/2 * sum(x_k * y_{k+1} - x_{k+1} * y_k)`` evaluated on the raw
(x, y) coordinates:

- outer loops have A > 0, equal to the number of pixels they enclose (holes included);
- hole loops have A < 0: minus the area they enclose (the hole, shapes inside it included);

so ``sum(A)`` over the loops of a shape is its pixel count. On screen (y pointing down)
outer loops run clockwise and holes counter-clockwise: the SVG/potrace picture.

Algorithm (vectorised, no Python loop over pixels or boundary points)
-------------------------------------------------------------------------
1. Every crack between a foreground and a background pixel becomes a directed unit edge
   (foreground on its left); horizontal edges are numbered first, in raster order, then
   vertical ones.
2. The successor of each edge follows from the two pixels ahead of its end vertex (turn
   right if the right-ahead pixel is foreground, else straight on if the left-ahead pixel
   is, else turn left), found by ``searchsorted`` in the sorted edge keys.
3. The successor permutation splits into cycles, each labelled by its smallest edge
   (random rulers walk to the next ruler, then the rulers are reduced by doubling); each
   cycle is ranked from its start edge the same way in O(n).
4. Shapes are numbered in raster order of their first pixel, as ``ndimage.label`` with
   a 3x3 structure numbers them, without labelling the image. Only when there are holes
   is nesting needed: a ray cast upwards from each loop's top edge to the nearest crack
   above it (``searchsorted`` on the cracks sorted by column) finds the loop of the same
   shape (above a hole) or of the same background region (above an outer loop).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pde2cad.errors import InputError

__all__ = ["ContourLoop", "signed_area", "trace_loops"]

# Direction codes 0..3 = +x, +y, -x, -y. With this order (k + 1) % 4 is a left turn and
# (k - 1) % 4 a right turn in the mathematical sense of the (x, y) coordinates.
#
# Vertices and pixels share one flat index on the padded image: vertex (x, y) has index
# y * wp + x, that of the pixel (row y, col x) below-right of it (wp = padded width). The
# four pixels around vertex v are then TL = v - wp - 1, TR = v - wp, BL = v - 1, BR = v.

# Mean distance between the rulers of the list ranking in _rank_in_cycles.
_RULER_SPACING = 16


@dataclass(frozen=True, slots=True)
class ContourLoop:
    """One closed crack loop around a shape or a hole.

    Attributes
    ----------
    points : (n, 2) float64
        Vertices (x, y) of the crack polygon, integer-valued, in walking order; the loop
        closes implicitly (``points[-1] != points[0]``). Every unit step is a vertex:
        consecutive points (including last -> first) differ by exactly 1 along x or y,
        and n >= 4. The loop starts at its top-most, then left-most vertex. Foreground is
        on the left in the (x, y) sense (see the module docstring): outer loops have
        positive shoelace area, holes negative. The array is read-only (a view of one
        buffer shared by all loops of a trace).
    is_hole : bool
        True for the boundary of a hole in a shape.
    shape : int
        0-based id of the foreground 8-connected component this loop bounds; ids follow
        the raster order of each component's first pixel (``scipy.ndimage.label``).
    parent : int
        For an outer loop: id of the shape in whose hole this shape lies, or -1 at top
        level. For a hole: its own shape id.
    depth : int
        0 for the outer loop of a top-level shape, 1 for its holes, 2 for the outer loop
        of a shape inside such a hole, 3 for that shape's holes, ...
    """

    points: NDArray[np.float64]
    is_hole: bool
    shape: int
    parent: int
    depth: int

    @property
    def signed_area(self) -> float:
        """Shoelace area: > 0 (pixels enclosed) for outer loops, < 0 for holes."""
        return signed_area(self.points)


def signed_area(points: NDArray[np.float64]) -> float:
    """Shoelace area ``1/2 * sum(x_k y_{k+1} - x_{k+1} y_k)`` of a closed polygon.

    Parameters
    ----------
    points : (n, 2) float
        Vertices (x, y); the polygon closes from the last point back to the first.

    Returns
    -------
    area : float
        Positive when the polygon turns from +x towards +y (clockwise on a y-down screen).
    """
    p = np.asarray(points, dtype=np.float64)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def trace_loops(mask: NDArray[np.bool_]) -> list[ContourLoop]:
    """Trace the pixel-boundary loops of every shape in a binary mask.

    Parameters
    ----------
    mask : (H, W) bool
        True for foreground pixels. Integer arrays are accepted (non-zero = foreground).

    Returns
    -------
    loops : list of ContourLoop
        Sorted by shape id; each shape's outer loop comes first, then its holes in raster
        order of their top-left vertex. Empty for a mask without foreground.

    Raises
    ------
    InputError
        If ``mask`` is not 2-D or is not boolean/integer.

    Notes
    -----
    Cost: a few boolean passes over the image and O(n) in the number n of boundary
    edges (O(n log n) for the column sort when there are holes). Peak memory is about
    2 bytes per pixel (padded mask, a boolean temporary) plus about 150 bytes per edge.
    """
    arr = np.asarray(mask)
    if arr.ndim != 2:
        raise InputError(
            f"the mask must be 2-D (H, W), got shape {arr.shape}; threshold the image "
            "with pde2cad.image.raster.to_mask first"
        )
    if arr.dtype.kind not in "bui":
        raise InputError(
            f"the mask must be boolean, got dtype {arr.dtype}; threshold it first "
            "(pde2cad.image.raster.to_mask, or mask > 0.5)"
        )
    height, width = arr.shape
    if height == 0 or width == 0:
        return []

    # One background pixel of padding: no crack lies on the array border and all
    # background outside the shapes is one 4-connected region.
    pad = np.zeros((height + 2, width + 2), dtype=bool)
    if arr.dtype == np.bool_:
        pad[1:-1, 1:-1] = arr
    else:
        np.not_equal(arr, 0, out=pad[1:-1, 1:-1])
    if not pad.any():
        return []
    wp = width + 2  # padded row length

    # ---- 1. directed crack edges ---------------------------------------------------
    flat = pad.reshape(-1)
    # Horizontal crack on line y = r between pixels (r-1, c) and (r, c): key is the flat
    # index of the upper pixel. np.flatnonzero returns the keys sorted (step 2 needs it).
    key_h = np.flatnonzero(flat[wp:] != flat[:-wp])
    # Vertical crack on line x = c between pixels (r, c-1) and (r, c): key is the flat
    # index of the left pixel. Pairs straddling two rows compare padding with padding,
    # so they never produce an edge.
    key_v = np.flatnonzero(flat[1:] != flat[:-1])
    n_h, n_v = key_h.size, key_v.size
    n_edges = n_h + n_v
    h_down = flat[key_h + wp]  # foreground below -> edge runs +x, else -x
    v_left = flat[key_v]  # foreground on the left (x smaller) -> edge runs +y, else -y
    # Start vertex (flat) and direction of every edge, horizontal ones first. The upper
    # pixel of horizontal crack `key` has the crack's left end as its bottom-left vertex.
    start_v = np.concatenate(
        [np.where(h_down, key_h + wp, key_h + wp + 1), np.where(v_left, key_v + 1, key_v + 1 + wp)]
    )
    k = np.concatenate([np.where(h_down, 0, 2), np.where(v_left, 1, 3)]).astype(np.int8)
    del h_down, v_left

    # ---- 2. successor of every edge --------------------------------------------------
    step = np.array([1, wp, -1, -wp], dtype=np.int64)
    left_ahead_off = np.array([0, -1, -wp - 1, -wp], dtype=np.int64)  # BR, BL, TL, TR
    right_ahead_off = np.array([-wp, 0, -1, -wp - 1], dtype=np.int64)  # TR, BR, BL, TL
    end_v = start_v + step[k]
    right_ahead = flat[end_v + right_ahead_off[k]]
    left_ahead = flat[end_v + left_ahead_off[k]]
    # Right turn when the right-ahead pixel is foreground: at a saddle this keeps the two
    # diagonal foreground pixels on one loop (8-connected foreground).
    k_next = np.where(right_ahead, (k - 1) % 4, np.where(left_ahead, k, (k + 1) % 4))
    del right_ahead, left_ahead
    # Key of the edge leaving vertex v in direction k_next: +x -> horizontal key v - wp,
    # -x -> v - wp - 1; +y -> vertical key v - 1, -y -> v - wp - 1.
    out_off = np.array([-wp, -1, -wp - 1, -wp - 1], dtype=np.int64)
    q = end_v + out_off[k_next]
    del end_v
    succ = np.empty(n_edges, dtype=np.int64)
    horiz = (k_next & 1) == 0
    del k_next
    succ[horiz] = np.searchsorted(key_h, q[horiz])
    succ[~horiz] = n_h + np.searchsorted(key_v, q[~horiz])
    del q, horiz, key_v

    # ---- 3. cycles and the order within them ----------------------------------------
    low = _cycle_minimum(succ)
    is_first = low == np.arange(n_edges, dtype=np.int64)
    first = np.flatnonzero(is_first)
    n_loops = first.size
    cyc = (np.cumsum(is_first) - 1)[low]
    del low, is_first
    # Each loop's smallest edge index is its top-most, left-most horizontal edge. It runs
    # +x on an outer loop (foreground below) and -x on a hole (background below).
    is_hole = k[first] == 2
    # Start at the top-left vertex: the first edge's start for outer loops, its end
    # (the start of its successor) for holes.
    start = np.where(is_hole, succ[first], first)
    pos = _rank_in_cycles(succ, start)
    sizes = np.bincount(cyc, minlength=n_loops)

    # ---- 4. shapes, regions and nesting ---------------------------------------------
    # The first pixel (raster order) of a shape has background above it, outside the
    # shape, so its top crack is the smallest edge of the shape's outer loop. Ranking the
    # outer loops by first edge therefore numbers the shapes exactly as ndimage.label
    # does, without labelling the image.
    outer = np.flatnonzero(~is_hole)
    outer = outer[np.argsort(first[outer], kind="stable")]
    n_shapes = outer.size
    shape = np.empty(n_loops, dtype=np.int64)
    shape[outer] = np.arange(n_shapes, dtype=np.int64)
    parent_of_shape = np.full(n_shapes, -1, dtype=np.int64)
    if np.any(is_hole):
        _nest(key_h[first], is_hole, shape, parent_of_shape, key_h, cyc, wp, height + 2)
    del pad
    shape_depth = 2 * _count_ancestors(parent_of_shape)
    parent = np.where(is_hole, shape, parent_of_shape[shape])
    depth = shape_depth[shape] + is_hole

    # ---- output: one (n, 2) buffer, loops as read-only slices ----------------------
    order = np.lexsort((first, is_hole, shape))  # by shape, outer first, then raster
    offsets = np.zeros(n_loops + 1, dtype=np.int64)
    np.cumsum(sizes[order], out=offsets[1:])
    loop_offset = np.empty(n_loops, dtype=np.int64)
    loop_offset[order] = offsets[:-1]
    dest = loop_offset[cyc] + pos
    points = np.empty((n_edges, 2), dtype=np.float64)
    sy, sx = np.divmod(start_v, wp)
    points[dest, 0] = sx - 1  # undo the padding
    points[dest, 1] = sy - 1
    points.flags.writeable = False

    bounds = offsets.tolist()
    holes = is_hole[order].tolist()
    shapes = shape[order].tolist()
    parents = parent[order].tolist()
    depths = depth[order].tolist()
    return [
        ContourLoop(points[bounds[i] : bounds[i + 1]], holes[i], shapes[i], parents[i], depths[i])
        for i in range(n_loops)
    ]


def _nest(
    above: NDArray[np.int64],
    is_hole: NDArray[np.bool_],
    shape: NDArray[np.int64],
    parent_of_shape: NDArray[np.int64],
    key_h: NDArray[np.int64],
    cyc: NDArray[np.int64],
    wp: int,
    hp: int,
) -> None:
    """Fill in each hole's shape and each shape's parent by casting rays upwards.

    Steps: 1. from the pixel above each loop's first (top-most) edge, the nearest
    horizontal crack above it in its column is found by ``searchsorted`` in the cracks
    sorted by column; 2. above a hole that pixel is foreground, so the crack lies on a
    loop of the same shape (its outer loop or a higher hole); above an outer loop it is
    background, so the crack bounds the same background region: a hole (whose shape is
    the parent) or the outer loop of a shape in the same region (same parent), or there
    is none (top level); 3. each link points to a loop whose first edge is higher, so
    pointer jumping resolves the chains. ``shape`` (holes) and ``parent_of_shape`` are
    written in place.

    Parameters
    ----------
    above : (L,) int64
        Flat padded index of the pixel above each loop's first edge.
    is_hole : (L,) bool
    shape : (L,) int64
        Shape ids of the outer loops (the holes' entries are overwritten).
    parent_of_shape : (S,) int64
    key_h : (n_h,) int64
        Sorted flat index of the upper pixel of every horizontal crack (= edge index).
    cyc : (n,) int64
        Loop of every edge.
    wp, hp : int
        Padded width and height.
    """
    col_key = (key_h % wp) * hp + key_h // wp
    by_col = np.argsort(col_key, kind="stable")
    col_key = col_key[by_col]
    query = (above % wp) * hp + above // wp
    j = np.searchsorted(col_key, query) - 1
    found = (j >= 0) & (col_key[np.maximum(j, 0)] // hp == query // hp)
    hit = np.where(found, cyc[by_col[np.maximum(j, 0)]], -1)
    loops = np.arange(is_hole.size, dtype=np.int64)
    # Holes: the loop hit belongs to the same shape; outer loops end the chain.
    link = np.where(is_hole, hit, loops)
    shape[is_hole] = shape[_resolve_links(link)[is_hole]]
    # Outer loops: a hit outer loop has the same parent; a hit hole or nothing ends it.
    outer_hit = found & ~is_hole & ~is_hole[np.maximum(hit, 0)]
    link = np.where(outer_hit, hit, loops)
    root = _resolve_links(link)
    value = np.where(found, shape[np.maximum(hit, 0)], -1)  # parent at a chain's end
    outer = ~is_hole
    parent_of_shape[shape[outer]] = value[root[outer]]


def _resolve_links(link: NDArray[np.int64]) -> NDArray[np.int64]:
    """End of every chain of an acyclic pointer forest (``link[i] == i`` at the ends)."""
    while True:
        nxt = link[link]
        if np.array_equal(nxt, link):
            return link
        link = nxt


def _cycle_minimum(succ: NDArray[np.int64]) -> NDArray[np.int64]:
    """Smallest element of the cycle of every element of a permutation.

    Steps: 1. about n/16 random rulers walk forward, all at once, to the next ruler,
    taking the minimum of the elements they pass and marking them as theirs; 2. the
    rulers' own permutation (ruler -> next ruler) is reduced by min-doubling; 3. the few
    elements on cycles without a ruler (short cycles) are reduced by min-doubling too.
    O(n) work in about 16 ln(n) vectorised rounds plus O((n / 16) log n).
    """
    n = succ.size
    is_ruler = np.random.default_rng(1).random(n) < 1.0 / _RULER_SPACING
    rulers = np.flatnonzero(is_ruler)
    ruler_id = np.full(n, -1, dtype=np.int64)
    ruler_id[rulers] = np.arange(rulers.size, dtype=np.int64)
    owner = ruler_id.copy()
    low = rulers.copy()
    next_ruler = np.empty(rulers.size, dtype=np.int64)
    walker = np.arange(rulers.size, dtype=np.int64)
    cur = succ[rulers]
    while walker.size:
        hit = is_ruler[cur]
        next_ruler[walker[hit]] = ruler_id[cur[hit]]
        walker, cur = walker[~hit], cur[~hit]
        owner[cur] = walker
        low[walker] = np.minimum(low[walker], cur)
        cur = succ[cur]
    out = np.empty(n, dtype=np.int64)
    reached = owner >= 0
    out[reached] = _min_doubling(next_ruler, low)[owner[reached]]
    rest = np.flatnonzero(~reached)
    if rest.size:
        local = np.searchsorted(rest, succ[rest])  # cycles without a ruler are closed
        out[rest] = _min_doubling(local, rest)
    return out


def _min_doubling(succ: NDArray[np.int64], value: NDArray[np.int64]) -> NDArray[np.int64]:
    """Minimum of ``value`` over every cycle of the permutation ``succ``, per element."""
    low, nxt, span = value.copy(), succ.copy(), 1
    while span < succ.size:
        low = np.minimum(low, low[nxt])
        nxt = nxt[nxt]
        span *= 2
    return low


def _rank_in_cycles(succ: NDArray[np.int64], start: NDArray[np.int64]) -> NDArray[np.int64]:
    """Position of every element in its cycle, counted from the cycle's start element.

    Parameters
    ----------
    succ : (n,) int64
        A permutation: ``succ[e]`` follows ``e`` on its cycle.
    start : (m,) int64
        Exactly one element of each of the m cycles.

    Returns
    -------
    pos : (n,) int64
        0 for the start elements, 1 for their successors, and so on.

    Notes
    -----
    Plain pointer jumping costs O(n log n) random memory accesses, which dominates on
    long loops. Instead about n/16 random "rulers" (plus every start) each walk forward,
    all at once, to the next ruler, labelling the elements they pass: O(n) work in about
    16 ln(n) vectorised rounds on a shrinking set of walkers. Only the short list of
    rulers is then ranked by pointer jumping. Ruler choice uses a fixed seed, though the
    result does not depend on it.
    """
    n = succ.size
    is_ruler = np.random.default_rng(0).random(n) < 1.0 / _RULER_SPACING
    is_ruler[start] = True
    rulers = np.flatnonzero(is_ruler)
    m = rulers.size
    ruler_id = np.full(n, -1, dtype=np.int64)
    ruler_id[rulers] = np.arange(m, dtype=np.int64)
    owner = np.empty(n, dtype=np.int64)  # the ruler at or before each element
    offset = np.zeros(n, dtype=np.int64)  # steps from that ruler
    owner[rulers] = np.arange(m, dtype=np.int64)
    next_ruler = np.empty(m, dtype=np.int64)
    gap = np.empty(m, dtype=np.int64)
    walker = np.arange(m, dtype=np.int64)
    cur = succ[rulers]
    step = 1
    while walker.size:
        hit = is_ruler[cur]
        if hit.any():
            next_ruler[walker[hit]] = ruler_id[cur[hit]]
            gap[walker[hit]] = step
            walker = walker[~hit]
            cur = cur[~hit]
        owner[cur] = walker
        offset[cur] = step
        cur = succ[cur]
        step += 1
    ruler_pos = _weighted_list_rank(next_ruler, gap, ruler_id[start])
    return ruler_pos[owner] + offset


def _weighted_list_rank(
    succ: NDArray[np.int64], weight: NDArray[np.int64], start: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Weighted distance of every element from its cycle's start, by pointer jumping.

    Parameters
    ----------
    succ : (n,) int64
        A permutation whose cycles are the lists.
    weight : (n,) int64
        Length of the step from ``e`` to ``succ[e]``.
    start : (m,) int64
        Exactly one element of each cycle.

    Returns
    -------
    pos : (n,) int64
        Sum of the weights from the start of the cycle up to each element (0 at starts).
    """
    n = succ.size
    pred = np.empty(n, dtype=np.int64)
    pred[succ] = np.arange(n, dtype=np.int64)
    last = pred[start]  # cut each cycle between its last element and its start
    nxt = succ.copy()
    nxt[last] = last
    dist = weight.copy()  # weighted length from e to nxt[e]
    dist[last] = 0
    active = np.flatnonzero(nxt[nxt] != nxt)
    while active.size:
        hop = nxt[active]
        # Read both arrays before writing them: the rounds must be synchronous.
        new_dist = dist[active] + dist[hop]
        new_nxt = nxt[hop]
        dist[active] = new_dist
        nxt[active] = new_nxt
        active = active[nxt[new_nxt] != new_nxt]
    # Now nxt[e] is the last element of e's cycle and dist[e] the distance to it.
    total = np.empty(n, dtype=np.int64)
    total[last] = dist[start]
    return total[nxt] - dist


def _count_ancestors(parent: NDArray[np.int64]) -> NDArray[np.int64]:
    """Number of ancestors of each node of a forest given by parent pointers (-1 = root)."""
    count = (parent >= 0).astype(np.int64)
    nxt = parent.copy()
    active = np.flatnonzero(nxt >= 0)
    while active.size:
        hop = nxt[active]
        new_count = count[active] + count[hop]
        new_nxt = nxt[hop]
        count[active] = new_count
        nxt[active] = new_nxt
        active = active[new_nxt >= 0]
    return count
