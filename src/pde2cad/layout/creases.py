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

from typing import NamedTuple

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
#: A cloud whose median surface variation (less its noise's) exceeds this share of the
#: threshold is too rough to tell creases of that angle.
CLOUD_NOISE_SHARE = 0.35
#: Noise adds ``sigma^2 / spread`` to a point's variation (``_variation``), estimated from
#: k points to a relative deviation ``sqrt(2 / k)``: creases of an angle are told when this
#: many such deviations of the median point stay within ``CLOUD_NOISE_SHARE`` of the
#: threshold (the excess over the noise is what is thresholded).
CLOUD_NOISE_DEVIATIONS = 3.0


def _variation(points: NDArray[np.float64], idx: NDArray[np.int64], quadric: bool = False
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    """Surface variation ``l0 / (l0 + l1 + l2)`` of each point's neighbours ``idx``, their
    spread ``l0 + l1 + l2`` (eigenvalues of their covariance) and, with ``quadric``, their
    quadric variation: the mean square height off the quadric through them (in their PCA
    frame) over the spread, which a curved smooth surface keeps near 0 where its sag raises
    ``l0`` (it costs 2.5x: 4.7 s at 150k points and 120 neighbours); in chunks (bounded
    memory on large clouds)."""
    out, spread = np.empty(len(points)), np.empty(len(points))
    quad = np.empty(len(points)) if quadric else None
    step = max(1, CHUNK_VALUES // idx.shape[1])
    for start in range(0, len(points), step):
        part = slice(start, start + step)
        near = points[idx[part]]
        hood = near - near.mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", hood, hood)
        if quad is None:
            values = np.linalg.eigvalsh(cov) / idx.shape[1]
        else:
            values, vectors = np.linalg.eigh(cov)
            values /= idx.shape[1]
        spread[part] = values.sum(axis=1)
        out[part] = values[:, 0] / np.maximum(spread[part], 1e-300)
        if quad is not None:
            quad[part] = _quadric_residual(hood, vectors, values) / np.maximum(spread[part], 1e-300)
    return out, spread, quad


def _quadric_residual(hood: NDArray[np.float64], vectors: NDArray[np.float64],
                      values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean square height of centred neighbourhoods ``hood`` (n, k, 3) off their quadric
    ``z = f(x, y)`` in their PCA frames (``vectors``, ``values`` ascending)."""
    local = np.einsum("nki,nij->nkj", hood, vectors)  # columns: normal, minor, major
    z = local[..., 0]
    scale = np.sqrt(values[:, 1:].sum(axis=1))[:, None] + 1e-300
    x, y = local[..., 2] / scale, local[..., 1] / scale
    design = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    gram = np.einsum("nki,nkj->nij", design, design) + 1e-10 * np.eye(6)
    coef = np.linalg.solve(gram, np.einsum("nki,nk->ni", design, z)[..., None])[..., 0]
    residual = z - np.einsum("nki,ni->nk", design, coef)
    return (residual**2).mean(axis=1)


#: Neighbour coordinates per chunk of :func:`_variation`.
CHUNK_VALUES = 1_000_000
#: A quadric through a crease's neighbourhood leaves this share of the variation a plane
#: leaves (:func:`crease_variation`; 0.0719 at 30, 60 and 90 deg, sampled on a disk).
QUADRIC_SHARE = 0.072


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


class CloudRegions(NamedTuple):
    """Crease-bounded regions of a cloud (:func:`cloud_regions`)."""

    #: (N,) region id per point, 0 .. R-1 (R >= 2).
    labels: NDArray[np.int64]
    #: Smallest crease angle (degrees) the cloud's noise let the regions tell: the angle
    #: asked for on a clean cloud, more on a noisy one.
    angle: float
    #: Neighbours whose surface variation told the creases.
    neighbours: int
    #: Noise of the points off their surface (standard deviation, point units): the median
    #: distance of a point from its neighbours' quadric / 0.6745 (:func:`surface_noise`).
    noise: float


#: A cloud too noisy to tell creases of the angle asked for tells the sharper ones, up to
#: this angle (degrees), in ``CLOUD_ANGLE_STEP`` steps: the sharp edges of a machined part
#: are mostly right angles (0.2 % noise of the diagonal on 50k points of CAD parts: 35-45
#: deg told at 120 neighbours; half a spacing of noise on a cube: 55).
CLOUD_MAX_ANGLE = 80.0
CLOUD_ANGLE_STEP = 5.0


def _calm_angle(wobble: float, angle: float) -> float | None:
    """Smallest angle from ``angle`` to ``CLOUD_MAX_ANGLE`` (in ``CLOUD_ANGLE_STEP`` steps)
    whose threshold the noise's ``wobble`` (``CLOUD_NOISE_DEVIATIONS`` deviations of the
    median point's noise variation) stays within ``CLOUD_NOISE_SHARE`` of."""
    for a in np.arange(angle, max(angle, CLOUD_MAX_ANGLE) + 1e-9, CLOUD_ANGLE_STEP):
        if wobble <= CLOUD_NOISE_SHARE * CLOUD_SHARE * crease_variation(float(a)):
            return float(a)
    return None


#: Neighbours whose quadric gives :func:`surface_noise`.
NOISE_NEIGHBOURS = 30
#: Points whose quadrics give :func:`surface_noise`.
NOISE_SAMPLE = 20_000


def surface_noise(points: NDArray[np.float64], tree: object, k: int = NOISE_NEIGHBOURS) -> float:
    """Noise of a cloud off its surface (a standard deviation, point units): the median
    distance of a point from the quadric through its ``k`` nearest neighbours (height over
    their plane; a crease's few points barely move a median, and the quadric takes a curved
    surface's sag, which a plane would read as noise) over 0.6745 (the median of |N(0, 1)|),
    from at most ``NOISE_SAMPLE`` points; ``tree`` is a cKDTree of ``points``."""
    pts = np.asarray(points, dtype=float)
    sample = pts[:: max(1, len(pts) // NOISE_SAMPLE)]
    _, idx = tree.query(sample, k=min(k, len(pts)), workers=-1)  # type: ignore[attr-defined]
    near = pts[idx]
    centre = near.mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", near - centre, near - centre))
    local = np.einsum("nki,nij->nkj", near - centre, vectors)  # columns: normal, minor, major
    z, x, y = local[..., 0], local[..., 2], local[..., 1]
    scale = np.sqrt((x * x + y * y).mean(axis=1, keepdims=True)) + 1e-300
    x, y = x / scale, y / scale
    design = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    gram = np.einsum("nki,nkj->nij", design, design) + 1e-10 * np.eye(6)
    coef = np.linalg.solve(gram, np.einsum("nki,nk->ni", design, z)[..., None])[..., 0]
    here = local[:, 0]  # the point itself is its own nearest neighbour
    hx, hy = here[:, 2] / scale[:, 0], here[:, 1] / scale[:, 0]
    row = np.stack([np.ones_like(hx), hx, hy, hx * hx, hx * hy, hy * hy], axis=-1)
    offset = here[:, 0] - np.einsum("ni,ni->n", row, coef)
    return float(np.median(np.abs(offset)) / 0.6745)


def cloud_regions(points: NDArray[np.float64], angle: float, min_points: int
                  ) -> CloudRegions | None:
    """Crease-bounded regions of a cloud without faces; None when it shows no creases or
    is too noisy to tell creases of even ``CLOUD_MAX_ANGLE`` degrees.

    1. Surface variation of each point's nearest neighbours (the smallest share of their
       covariance) less what the cloud's noise adds to it (``sigma^2 / spread``, sigma
       from :func:`surface_noise`), over the fewest of ``CLOUD_NEIGHBOURS`` at which the
       noise's deviation leaves creases of ``angle`` to tell (:func:`_calm_angle`); when
       none does, the crease angle rises, over the most neighbours that tell the smallest:
       a noisy cloud tells only its sharper creases. None when no count tells even
       ``CLOUD_MAX_ANGLE`` or the median point is still rough (a curved cloud).
    2. Points near a crease: that excess variation above ``CLOUD_SHARE`` x
       :func:`crease_variation` of the angle told, and, where the noise's wobble lets it
       tell, their quadric variation above ``QUADRIC_SHARE`` x that (a tight curve sags
       like a crease but fits a quadric).
    3. The other points, joined to their neighbours, fall into connected regions; regions
       of fewer than ``min_points`` points (speckle along a crease) count as crease points.
    4. Crease points take the region whose plane through its nearest points lies nearest
       (:func:`_band_regions`).

    Returns
    -------
    CloudRegions or None
        Region id per point (0 .. R-1, R >= 2), the crease angle told, the neighbour count
        and the noise estimate.
    """
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=float)
    tree = cKDTree(pts)
    k = min(CLOUD_NEIGHBOURS[0], len(pts))
    _, idx = tree.query(pts, k=k, workers=-1)
    sigma = surface_noise(pts, tree)
    variation, spread, quad = _variation(pts, idx)
    # The noise's share sigma^2 / spread falls as 1/k and its deviation as 1/sqrt(k), so its
    # wobble as k^-1.5, while a crease's variation keeps: more neighbours for noisier clouds.
    wobble = CLOUD_NOISE_DEVIATIONS * float(np.median(sigma**2 / spread)) * np.sqrt(2.0 / k)
    told = {n: _calm_angle(wobble * (k / n) ** 1.5, angle) for n in CLOUD_NEIGHBOURS}
    usable = [n for n in CLOUD_NEIGHBOURS if told[n] is not None]
    if not usable:
        return None
    best = next((n for n in usable if told[n] == angle), usable[-1])
    told_angle = float(told[best])  # type: ignore[arg-type]
    moved = best != k
    if moved:
        k = min(best, len(pts))
        _, idx = tree.query(pts, k=k, workers=-1)
    threshold = CLOUD_SHARE * crease_variation(told_angle)
    # A tight curve (a bolt hole's wall, 8 spacings round) sags like a crease; the quadric
    # takes the sag but not a crease's kink, where the noise lets it tell.
    quadric = wobble * (CLOUD_NEIGHBOURS[0] / k) ** 1.5 <= QUADRIC_SHARE * threshold
    if moved or quadric:
        variation, spread, quad = _variation(pts, idx, quadric)
    excess = variation - sigma**2 / np.maximum(spread, 1e-300)
    if np.median(excess) > CLOUD_NOISE_SHARE * threshold:
        return None
    flat = excess <= threshold
    if quad is not None:
        noise = sigma**2 * (k - 6) / k / np.maximum(spread, 1e-300)
        flat |= quad - noise <= QUADRIC_SHARE * threshold
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
    region = region.copy()
    region[~kept] = _band_regions(pts[~kept], pts[kept], region[kept], k)
    _, out = np.unique(region, return_inverse=True)
    return CloudRegions(out.astype(np.int64), told_angle, k, sigma)


def _band_regions(band: NDArray[np.float64], region_points: NDArray[np.float64],
                  region: NDArray[np.int64], k: int) -> NDArray[np.int64]:
    """Region of each crease-band point: of the (up to ``BAND_CANDIDATES``) regions among
    its ``k`` nearest region points, the one whose plane through its own of them (at least
    ``BAND_MIN_POINTS``) passes nearest; the nearest region point's region where none has
    that many. A crease lies where the two faces' surfaces meet, not halfway between the
    region points: on a noisy cloud those stop at ragged distances from it (speckle), and
    the band's border followed the rags (3 corners on a border, a segment refused).

    Returns
    -------
    (B,) int
        Region per band point.
    """
    from scipy.spatial import cKDTree

    k = min(k, len(region_points))
    out = np.empty(len(band), dtype=np.int64)
    step = max(1, CHUNK_VALUES // k)
    tree = cKDTree(region_points)
    for start in range(0, len(band), step):
        q = band[start : start + step]
        _, idx = tree.query(q, k=k, workers=-1)
        idx = idx.reshape(len(q), k)
        labels, near = region[idx], region_points[idx]
        best, best_d = labels[:, 0].copy(), np.full(len(q), np.inf)
        taken = np.zeros_like(labels, dtype=bool)
        for _ in range(BAND_CANDIDATES):
            first = np.argmax(~taken, axis=1)
            cand = labels[np.arange(len(q)), first]
            own = (labels == cand[:, None]) & ~taken
            taken |= own
            d = _plane_distance(q, near, own)
            better = (own.sum(axis=1) >= BAND_MIN_POINTS) & (d < best_d)
            best = np.where(better, cand, best)
            best_d = np.where(better, d, best_d)
        out[start : start + step] = best
    return out


#: Regions a crease-band point chooses among (three faces meet at a box's corner).
BAND_CANDIDATES = 3
#: Fewest of a region's points that give it a plane for :func:`_band_regions`.
BAND_MIN_POINTS = 6


def _plane_distance(q: NDArray[np.float64], near: NDArray[np.float64],
                    mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Distance of each ``q`` from the plane through its ``near`` points where ``mask``
    (least squares: the smallest principal axis of their covariance)."""
    w = mask.astype(float)
    count = np.maximum(w.sum(axis=1), 1.0)
    centre = np.einsum("nk,nki->ni", w, near) / count[:, None]
    hood = (near - centre[:, None]) * w[..., None]
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", hood, hood))
    return np.abs(np.einsum("ni,ni->n", q - centre, vectors[:, :, 0]))

