"""Sharp creases of a triangle mesh, told apart from the faceting of a smooth surface.

A coarse mesh of a curved surface bends every edge by about its spacing over the radius
of curvature across it: on the 1.8k-vertex Stanford bunny 10 % of the edges bend by more
than 30 deg, in bands where every edge bends by 10-20 deg. A crease bends by its own angle
on top of what the surface around it bends; a CAD part's faces next to a crease are flat or
finely tessellated (their edges bend by 0-10 deg). So:

1. :func:`dihedral_angles`: the angle between the two faces' normals, per interior edge.
2. :func:`background_bend`: the surface's own bend around each edge that bends by more
   than the crease angle, the median dihedral of the edges within ``BACKGROUND_RINGS`` face
   rings that bend less (a crease's chain and the creases next to it are left out, so a
   12-triangle box reads 0 and keeps its 12 creases).
3. An edge is a crease when its dihedral exceeds the background by more than the crease
   angle: the angle keeps its meaning, the normal jump of a real crease, on a faceted
   curved face as on a flat one. An edge bending by over twice the angle stays a crease
   whatever its surroundings (the background is below the angle).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix

#: Face rings around an edge whose edges give its :func:`background_bend`: two rings hold
#: ~25 edges, enough for a median, within ~2 spacings of the edge.
BACKGROUND_RINGS = 2


def dihedral_angles(normals: NDArray[np.float64], pair: NDArray[np.int64]) -> NDArray[np.float64]:
    """Angle (deg) between the unit normals of each edge's two faces, ``pair``: (E, 2) int."""
    cos = np.einsum("ij,ij->i", normals[pair[:, 0]], normals[pair[:, 1]])
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def crease_mask(normals: NDArray[np.float64], pair: NDArray[np.int64], angle: float
                ) -> NDArray[np.bool_]:
    """Which interior edges are creases (the module's steps 1-3).

    Parameters
    ----------
    normals : (F, 3) float
        Unit face normals.
    pair : (E, 2) int
        The two faces of each interior edge.
    angle : float
        Crease angle (deg): the least normal jump of a crease.

    Returns
    -------
    (E,) bool
    """
    theta = dihedral_angles(normals, pair)
    crease = theta > angle
    if crease.any():
        crease[crease] = theta[crease] - background_bend(theta, pair, crease, len(normals)) > angle
    return crease


def background_bend(
    theta: NDArray[np.float64], pair: NDArray[np.int64], bent: NDArray[np.bool_], n_faces: int,
    rings: int = BACKGROUND_RINGS,
) -> NDArray[np.float64]:
    """Median dihedral (deg) of the edges that are not ``bent`` within ``rings`` face rings
    of each ``bent`` edge's faces; 0 where there are none.

    1. Edge-face incidence ``M`` (E x F, sparse); the bent edges' faces grown by ``rings``
       products with the face adjacency ``M^T M``, their edges by one product with ``M^T``.
    2. Per bent edge, the median of those edges' dihedrals, from one lexicographic sort.

    Returns
    -------
    (B,) float
        One value per ``bent`` edge, in edge order.
    """
    n_e = len(pair)
    inc = csr_matrix(coo_matrix((np.ones(2 * n_e), (np.tile(np.arange(n_e), 2), pair.T.ravel())),
                                shape=(n_e, n_faces)))
    near = inc[np.flatnonzero(bent)]
    adjacency = inc.T @ inc
    for _ in range(rings):
        near = near @ adjacency
    found = coo_matrix(near @ inc.T)
    keep = ~bent[found.col]
    row, col = found.row[keep], found.col[keep]
    n_b = int(bent.sum())
    if not len(col):
        return np.zeros(n_b)
    order = np.lexsort((theta[col], row))
    row, col = row[order], col[order]
    count = np.bincount(row, minlength=n_b)
    start = np.searchsorted(row, np.arange(n_b))
    middle = np.minimum(start + count // 2, len(col) - 1)
    return np.where(count > 0, theta[col[middle]], 0.0)


#: Neighbours whose spread tells a point near a crease of a cloud (surface variation): the
#: first count at which the cloud's median point is calm enough (``CLOUD_NOISE_SHARE``).
CLOUD_NEIGHBOURS = (30, 60, 120)
#: Nearest neighbours each point is joined to when the regions are grown.
CLOUD_LINKS = 8
#: Points near a crease: their surface variation exceeds this share of the variation at a
#: crease of the crease angle itself (``crease_variation``; it falls to ~40 % one spacing off
#: the crease line and to 0 three spacings off at 30 neighbours).
CLOUD_SHARE = 0.5
#: A cloud whose median surface variation exceeds this share of the threshold is too noisy
#: to tell creases of that angle (measured on planes: median 0.008 at noise 0.2 spacings,
#: 0.029 at 0.4, 30 neighbours; the threshold at 30 deg is 0.0048): no crease regions.
CLOUD_NOISE_SHARE = 0.35


def _variation(points: NDArray[np.float64], idx: NDArray[np.int64]) -> NDArray[np.float64]:
    """Surface variation ``l0 / (l0 + l1 + l2)`` of each point's neighbours ``idx``, in
    chunks (bounded memory on large clouds)."""
    out = np.empty(len(points))
    step = max(1, CHUNK_VALUES // idx.shape[1])
    for start in range(0, len(points), step):
        near = points[idx[start : start + step]]
        hood = near - near.mean(axis=1, keepdims=True)
        values = np.linalg.eigvalsh(np.einsum("nki,nkj->nij", hood, hood))
        out[start : start + step] = values[:, 0] / np.maximum(values.sum(axis=1), 1e-300)
    return out


#: Neighbour coordinates per chunk of :func:`_variation`.
CHUNK_VALUES = 2_000_000


def crease_variation(angle: float) -> float:
    """Surface variation ``l0 / (l0 + l1 + l2)`` of a disk-shaped neighbourhood centred on
    a crease whose two sides' normals differ by ``angle`` degrees: across the crease the
    offset ``s`` (uniform on a disk of radius r) gives heights ``|s| sin(a/2)``, of variance
    ``(1/4 - 16 / (9 pi^2)) r^2 sin^2(a/2)``; along and across, ``r^2/4`` and
    ``r^2/4 cos^2(a/2)`` (checked against sampled creases: 30 deg 0.0096 vs 0.0086-0.0089,
    90 deg 0.085 vs 0.085-0.11)."""
    half = np.radians(angle) / 2.0
    height = (0.25 - 16.0 / (9.0 * np.pi**2)) * np.sin(half) ** 2
    return float(height / (0.25 + 0.25 * np.cos(half) ** 2 + height))


def cloud_regions(points: NDArray[np.float64], angle: float, min_points: int
                  ) -> NDArray[np.int64] | None:
    """Crease-bounded regions of a cloud without faces; None when it shows no creases or
    is too noisy to tell creases of ``angle`` degrees.

    1. Surface variation of each point's nearest neighbours (the smallest share of their
       covariance), over the fewest of ``CLOUD_NEIGHBOURS`` at which the cloud's median
       point stays below ``CLOUD_NOISE_SHARE`` of the threshold (step 2); None if even the
       most do not (too noisy to tell creases of ``angle``).
    2. Points near a crease: variation above ``CLOUD_SHARE`` x :func:`crease_variation`
       of ``angle``.
    3. The other points, joined to their neighbours, fall into connected regions; regions
       of fewer than ``min_points`` points (speckle along a crease) count as crease points.
    4. Crease points take the region of the nearest region point (on a crease's side the
       nearest such point lies on the same side).

    Returns
    -------
    (N,) int or None
        Region id per point, 0 .. R-1, when there are at least two regions.
    """
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=float)
    tree = cKDTree(pts)
    threshold = CLOUD_SHARE * crease_variation(angle)
    k = min(CLOUD_NEIGHBOURS[0], len(pts))
    _, idx = tree.query(pts, k=k, workers=-1)
    variation = _variation(pts, idx)
    # Noise spreads a neighbourhood's heights by its own size but its disk by r^2 ~ k, so
    # its variation falls as 1/k while a crease's keeps: more neighbours for noisier clouds.
    calm = [n for n in CLOUD_NEIGHBOURS
            if np.median(variation) * k / n <= CLOUD_NOISE_SHARE * threshold]
    if not calm:
        return None
    if calm[0] != k:
        k = min(calm[0], len(pts))
        _, idx = tree.query(pts, k=k, workers=-1)
        variation = _variation(pts, idx)
        if np.median(variation) > CLOUD_NOISE_SHARE * threshold:
            return None
    flat = variation <= threshold
    # Joined to the nearest few only: the variation's neighbourhood reaches ~3 spacings, as
    # far as a crease's band is wide, so its edges would bridge the band.
    link = min(CLOUD_LINKS, k)
    rows = np.repeat(np.arange(len(pts)), link)
    cols = idx[:, :link].ravel()
    keep = flat[rows] & flat[cols]
    graph = coo_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(len(pts),) * 2)
    _, region = connected_components(graph, directed=False)
    sizes = np.bincount(region[flat], minlength=int(region.max()) + 1)
    kept = flat & (sizes[region] >= min_points)
    if len(np.unique(region[kept])) < 2:
        return None
    _, near = cKDTree(pts[kept]).query(pts[~kept], workers=-1)
    region = region.copy()
    region[~kept] = region[kept][near]
    _, out = np.unique(region, return_inverse=True)
    return out.astype(np.int64)
