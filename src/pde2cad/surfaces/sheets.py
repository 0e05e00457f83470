"""Neighbourhoods on one sheet of a surface.

A ball around a point of a thin lip or wall holds both of its sides: the Utah teapot's rim
is a lip whose two sides lie 0.1 apart at its foot, less than a quadric's reach on 100k
samples, and a normal or quadric fitted to both lies between them (its open rim was found
on the crest, 0.05 above the true one). Along the surface the far side is the whole fold
away. Both functions here keep the points whose shortest path through the samples (steps
of at most a few spacings) is about as short as the straight distance:

* :func:`one_sheet`: one graph search from many sources over a set of points (a tube
  around a curve, a ball around a corner);
* :func:`same_sheet`: the k nearest neighbours of many queries at once, each neighbourhood
  searched on its own (one graph of all of them, side by side and unlinked).

Core math: numpy and scipy only.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

#: Longest step between neighbours on one sheet, in sample spacings (uniform random samples
#: leave a point without a neighbour this close with probability exp(-pi 2.5^2) ~ 3e-9).
SHEET_LINK = 2.5
#: Path length along a sheet over straight distance that still counts as near (paths
#: through random samples zigzag ~5-15 % longer).
SHEET_STRETCH = 1.25
#: The neighbour rank whose distance sets a neighbourhood's own spacing in
#: :func:`same_sheet` (at rank r a uniform sample's distance is ~sqrt(r / pi) spacings).
SPACING_RANK = 6


def one_sheet(
    cloud: NDArray[np.float64], queries: NDArray[np.float64], link: float, limit: float,
    least: int = 0,
) -> NDArray[np.int64]:
    """Indices of the ``cloud`` points on the queries' own sheet: within ``limit`` along the
    surface (steps of at most ``link``) of the points nearest the queries.

    Returns every index when fewer than ``least`` points are reached (a sparse cloud's links
    break off: better a mixed neighbourhood than none).
    """
    tree = cKDTree(cloud)
    _, src = tree.query(queries)
    graph = tree.sparse_distance_matrix(tree, link, output_type="coo_matrix").tocsr()
    dist = dijkstra(graph, directed=False, indices=np.unique(src), min_only=True, limit=limit)
    keep = np.flatnonzero(np.isfinite(dist))
    return keep if len(keep) >= least else np.arange(len(cloud))


def same_sheet(points: NDArray[np.float64], idx: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Mask (Q, k) of the neighbours ``idx[:, j]`` on the sheet of ``idx[:, 0]``.

    1. Per neighbourhood, its spacing: its first point's distance to its
       ``SPACING_RANK``-th neighbour over ``sqrt(SPACING_RANK / pi)``. One within a slab
       half a link (``SHEET_LINK`` spacings) thick is one sheet; the others go on, in
       units of a link, side by side far apart.
    2. Links: pairs within one unit (one k-d tree over all neighbourhoods at once).
    3. Shortest paths from every neighbourhood's first point (one multi-source Dijkstra:
       the neighbourhoods are not linked to each other).
    4. A neighbour is on the sheet when its path is at most ``SHEET_STRETCH`` x its
       straight distance (a direct link always is).
    """
    out = np.ones(idx.shape, dtype=bool)
    if idx.shape[1] <= SPACING_RANK:
        return out
    hood = points[idx] - points[idx[:, :1]]  # (Q, k, 3), first point at the origin
    straight = np.linalg.norm(hood, axis=2)
    spacing = np.partition(straight, SPACING_RANK, axis=1)[:, SPACING_RANK]
    unit = SHEET_LINK * np.maximum(spacing, 1e-300) / np.sqrt(SPACING_RANK / np.pi)
    # A neighbourhood within a slab half a link thick holds no second sheet a link away.
    centred = hood - hood.mean(axis=1, keepdims=True)
    normal = np.linalg.eigh(np.einsum("qki,qkj->qij", centred, centred))[1][:, :, 0]
    slab = np.abs(np.einsum("qki,qi->qk", centred, normal)).max(axis=1)
    # (Rows without SPACING_RANK distinct neighbours, e.g. padded with repeats, stay whole.)
    test = np.flatnonzero((slab >= 0.5 * unit) & (spacing > 0.0))
    if test.size:
        out[test] = _on_paths(hood[test], straight[test], unit[test])
    return out


def _on_paths(
    hood: NDArray[np.float64], straight: NDArray[np.float64], unit: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Steps 2-4 of :func:`same_sheet` for neighbourhoods ``hood`` (Q, k, 3) around their
    first point, ``straight`` their distances from it, ``unit`` their link lengths."""
    q, k = straight.shape
    local = hood / unit[:, None, None]
    straight = straight / unit[:, None]
    step = 2.0 * float(straight.max()) + 2.0
    local[:, :, 0] += step * np.arange(q)[:, None]
    flat = local.reshape(-1, 3)
    pairs = cKDTree(flat).query_pairs(1.0, output_type="ndarray")
    weight = np.linalg.norm(flat[pairs[:, 0]] - flat[pairs[:, 1]], axis=1)
    n = q * k
    graph = coo_matrix((weight, (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    geo = dijkstra(graph, directed=False, indices=np.arange(q) * k, min_only=True)
    return (geo.reshape(q, k) <= SHEET_STRETCH * straight + 1e-9)
