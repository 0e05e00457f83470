"""Principal curvatures of a sampled surface from local quadric fits (numpy/scipy only).

The automatic layout sizes its patches by how strongly the surface bends. Measured on a
mesh's edges (dihedral angle over centroid distance), the curvature of a marching-cubes
mesh (open3d Poisson) reads 4x too high on a clean unit sphere and 25x on 0.2 % noise,
because its faceting and wrinkles are at the scale of one triangle. Here the curvature is
measured at the scale of a neighbourhood of ``NEIGHBOURS`` points of a subsample of
``CLOUD_SUBSAMPLE`` points: a fixed fraction of the surface (about 1/30 of its square root
across), whatever the density or size of the input, so noise averages out and the answer
is in the units of the points.

1. :func:`principal_curvatures`: per centre, its neighbours in the subsample, a local frame
   from their principal axes, a least-squares quadric height ``h = a u^2 + b uv + c v^2 +
   d u + e v + f`` (batched normal equations), curvatures from the Hessian.
2. :func:`curvature_radius_of_points`: a robust smallest radius of curvature (a high
   percentile of the larger principal curvature).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

#: Points the neighbourhoods are taken from (every k-th point of the cloud).
CLOUD_SUBSAMPLE = 20_000
#: Neighbours per quadric fit.
NEIGHBOURS = 128
#: Centres at which the curvature is measured.
CENTRES = 4000
#: A quadric fit whose RMS residual exceeds this multiple of the median one straddles a
#: crease or a gap (no smooth surface there): its curvature is left out.
RESIDUAL_FACTOR = 3.0


def principal_curvatures(
    points: NDArray[np.float64], centres: int = CENTRES, neighbours: int = NEIGHBOURS
) -> NDArray[np.float64]:
    """Principal curvatures at about ``centres`` points of a cloud.

    Parameters
    ----------
    points : (N, 3) float
        Points on a surface (N > ``neighbours``).
    centres : int
        How many points (spread evenly through the array) to measure at.
    neighbours : int
        Points per local quadric fit.

    Returns
    -------
    (M, 2) float
        ``|kappa_1| >= |kappa_2|`` per smooth centre, signed, in 1 / (units of ``points``).

    Notes
    -----
    1. Subsample to ``CLOUD_SUBSAMPLE`` points; neighbours from one KD-tree query.
    2. Frame per centre: eigenvectors of the neighbours' covariance (normal = smallest).
    3. Quadric height over the tangent plane by least squares; the shape operator at the
       foot is ``[[2a, b], [b, 2c]] / (1 + d^2 + e^2)^(3/2)`` (the slope terms are small
       in the principal-axis frame), its eigenvalues are the curvatures.
    4. Centres whose fit residual is above ``RESIDUAL_FACTOR`` x the median (a crease or a
       border in the neighbourhood) are left out: creases become patch borders, they do
       not size the patches.
    """
    cloud = points[:: max(1, len(points) // CLOUD_SUBSAMPLE)]
    k = int(min(neighbours, len(cloud)))
    at = cloud[:: max(1, len(cloud) // centres)]
    _, idx = cKDTree(cloud).query(at, k=k, workers=-1)
    nb = cloud[idx]  # (M, k, 3)
    nb = nb - nb.mean(axis=1, keepdims=True)
    _, axes = np.linalg.eigh(np.einsum("mki,mkj->mij", nb, nb))
    local = np.einsum("mki,mij->mkj", nb, axes)  # columns: normal, minor, major axis
    # Fit in units of the neighbourhood's size, so the solve is equally conditioned at
    # any scale; curvatures scale back by 1 / size.
    size = np.sqrt(np.mean(np.sum(local**2, axis=2), axis=1))[:, None, None]
    local = local / size
    h, u, v = local[..., 0], local[..., 1], local[..., 2]
    design = np.stack([u * u, u * v, v * v, u, v, np.ones_like(u)], axis=-1)  # (M, k, 6)
    normal_eq = np.einsum("mki,mkj->mij", design, design)
    rhs = np.einsum("mki,mk->mi", design, h)
    coef = np.linalg.solve(normal_eq + 1e-12 * np.eye(6), rhs[..., None])[..., 0]
    residual = np.sqrt(np.mean((np.einsum("mkj,mj->mk", design, coef) - h) ** 2, axis=1))
    smooth = residual <= RESIDUAL_FACTOR * np.median(residual)
    coef, size = coef[smooth], size[smooth]
    a, b, c, d, e = (coef[:, j] for j in range(5))
    scale = (1.0 + d * d + e * e) ** 1.5
    hess = np.stack([np.stack([2 * a, b], -1), np.stack([b, 2 * c], -1)], -2)
    hess = hess / (scale[:, None, None] * size)
    kappa = np.linalg.eigvalsh(hess)
    order = np.argsort(-np.abs(kappa), axis=1)
    return np.take_along_axis(kappa, order, axis=1)


def curvature_radius_of_points(points: NDArray[np.float64], percentile: float = 90.0) -> float:
    """A small radius of curvature of a sampled surface (units of ``points``).

    The ``percentile`` of the larger principal curvature's magnitude over the centres of
    :func:`principal_curvatures`, inverted (a robust smallest radius); ``inf`` for a plane.
    """
    kappa = float(np.percentile(np.abs(principal_curvatures(points)[:, 0]), percentile))
    return 1.0 / kappa if kappa > 0 else float("inf")
