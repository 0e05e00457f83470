"""Point-set parameterizations for curve fitting (thesis Section 2.1).

Each function maps ordered points ``(n, D)`` to increasing parameters ``(n,)`` with
``t[0] = 0`` and ``t[-1] = 1``. :data:`METHODS` lists them in the order the fitter tries them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray


def _normalize(steps: NDArray[np.float64]) -> NDArray[np.float64]:
    t = np.concatenate([[0.0], np.cumsum(steps)])
    total = t[-1]
    if not np.isfinite(total) or total <= 0.0:
        return np.linspace(0.0, 1.0, len(t))
    return t / total


def uniform(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Equally spaced parameters."""
    return np.linspace(0.0, 1.0, len(points))


def chord(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Chord-length parameters (cumulative distance)."""
    return _normalize(np.linalg.norm(np.diff(points, axis=0), axis=1))


def centripetal(points: NDArray[np.float64], alpha: float = 0.5) -> NDArray[np.float64]:
    """Centripetal parameters: cumulative distance to the power ``alpha`` (Lee 1989)."""
    return _normalize(np.linalg.norm(np.diff(points, axis=0), axis=1) ** alpha)


def foley(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Foley-Nielson parameters: chord lengths enlarged where the polygon turns sharply.

    ``delta_i = d_i * (1 + 1.5 * theta_i d_{i-1} / (d_{i-1} + d_i)
    + 1.5 * theta_{i+1} d_{i+1} / (d_i + d_{i+1}))`` with ``theta`` the exterior angle at a
    vertex, capped at pi/2 (Foley and Nielson 1989).
    """
    d = np.linalg.norm(np.diff(points, axis=0), axis=1)
    if len(d) < 2:
        return chord(points)
    v = np.diff(points, axis=0)
    safe = np.where(d > 0, d, 1.0)[:, None]
    u = v / safe
    cos = np.clip(np.sum(u[:-1] * u[1:], axis=1), -1.0, 1.0)
    theta = np.minimum(np.arccos(cos), np.pi / 2)  # exterior angle at interior vertices
    theta_full = np.concatenate([[0.0], theta, [0.0]])  # at vertices 0..n-1
    d_prev = np.concatenate([[0.0], d[:-1]])
    d_next = np.concatenate([d[1:], [0.0]])
    with np.errstate(invalid="ignore", divide="ignore"):
        left = np.where(d_prev + d > 0, theta_full[:-1] * d_prev / (d_prev + d), 0.0)
        right = np.where(d + d_next > 0, theta_full[1:] * d_next / (d + d_next), 0.0)
    return _normalize(d * (1.0 + 1.5 * left + 1.5 * right))


METHODS: dict[str, Callable[[NDArray[np.float64]], NDArray[np.float64]]] = {
    "chord": chord,
    "centripetal": centripetal,
    "uniform": uniform,
    "foley": foley,
}
