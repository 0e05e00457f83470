"""Distance from points to a set of cubic Bézier curves (any dimension)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.curves import bezier


def points_to_curves(
    points: NDArray[np.float64],
    curves: NDArray[np.float64],
    samples: int = 64,
    newton: int = 4,
    candidates: int = 3,
) -> NDArray[np.float64]:
    """Distance from each point to the nearest point on any of the curves.

    Dense samples and a KD-tree give each point its nearest curve and parameter; a few
    clamped Newton steps on that curve then refine the foot point.

    Parameters
    ----------
    points : (n, D) float
    curves : (K, 4, D) float

    Returns
    -------
    (n,) float
    """
    pts = np.asarray(points, dtype=float)
    cv = np.asarray(curves, dtype=float)
    if len(cv) == 0 or len(pts) == 0:
        return np.full(len(pts), np.inf)
    t = np.linspace(0.0, 1.0, samples)
    dense = bezier.evaluate(cv, t).reshape(-1, pts.shape[1])
    # Several candidates: the nearest sample may sit at the end of one curve while the foot
    # point lies on its neighbour.
    cand = min(candidates, len(dense))
    coarse, idx = cKDTree(dense).query(pts, k=cand)
    coarse = coarse.reshape(len(pts), cand)
    idx = idx.reshape(len(pts), cand)
    best = coarse.min(axis=1)
    rep = np.repeat(pts, cand, axis=0)
    flat = idx.ravel()
    ctrl = cv[flat // samples]  # (n*cand, 4, D)
    tt = t[flat % samples]
    d1c = 3.0 * np.diff(ctrl, axis=1)
    d2c = 6.0 * np.diff(ctrl, n=2, axis=1)
    for _ in range(newton):
        s = 1.0 - tt
        p = np.einsum("nk,nkd->nd", bezier.bernstein(tt), ctrl)
        d1 = np.einsum("nk,nkd->nd", np.stack([s * s, 2 * tt * s, tt * tt], 1), d1c)
        d2 = np.einsum("nk,nkd->nd", np.stack([s, tt], 1), d2c)
        diff = p - rep
        num = np.sum(diff * d1, axis=1)
        den = np.sum(d1 * d1, axis=1) + np.sum(diff * d2, axis=1)
        step = np.divide(num, den, out=np.zeros_like(num), where=den > 1e-12)
        tt = np.clip(tt - step, 0.0, 1.0)
    p = np.einsum("nk,nkd->nd", bezier.bernstein(tt), ctrl)
    refined = np.linalg.norm(p - rep, axis=1).reshape(len(pts), cand).min(axis=1)
    return np.minimum(refined, best)
