"""Corner points of pixel-boundary loops.

A pixel staircase turns by 90 degrees at almost every vertex, so corners are measured at a
scale: the turning angle between the chords to the points ``k`` steps back and ahead. A
true corner turns as much at scale ``k`` as at ``2k`` (its sides are straight), while a
smooth bend of radius r turns twice as much at ``2k`` (about 2k/r); that ratio separates
corners from tight curves without a curvature threshold that depends on the image size.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# Defaults: turning at least 50 degrees at scale k = 4 px, concentrated (>= 0.7 of the
# turning at 2k). Pixel noise turns at most 2*atan(1/4) = 28 degrees at k = 4.
CORNER_ANGLE = 50.0
CORNER_SCALE = 4
CONCENTRATION = 0.7


def turning_angle(points: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """Turning angle in degrees at every vertex of a closed polygon, between the chords to
    the vertices ``k`` steps back and ``k`` ahead (0 = straight, 180 = folds back)."""
    a = points - np.roll(points, k, axis=0)
    b = np.roll(points, -k, axis=0) - points
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    dot = np.sum(a * b, axis=1)
    return np.degrees(np.abs(np.arctan2(cross, dot)))


def detect_corners(
    points: NDArray[np.float64],
    *,
    angle: float = CORNER_ANGLE,
    scale: int = CORNER_SCALE,
) -> NDArray[np.int64]:
    """Indices of the corners of a closed pixel-boundary loop, increasing.

    Parameters
    ----------
    points : (n, 2) float
        Loop vertices (unit steps), closed implicitly.
    angle : float
        Minimum turning angle in degrees at scale ``scale``.
    scale : int
        Chord length in vertices (pixels) over which the turn is measured.

    Returns
    -------
    (c,) int
    """
    n = len(points)
    k = int(min(scale, max(1, n // 6)))
    if n < 8:
        return np.arange(0)
    theta = turning_angle(points, k)
    theta2 = turning_angle(points, min(2 * k, max(1, n // 3)))
    candidate = (theta >= angle) & (theta >= CONCENTRATION * theta2)
    # Non-maximum suppression over +-k (cyclic); prefer the sharpest fine-scale turn.
    fine = turning_angle(points, max(1, k // 2))
    score = theta + 1e-3 * fine
    local_max = score >= _cyclic_max(score, k)
    idx = np.flatnonzero(candidate & local_max)
    if len(idx) > 1:
        # Plateaus give neighbouring equal maxima: keep the first of each run within k.
        gaps = np.diff(np.r_[idx, idx[0] + n])
        keep = np.r_[True, gaps[:-1] > k]
        if gaps[-1] <= k and len(idx) > 1:
            keep[0] = False if keep[1:].any() else True
        idx = idx[keep]
    return idx.astype(np.int64)


def _cyclic_max(values: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """Maximum over the cyclic window ``i - k .. i + k`` at every index (k is small)."""
    out = values.copy()
    for shift in range(1, k + 1):
        np.maximum(out, np.roll(values, shift), out=out)
        np.maximum(out, np.roll(values, -shift), out=out)
    return out
