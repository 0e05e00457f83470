"""Labelled sample clouds of analytic shapes, with the exact distance to the true surface.

Used by the bundled examples, the tests and the benchmarks: each generator samples points
uniformly by area (or on a parameter grid), labels them by patch, optionally adds Gaussian
noise, and returns a :class:`LabelledCloud` whose ``distance`` gives the unsigned distance of
any points to the true surface, so a reconstruction's error can be measured against the truth
rather than against the noisy samples.

Shapes (every segment is 4-sided):

* :func:`sphere6` -- unit sphere as six patches (cube-sphere), corners where three meet.
* :func:`torus` -- ring torus as a 4 x 4 grid of patches, every corner joins four.
* :func:`cylinder` -- open tube, 4 patches around x 2 along the axis.
* :func:`pot` -- a bulging surface of revolution, 4 x 2 patches, closed by a flat bottom.
* :func:`sheet` -- a curved open sheet split 2 x 2.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.errors import InputError

Distance = Callable[[NDArray[np.float64]], NDArray[np.float64]]


@dataclass(frozen=True)
class LabelledCloud:
    """A labelled cloud and its true surface.

    Attributes
    ----------
    name : str
    points : (N, 3) float
    labels : (N,) int
    distance : callable
        ``distance(q)`` for ``q`` of shape (K, 3): unsigned distance to the true surface, (K,).
    closed : bool
        Whether the true surface is closed (encloses a volume).
    volume : float or None
        Enclosed volume of a closed shape.
    """

    name: str
    points: NDArray[np.float64]
    labels: NDArray[np.int64]
    distance: Distance
    closed: bool
    volume: float | None = None

    @property
    def diagonal(self) -> float:
        """Bounding-box diagonal of the points."""
        return float(np.linalg.norm(self.points.max(axis=0) - self.points.min(axis=0)))


def _check(n_points: int, noise: float) -> None:
    if int(n_points) < 100:
        raise InputError(f"n_points must be at least 100, got {n_points}")
    if not (np.isfinite(noise) and noise >= 0):
        raise InputError(f"noise must be a number >= 0 (fraction of the diagonal), got {noise}")


def _finish(
    name: str,
    pts: NDArray[np.float64],
    labels: NDArray[np.int64],
    distance: Distance,
    noise: float,
    rng: np.random.Generator,
    closed: bool,
    volume: float | None = None,
) -> LabelledCloud:
    if noise > 0:
        diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        pts = pts + rng.normal(scale=noise * diagonal, size=pts.shape)
    return LabelledCloud(name, pts, labels.astype(np.int64), distance, closed, volume)


def _accept(
    rng: np.random.Generator, count: int, draw: Callable[[int], NDArray[np.float64]],
    weight: Callable[[NDArray[np.float64]], NDArray[np.float64]], bound: float,
) -> NDArray[np.float64]:
    """``count`` parameter samples with density proportional to ``weight`` (rejection)."""
    out: list[NDArray[np.float64]] = []
    have = 0
    while have < count:
        cand = draw(2 * (count - have) + 64)
        cand = cand[rng.random(len(cand)) * bound < weight(cand)]
        out.append(cand)
        have += len(cand)
    return np.vstack(out)[:count]


def sphere6(n_points: int = 20000, noise: float = 0.0, seed: int = 0) -> LabelledCloud:
    """Unit sphere split into six 4-sided patches by the faces of the enclosing cube.

    Corners (the cube's vertex directions) join three patches.
    """
    _check(n_points, noise)
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(int(n_points), 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    axis = np.abs(pts).argmax(axis=1)
    labels = 2 * axis + (pts[np.arange(len(pts)), axis] > 0)

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.abs(np.linalg.norm(np.asarray(q, float), axis=1) - 1.0)

    return _finish("sphere6", pts, labels, distance, noise, rng, True, 4.0 / 3.0 * np.pi)


def torus(
    n_points: int = 30000, noise: float = 0.0, seed: int = 0, major: float = 1.0,
    minor: float = 0.35, split: tuple[int, int] = (4, 4),
) -> LabelledCloud:
    """Ring torus as a ``split[0] x split[1]`` grid of patches (around the axis x around the tube).

    Every corner joins four patches.
    """
    _check(n_points, noise)
    if not 0 < minor < major:
        raise InputError(f"need 0 < minor < major, got minor={minor}, major={major}")
    rng = np.random.default_rng(seed)
    uv = _accept(
        rng, int(n_points), lambda k: rng.random((k, 2)) * 2 * np.pi,
        lambda c: major + minor * np.cos(c[:, 1]), major + minor,
    )
    u, v = uv[:, 0], uv[:, 1]
    ring = major + minor * np.cos(v)
    pts = np.column_stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(v)])
    # Shift the tube split by half a patch so no seam runs along the flat top circle.
    iu = np.floor(u / (2 * np.pi) * split[0]).astype(np.int64) % split[0]
    iv = np.floor((v / (2 * np.pi) + 0.5 / split[1]) * split[1]).astype(np.int64) % split[1]

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, float)
        rho = np.hypot(q[:, 0], q[:, 1])
        return np.abs(np.hypot(rho - major, q[:, 2]) - minor)

    return _finish(
        "torus", pts, iu * split[1] + iv, distance, noise, rng, True,
        2 * np.pi**2 * major * minor**2,
    )


def cylinder(
    n_points: int = 20000, noise: float = 0.0, seed: int = 0, radius: float = 1.0,
    height: float = 2.0, split: tuple[int, int] = (4, 2),
) -> LabelledCloud:
    """Open circular tube, ``split[0]`` patches around x ``split[1]`` along the axis."""
    _check(n_points, noise)
    rng = np.random.default_rng(seed)
    u = rng.random(int(n_points)) * 2 * np.pi
    z = rng.random(int(n_points)) * height
    pts = np.column_stack([radius * np.cos(u), radius * np.sin(u), z])
    iu = np.floor(u / (2 * np.pi) * split[0]).astype(np.int64) % split[0]
    iz = np.minimum((z / height * split[1]).astype(np.int64), split[1] - 1)

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, float)
        return np.abs(np.hypot(q[:, 0], q[:, 1]) - radius)

    return _finish("cylinder", pts, iu * split[1] + iz, distance, noise, rng, False)


def _pot_profile(z: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.8 + 0.3 * np.sin(np.pi * z / 1.2) - 0.1 * z


def pot(n_points: int = 30000, noise: float = 0.0, seed: int = 0) -> LabelledCloud:
    """A pot: bulging wall of revolution (4 around x 2 up, open top) on a flat round bottom.

    The bottom is one 4-sided patch whose corners are where the wall seams reach it.
    """
    _check(n_points, noise)
    rng = np.random.default_rng(seed)
    height = 1.6
    zs = np.linspace(0.0, height, 4001)
    rs = _pot_profile(zs)
    slope = np.gradient(rs, zs)
    ring = 2 * np.pi * rs * np.sqrt(1 + slope**2)
    wall_area = float(((ring[1:] + ring[:-1]) / 2 * np.diff(zs)).sum())
    r0 = float(_pot_profile(np.zeros(1))[0])
    bottom_area = np.pi * r0**2
    n_bottom = int(round(n_points * bottom_area / (wall_area + bottom_area)))
    n_wall = int(n_points) - n_bottom
    bound = float((rs * np.sqrt(1 + slope**2)).max())

    def weight(c: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.interp(c[:, 1], zs, rs * np.sqrt(1 + slope**2))

    tz = _accept(
        rng, n_wall, lambda k: rng.random((k, 2)) * [2 * np.pi, height], weight, bound
    )
    r = _pot_profile(tz[:, 1])
    wall = np.column_stack([r * np.cos(tz[:, 0]), r * np.sin(tz[:, 0]), tz[:, 1]])
    iu = np.floor(tz[:, 0] / (2 * np.pi) * 4).astype(np.int64) % 4
    iz = np.minimum((tz[:, 1] / height * 2).astype(np.int64), 1)
    rho = r0 * np.sqrt(rng.random(n_bottom))
    phi = rng.random(n_bottom) * 2 * np.pi
    bottom = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), np.zeros(n_bottom)])
    pts = np.vstack([wall, bottom])
    labels = np.r_[iu * 2 + iz, np.full(n_bottom, 8)]
    # Profile sampled every 4e-4: the chord sag is far below any error worth measuring.
    profile = cKDTree(np.column_stack([rs, zs]))

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, float)
        rq = np.hypot(q[:, 0], q[:, 1])
        d_wall, _ = profile.query(np.column_stack([rq, q[:, 2]]))
        d_bottom = np.where(rq <= r0, np.abs(q[:, 2]), np.hypot(rq - r0, q[:, 2]))
        return np.minimum(d_wall, d_bottom)

    return _finish("pot", pts, labels, distance, noise, rng, False)


def sheet(n_points: int = 20000, noise: float = 0.0, seed: int = 0) -> LabelledCloud:
    """z = 0.1 sin(x) sin(y) over [0, 2]^2, split 2 x 2 at x = 1, y = 1 (random samples)."""
    _check(n_points, noise)
    rng = np.random.default_rng(seed)
    xy = rng.random((int(n_points), 2)) * 2.0
    pts = np.column_stack([xy, 0.1 * np.sin(xy[:, 0]) * np.sin(xy[:, 1])])
    labels = (xy[:, 0] > 1.0).astype(np.int64) + 2 * (xy[:, 1] > 1.0)

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        # First-order distance |f - z| / |grad(f - z)|: exact to O(d^2 x curvature).
        q = np.asarray(q, float)
        x, y = q[:, 0], q[:, 1]
        fx, fy = 0.1 * np.cos(x) * np.sin(y), 0.1 * np.sin(x) * np.cos(y)
        return np.abs(q[:, 2] - 0.1 * np.sin(x) * np.sin(y)) / np.sqrt(1 + fx**2 + fy**2)

    return _finish("sheet", pts, labels, distance, noise, rng, False)


SHAPES: dict[str, Callable[..., LabelledCloud]] = {
    "sphere6": sphere6,
    "torus": torus,
    "cylinder": cylinder,
    "pot": pot,
    "sheet": sheet,
}

__all__ = ["SHAPES", "LabelledCloud", "cylinder", "pot", "sheet", "sphere6", "torus"]
