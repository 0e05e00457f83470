"""Labelled sample clouds of analytic shapes, with the exact distance to the true surface.

Used by the bundled examples, the tests and the benchmarks: each generator samples points
uniformly by area (or on a parameter grid), labels them by patch, optionally adds Gaussian
noise, and returns a :class:`LabelledCloud` whose ``distance`` gives the unsigned distance of
any points to the true surface, so a reconstruction's error can be measured against the truth
rather than against the noisy samples.

Shapes (every segment is 4-sided, except the teapot's collapsed lid and bottom patches):

* :func:`sphere6` -- unit sphere as six patches (cube-sphere), corners where three meet.
* :func:`ellipsoid6` -- the same split on an ellipsoid (curvature varies along every edge).
* :func:`torus` -- ring torus as a 4 x 4 grid of patches, every corner joins four.
* :func:`cylinder` -- open tube, 4 patches around x 2 along the axis.
* :func:`can` -- closed cylinder: 4 wall patches and two round caps (90-degree crease rims).
* :func:`pot` -- a bulging surface of revolution, 4 x 2 patches, closed by a flat bottom.
* :func:`sheet` -- a curved open sheet split 2 x 2.
* :func:`teapot` -- Newell's Utah teapot, one label per bicubic Bezier patch (by default rim,
  body, lid and bottom: 24 patches, 8 of them 3-sided with a collapsed side; open).
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


def ellipsoid6(
    n_points: int = 20000, noise: float = 0.0, seed: int = 0,
    axes: tuple[float, float, float] = (1.5, 1.0, 0.7),
) -> LabelledCloud:
    """Ellipsoid with semi-axes ``axes``, split into six patches like :func:`sphere6` (the
    cube-sphere split, stretched), uniform by area. Three patches meet at every corner and
    the curvature differs along every edge.

    ``distance`` is the first-order distance ``|F| / |grad F|`` of
    ``F = sum (x_i / a_i)^2 - 1`` (halved): exact on the surface, off by ``O(d^2)`` a
    distance ``d`` away (below 1e-7 of the diagonal at d = 1e-4 of it for these axes).
    """
    _check(n_points, noise)
    rng = np.random.default_rng(seed)
    scale = np.asarray(axes, dtype=float)
    if scale.shape != (3,) or not np.all(np.isfinite(scale)) or np.any(scale <= 0):
        raise InputError(f"axes must be three positive numbers, got {axes}")

    def draw(k: int) -> NDArray[np.float64]:
        unit = rng.normal(size=(k, 3))
        return unit / np.linalg.norm(unit, axis=1, keepdims=True)

    def stretch(unit: NDArray[np.float64]) -> NDArray[np.float64]:
        # Area element of x -> diag(axes) x on the unit sphere: det(S) |S^-1 n|.
        return np.linalg.norm(unit / scale, axis=1)

    unit = _accept(rng, int(n_points), draw, stretch, float((1.0 / scale).max()))
    axis = np.abs(unit).argmax(axis=1)
    labels = 2 * axis + (unit[np.arange(len(unit)), axis] > 0)

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, float)
        f = ((q / scale) ** 2).sum(axis=1) - 1.0
        return np.abs(f) / (2.0 * np.linalg.norm(q / scale**2, axis=1))

    return _finish(
        "ellipsoid6", unit * scale, labels, distance, noise, rng, True,
        4.0 / 3.0 * np.pi * float(np.prod(scale)),
    )


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


def can(
    n_points: int = 20000, noise: float = 0.0, seed: int = 0, radius: float = 1.0,
    height: float = 2.0,
) -> LabelledCloud:
    """Closed cylinder (a can): 4 wall patches and two flat round caps, one patch each.

    The rims are 90-degree creases; each cap's four corners (where the wall seams reach it)
    are straight angles, so the caps are 4-sided patches with degenerate corners.
    """
    _check(n_points, noise)
    rng = np.random.default_rng(seed)
    wall_area, cap_area = 2 * np.pi * radius * height, np.pi * radius**2
    n_wall = int(round(n_points * wall_area / (wall_area + 2 * cap_area)))
    n_cap = (int(n_points) - n_wall) // 2
    u = rng.random(n_wall) * 2 * np.pi
    z = rng.random(n_wall) * height
    wall = np.column_stack([radius * np.cos(u), radius * np.sin(u), z])
    labels = [np.floor(u / (np.pi / 2)).astype(np.int64) % 4]
    parts = [wall]
    for k, level in enumerate((0.0, height)):
        r = radius * np.sqrt(rng.random(n_cap))
        phi = rng.random(n_cap) * 2 * np.pi
        parts.append(np.column_stack([r * np.cos(phi), r * np.sin(phi), np.full(n_cap, level)]))
        labels.append(np.full(n_cap, 4 + k, dtype=np.int64))

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, float)
        rq, zq = np.hypot(q[:, 0], q[:, 1]), q[:, 2]
        above = np.maximum(np.maximum(-zq, zq - height), 0.0)
        d_wall = np.hypot(rq - radius, above)
        d_caps = [np.hypot(np.maximum(rq - radius, 0.0), zq - level) for level in (0.0, height)]
        return np.minimum(d_wall, np.minimum(*d_caps))

    return _finish(
        "can", np.vstack(parts), np.concatenate(labels), distance, noise, rng, True,
        np.pi * radius**2 * height,
    )


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


# Newell's teapot: 32 bicubic Bezier patches (rows of 16 one-based indices, 4 x 4 in row order)
# into 306 control points (x y z, z up), in the original order -- except the last two points,
# 305 and 306, which the common copy lists swapped (a kinked control row in the last bottom
# patch); here they are in the order of the other three bottom quarters. Points 205, 206, 216
# and 223 are unused, as in the original.
_TEAPOT_PATCHES = """
1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16
4 17 18 19 8 20 21 22 12 23 24 25 16 26 27 28
19 29 30 31 22 32 33 34 25 35 36 37 28 38 39 40
31 41 42 1 34 43 44 5 37 45 46 9 40 47 48 13
13 14 15 16 49 50 51 52 53 54 55 56 57 58 59 60
16 26 27 28 52 61 62 63 56 64 65 66 60 67 68 69
28 38 39 40 63 70 71 72 66 73 74 75 69 76 77 78
40 47 48 13 72 79 80 49 75 81 82 53 78 83 84 57
57 58 59 60 85 86 87 88 89 90 91 92 93 94 95 96
60 67 68 69 88 97 98 99 92 100 101 102 96 103 104 105
69 76 77 78 99 106 107 108 102 109 110 111 105 112 113 114
78 83 84 57 108 115 116 85 111 117 118 89 114 119 120 93
121 122 123 124 125 126 127 128 129 130 131 132 133 134 135 136
124 137 138 121 128 139 140 125 132 141 142 129 136 143 144 133
133 134 135 136 145 146 147 148 149 150 151 152 69 153 154 155
136 143 144 133 148 156 157 145 152 158 159 149 155 160 161 69
162 163 164 165 166 167 168 169 170 171 172 173 174 175 176 177
165 178 179 162 169 180 181 166 173 182 183 170 177 184 185 174
174 175 176 177 186 187 188 189 190 191 192 193 194 195 196 197
177 184 185 174 189 198 199 186 193 200 201 190 197 202 203 194
204 204 204 204 207 208 209 210 211 211 211 211 212 213 214 215
204 204 204 204 210 217 218 219 211 211 211 211 215 220 221 222
204 204 204 204 219 224 225 226 211 211 211 211 222 227 228 229
204 204 204 204 226 230 231 207 211 211 211 211 229 232 233 212
212 213 214 215 234 235 236 237 238 239 240 241 242 243 244 245
215 220 221 222 237 246 247 248 241 249 250 251 245 252 253 254
222 227 228 229 248 255 256 257 251 258 259 260 254 261 262 263
229 232 233 212 257 264 265 234 260 266 267 238 263 268 269 242
270 270 270 270 279 280 281 282 275 276 277 278 271 272 273 274
270 270 270 270 282 289 290 291 278 286 287 288 274 283 284 285
270 270 270 270 291 298 299 300 288 295 296 297 285 292 293 294
270 270 270 270 300 305 306 279 297 303 304 275 294 301 302 271
"""

_TEAPOT_VERTICES = """
1.4 0 2.4  1.4 -0.784 2.4  0.784 -1.4 2.4  0 -1.4 2.4
1.3375 0 2.53125  1.3375 -0.749 2.53125  0.749 -1.3375 2.53125  0 -1.3375 2.53125
1.4375 0 2.53125  1.4375 -0.805 2.53125  0.805 -1.4375 2.53125  0 -1.4375 2.53125
1.5 0 2.4  1.5 -0.84 2.4  0.84 -1.5 2.4  0 -1.5 2.4
-0.784 -1.4 2.4  -1.4 -0.784 2.4  -1.4 0 2.4
-0.749 -1.3375 2.53125  -1.3375 -0.749 2.53125  -1.3375 0 2.53125
-0.805 -1.4375 2.53125  -1.4375 -0.805 2.53125  -1.4375 0 2.53125
-0.84 -1.5 2.4  -1.5 -0.84 2.4  -1.5 0 2.4
-1.4 0.784 2.4  -0.784 1.4 2.4  0 1.4 2.4
-1.3375 0.749 2.53125  -0.749 1.3375 2.53125  0 1.3375 2.53125
-1.4375 0.805 2.53125  -0.805 1.4375 2.53125  0 1.4375 2.53125
-1.5 0.84 2.4  -0.84 1.5 2.4  0 1.5 2.4
0.784 1.4 2.4  1.4 0.784 2.4
0.749 1.3375 2.53125  1.3375 0.749 2.53125
0.805 1.4375 2.53125  1.4375 0.805 2.53125
0.84 1.5 2.4  1.5 0.84 2.4
1.75 0 1.875  1.75 -0.98 1.875  0.98 -1.75 1.875  0 -1.75 1.875
2 0 1.35  2 -1.12 1.35  1.12 -2 1.35  0 -2 1.35
2 0 0.9  2 -1.12 0.9  1.12 -2 0.9  0 -2 0.9
-0.98 -1.75 1.875  -1.75 -0.98 1.875  -1.75 0 1.875
-1.12 -2 1.35  -2 -1.12 1.35  -2 0 1.35
-1.12 -2 0.9  -2 -1.12 0.9  -2 0 0.9
-1.75 0.98 1.875  -0.98 1.75 1.875  0 1.75 1.875
-2 1.12 1.35  -1.12 2 1.35  0 2 1.35
-2 1.12 0.9  -1.12 2 0.9  0 2 0.9
0.98 1.75 1.875  1.75 0.98 1.875
1.12 2 1.35  2 1.12 1.35
1.12 2 0.9  2 1.12 0.9
2 0 0.45  2 -1.12 0.45  1.12 -2 0.45  0 -2 0.45
1.5 0 0.225  1.5 -0.84 0.225  0.84 -1.5 0.225  0 -1.5 0.225
1.5 0 0.15  1.5 -0.84 0.15  0.84 -1.5 0.15  0 -1.5 0.15
-1.12 -2 0.45  -2 -1.12 0.45  -2 0 0.45
-0.84 -1.5 0.225  -1.5 -0.84 0.225  -1.5 0 0.225
-0.84 -1.5 0.15  -1.5 -0.84 0.15  -1.5 0 0.15
-2 1.12 0.45  -1.12 2 0.45  0 2 0.45
-1.5 0.84 0.225  -0.84 1.5 0.225  0 1.5 0.225
-1.5 0.84 0.15  -0.84 1.5 0.15  0 1.5 0.15
1.12 2 0.45  2 1.12 0.45
0.84 1.5 0.225  1.5 0.84 0.225
0.84 1.5 0.15  1.5 0.84 0.15
-1.6 0 2.025  -1.6 -0.3 2.025  -1.5 -0.3 2.25  -1.5 0 2.25
-2.3 0 2.025  -2.3 -0.3 2.025  -2.5 -0.3 2.25  -2.5 0 2.25
-2.7 0 2.025  -2.7 -0.3 2.025  -3 -0.3 2.25  -3 0 2.25
-2.7 0 1.8  -2.7 -0.3 1.8  -3 -0.3 1.8  -3 0 1.8
-1.5 0.3 2.25  -1.6 0.3 2.025
-2.5 0.3 2.25  -2.3 0.3 2.025
-3 0.3 2.25  -2.7 0.3 2.025
-3 0.3 1.8  -2.7 0.3 1.8
-2.7 0 1.575  -2.7 -0.3 1.575  -3 -0.3 1.35  -3 0 1.35
-2.5 0 1.125  -2.5 -0.3 1.125  -2.65 -0.3 0.9375  -2.65 0 0.9375
-2 -0.3 0.9  -1.9 -0.3 0.6  -1.9 0 0.6
-3 0.3 1.35  -2.7 0.3 1.575
-2.65 0.3 0.9375  -2.5 0.3 1.125
-1.9 0.3 0.6  -2 0.3 0.9
1.7 0 1.425  1.7 -0.66 1.425  1.7 -0.66 0.6  1.7 0 0.6
2.6 0 1.425  2.6 -0.66 1.425  3.1 -0.66 0.825  3.1 0 0.825
2.3 0 2.1  2.3 -0.25 2.1  2.4 -0.25 2.025  2.4 0 2.025
2.7 0 2.4  2.7 -0.25 2.4  3.3 -0.25 2.4  3.3 0 2.4
1.7 0.66 0.6  1.7 0.66 1.425
3.1 0.66 0.825  2.6 0.66 1.425
2.4 0.25 2.025  2.3 0.25 2.1
3.3 0.25 2.4  2.7 0.25 2.4
2.8 0 2.475  2.8 -0.25 2.475  3.525 -0.25 2.49375  3.525 0 2.49375
2.9 0 2.475  2.9 -0.15 2.475  3.45 -0.15 2.5125  3.45 0 2.5125
2.8 0 2.4  2.8 -0.15 2.4  3.2 -0.15 2.4  3.2 0 2.4
3.525 0.25 2.49375  2.8 0.25 2.475
3.45 0.15 2.5125  2.9 0.15 2.475
3.2 0.15 2.4  2.8 0.15 2.4
0 0 3.15  0 -0.002 3.15  0.002 0 3.15
0.8 0 3.15  0.8 -0.45 3.15  0.45 -0.8 3.15  0 -0.8 3.15
0 0 2.85
0.2 0 2.7  0.2 -0.112 2.7  0.112 -0.2 2.7  0 -0.2 2.7
-0.002 0 3.15  -0.45 -0.8 3.15  -0.8 -0.45 3.15  -0.8 0 3.15
-0.112 -0.2 2.7  -0.2 -0.112 2.7  -0.2 0 2.7
0 0.002 3.15  -0.8 0.45 3.15  -0.45 0.8 3.15  0 0.8 3.15
-0.2 0.112 2.7  -0.112 0.2 2.7  0 0.2 2.7
0.45 0.8 3.15  0.8 0.45 3.15
0.112 0.2 2.7  0.2 0.112 2.7
0.4 0 2.55  0.4 -0.224 2.55  0.224 -0.4 2.55  0 -0.4 2.55
1.3 0 2.55  1.3 -0.728 2.55  0.728 -1.3 2.55  0 -1.3 2.55
1.3 0 2.4  1.3 -0.728 2.4  0.728 -1.3 2.4  0 -1.3 2.4
-0.224 -0.4 2.55  -0.4 -0.224 2.55  -0.4 0 2.55
-0.728 -1.3 2.55  -1.3 -0.728 2.55  -1.3 0 2.55
-0.728 -1.3 2.4  -1.3 -0.728 2.4  -1.3 0 2.4
-0.4 0.224 2.55  -0.224 0.4 2.55  0 0.4 2.55
-1.3 0.728 2.55  -0.728 1.3 2.55  0 1.3 2.55
-1.3 0.728 2.4  -0.728 1.3 2.4  0 1.3 2.4
0.224 0.4 2.55  0.4 0.224 2.55
0.728 1.3 2.55  1.3 0.728 2.55
0.728 1.3 2.4  1.3 0.728 2.4
0 0 0
1.5 0 0.15  1.5 0.84 0.15  0.84 1.5 0.15  0 1.5 0.15
1.5 0 0.075  1.5 0.84 0.075  0.84 1.5 0.075  0 1.5 0.075
1.425 0 0  1.425 0.798 0  0.798 1.425 0  0 1.425 0
-0.84 1.5 0.15  -1.5 0.84 0.15  -1.5 0 0.15
-0.84 1.5 0.075  -1.5 0.84 0.075  -1.5 0 0.075
-0.798 1.425 0  -1.425 0.798 0  -1.425 0 0
-1.5 -0.84 0.15  -0.84 -1.5 0.15  0 -1.5 0.15
-1.5 -0.84 0.075  -0.84 -1.5 0.075  0 -1.5 0.075
-1.425 -0.798 0  -0.798 -1.425 0  0 -1.425 0
0.84 -1.5 0.15  1.5 -0.84 0.15
0.84 -1.5 0.075  1.5 -0.84 0.075
0.798 -1.425 0  1.425 -0.798 0
"""

_TEAPOT_PARTS: dict[str, tuple[int, ...]] = {
    "rim": tuple(range(0, 4)),
    "body": tuple(range(4, 12)),
    "handle": tuple(range(12, 16)),
    "spout": tuple(range(16, 20)),
    "lid": tuple(range(20, 28)),
    "bottom": tuple(range(28, 32)),
}


def _bernstein(t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
    """Cubic Bernstein basis (``order`` = 0, 1, 2: the basis or its derivative), (K, 4)."""
    t = np.asarray(t, float)[:, None]
    s = 1.0 - t
    if order == 0:
        return np.hstack([s**3, 3 * t * s**2, 3 * t**2 * s, t**3])
    if order == 1:
        return np.hstack([-3 * s**2, 3 * s**2 - 6 * t * s, 6 * t * s - 3 * t**2, 3 * t**2])
    return np.hstack([6 * s, 6 * t - 12 * s, 6 * s - 12 * t, 6 * t])


class _BezierPatches:
    """Bicubic Bezier patches ``ctrl`` (P, 4, 4, 3): evaluation and closest points.

    ``project`` seeds from the nearest of a ``grid`` x ``grid`` sampling of every patch
    (cKDTree, built on first use) and refines each seed by clamped Newton steps on
    |S(u, v) - q|^2 (Gauss-Newton where the Hessian is indefinite), keeping the best surface
    point seen, so the distance is always an upper bound and converges to the exact one.
    """

    def __init__(self, ctrl: NDArray[np.float64], grid: int = 64) -> None:
        self.ctrl = np.asarray(ctrl, float)
        self.grid = grid
        self._tree: cKDTree | None = None
        self._seeds: NDArray[np.float64] | None = None

    def derivs(
        self, patch: NDArray[np.int64], u: NDArray[np.float64], v: NDArray[np.float64],
        order: int = 0,
    ) -> list[NDArray[np.float64]]:
        """S, and for ``order`` >= 1 also S_u, S_v, and for 2 S_uu, S_uv, S_vv (each (K, 3))."""
        c = self.ctrl[patch]
        b = [_bernstein(u, k) for k in range(order + 1)]
        cv = [np.einsum("kj,kijd->kid", _bernstein(v, k), c) for k in range(order + 1)]
        pairs = [(0, 0)] + ([(1, 0), (0, 1)] if order >= 1 else [])
        pairs += [(2, 0), (1, 1), (0, 2)] if order >= 2 else []
        return [np.einsum("ki,kid->kd", b[i], cv[j]) for i, j in pairs]

    def jacobian(self, patch: NDArray[np.int64], uv: NDArray[np.float64]) -> NDArray[np.float64]:
        """Area element |S_u x S_v|."""
        _, su, sv = self.derivs(patch, uv[:, 0], uv[:, 1], order=1)
        return np.linalg.norm(np.cross(su, sv), axis=1)

    def project(
        self, q: NDArray[np.float64], seeds: int = 3, steps: int = 12
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Closest surface points of ``q`` (K, 3): (points (K, 3), distances (K,))."""
        q = np.asarray(q, float).reshape(-1, 3)
        if self._tree is None:
            t = (np.arange(self.grid) + 0.5) / self.grid
            uu, vv = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
            p = np.repeat(np.arange(len(self.ctrl)), len(uu))
            u, v = np.tile(uu, len(self.ctrl)), np.tile(vv, len(self.ctrl))
            (pts,) = self.derivs(p, u, v)
            self._tree = cKDTree(pts)
            self._seeds = np.column_stack([p, u, v])
        assert self._seeds is not None  # built with the tree just above
        _, idx = self._tree.query(q, k=seeds)
        idx = idx.reshape(len(q), -1)
        best = np.full(len(q), np.inf)
        best_pt = np.zeros_like(q)
        for j in range(idx.shape[1]):
            seed = self._seeds[idx[:, j]]
            patch = seed[:, 0].astype(np.int64)
            uv = seed[:, 1:].copy()
            for _ in range(steps + 1):
                s, su, sv, suu, suv, svv = self.derivs(patch, uv[:, 0], uv[:, 1], order=2)
                r = s - q
                dist = np.linalg.norm(r, axis=1)
                better = dist < best
                best[better] = dist[better]
                best_pt[better] = s[better]
                g = np.column_stack([(su * r).sum(1), (sv * r).sum(1)])
                a = (su * su).sum(1) + (suu * r).sum(1)
                b = (su * sv).sum(1) + (suv * r).sum(1)
                c = (sv * sv).sum(1) + (svv * r).sum(1)
                indefinite = (a <= 0) | (a * c - b * b <= 0)
                a = np.where(indefinite, (su * su).sum(1), a)
                b = np.where(indefinite, (su * sv).sum(1), b)
                c = np.where(indefinite, (sv * sv).sum(1), c)
                damp = 1e-12 * (a + c) + 1e-300
                a, c = a + damp, c + damp
                det = a * c - b * b
                du = -(c * g[:, 0] - b * g[:, 1]) / det
                dv = -(a * g[:, 1] - b * g[:, 0]) / det
                step = np.column_stack([du, dv])
                # Newton steps far outside the patch (near collapsed sides) are cut to 0.25.
                scale = np.minimum(1.0, 0.25 / np.maximum(np.abs(step).max(axis=1), 1e-300))
                uv = np.clip(uv + step * scale[:, None], 0.0, 1.0)
        return best_pt, best


def _patch_edges(indices: NDArray[np.int64]) -> list[tuple[int, ...]]:
    """The non-degenerate boundary edges of a 4 x 4 index grid, direction-free."""
    out = []
    for e in (indices[0], indices[3], indices[:, 0], indices[:, 3]):
        if len(set(e.tolist())) > 1:
            out.append(tuple(min(e.tolist(), e[::-1].tolist())))
    return out


def teapot(
    n_points: int = 20000, noise: float = 0.0, seed: int = 0,
    parts: tuple[str, ...] = ("rim", "body", "lid", "bottom"),
) -> LabelledCloud:
    """Newell's Utah teapot: the bicubic Bezier patches of the selected ``parts``.

    ``parts`` picks from ``rim`` (4 patches), ``body`` (8: 4 around x 2 up), ``lid`` (8: a
    4-patch knob and a 4-patch ring), ``bottom`` (4), ``handle`` (4) and ``spout`` (4).
    Points are uniform by area (patch counts in proportion to area, rejection sampling by the
    area element within a patch) and labelled by the original patch number, 0..31
    (rim 0-3, body 4-11, handle 12-15, spout 16-19, lid 20-27, bottom 28-31). Original units,
    z up: the teapot spans about 6.4 x 4 x 3.15 (without handle and spout 4 x 4 x 3.15).

    Layout notes: the lid's knob patches and the bottom patches have one side collapsed to the
    centre point (3-sided regions meeting at a smooth pole with a horizontal tangent plane).
    There are no creases: every shared patch edge is tangent-continuous (normals agree to
    1e-6 deg; the rim is a lip folding over into the body). The lid does not touch the
    rim: the lid's lower edge is the circle r = 1.3 at z = 2.4 and the rim's inner edge
    r = 1.4 at z = 2.4, so every selection is open (``closed`` is computed from the shared
    patch edges) and lid + pot are two separate components. Handle and spout pierce the body
    without a shared edge, which is why the default leaves them out.

    ``distance`` is Newton-converged (nearest of a 64 x 64 sampling per patch refined by
    clamped Newton steps, see :class:`_BezierPatches`): about 1e-15 for the clean samples,
    and never above a brute-force 1201 x 1201 sampling per patch; roughly 40 us a point.

    The table follows the widely copied original, except that its vertices 305 and 306 are
    listed in the rotationally symmetric order (the common copy has them swapped, which
    kinks the last bottom patch's control row).
    """
    _check(n_points, noise)
    unknown = [p for p in parts if p not in _TEAPOT_PARTS]
    if unknown or not parts:
        raise InputError(
            f"teapot parts must be a non-empty subset of {sorted(_TEAPOT_PARTS)}, got {parts}"
        )
    rng = np.random.default_rng(seed)
    ids = np.array(sorted({i for p in parts for i in _TEAPOT_PARTS[p]}), dtype=np.int64)
    index = np.array(_TEAPOT_PATCHES.split(), dtype=np.int64).reshape(-1, 4, 4)[ids] - 1
    vertices = np.array(_TEAPOT_VERTICES.split(), dtype=float).reshape(-1, 3)
    surf = _BezierPatches(vertices[index])
    # Area and area-element bound of each patch on a 200 x 200 midpoint grid.
    t = (np.arange(200) + 0.5) / 200
    grid = np.column_stack([a.ravel() for a in np.meshgrid(t, t, indexing="ij")])
    areas, bounds = np.zeros(len(ids)), np.zeros(len(ids))
    for k in range(len(ids)):
        jac = surf.jacobian(np.full(len(grid), k), grid)
        areas[k], bounds[k] = jac.mean(), jac.max()
    # Largest-remainder split of n_points in proportion to area.
    share = areas / areas.sum() * int(n_points)
    counts = np.floor(share).astype(np.int64)
    counts[np.argsort(counts - share)[: int(n_points) - counts.sum()]] += 1
    pts, labels = [], []
    for k, count in enumerate(counts):
        if count == 0:
            continue

        def area(c: NDArray[np.float64], k: int = k) -> NDArray[np.float64]:
            return surf.jacobian(np.full(len(c), k), c)

        uv = _accept(rng, int(count), lambda m: rng.random((m, 2)), area, 1.02 * bounds[k])
        (p,) = surf.derivs(np.full(len(uv), k), uv[:, 0], uv[:, 1])
        pts.append(p)
        labels.append(np.full(len(uv), ids[k]))
    edges: dict[tuple[int, ...], int] = {}
    for grid_k in index:
        for e in _patch_edges(grid_k):
            edges[e] = edges.get(e, 0) + 1
    closed = all(n == 2 for n in edges.values())

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        return surf.project(q)[1]

    return _finish("teapot", np.vstack(pts), np.concatenate(labels), distance, noise, rng, closed)


SHAPES: dict[str, Callable[..., LabelledCloud]] = {
    "sphere6": sphere6,
    "ellipsoid6": ellipsoid6,
    "torus": torus,
    "cylinder": cylinder,
    "can": can,
    "pot": pot,
    "sheet": sheet,
    "teapot": teapot,
}

__all__ = [
    "SHAPES", "LabelledCloud", "can", "cylinder", "ellipsoid6", "pot", "sheet", "sphere6",
    "teapot", "torus",
]
