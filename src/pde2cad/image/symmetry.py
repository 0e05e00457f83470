"""Mirror and rotational symmetry of a boundary loop (thesis Section 3.1).

A symmetric shape only needs its fundamental part fitted; the other parts are the fitted
Béziers mapped by an affine transform, which Béziers are invariant under (Section 3.1).
The thesis tests the PCA axes through the centroid with an intersection-over-union (IoU) of
the shape and its flipped copy, and estimates a rotation angle by least squares on
corresponding corners (Eq. 3.2). This module does the same on the exact pixel region of a
loop, then refines and snaps the transform so that it is exact for exactly symmetric pixels.

A loop is the crack polygon of a shape or hole: ``points`` (n, 2) with integer coordinates,
x right, y down, axis-aligned steps, closed implicitly (pixel (row i, col j) is the unit
square [j, j+1] x [i, i+1]).

Direction contract
------------------
* Rotation: :func:`detect_symmetry` orients the rotation with the loop, so ``sym.apply`` maps a
  forward run of the loop onto the NEXT run in forward order. The loop's signed shoelace area
  (x right, y down) is positive when the loop advances by increasing angle
  ``atan2(y - cy, x - cx)``, so the angle is ``sign(area) * 2 pi / k``.
  For the split ``(i0, i1)`` of :func:`fundamental_split`, ``sym.apply(points[i0])`` is close
  to ``points[i1]``, ``sym.apply`` of the run ``i0..i1`` follows the run ``i1..i1+m``, and
  ``j`` applications give the ``j``-th next part (m ~ n / k).
* Mirror: ``sym.apply`` reverses the loop's direction. ``points[i0]`` and ``points[i1]`` lie
  on the axis (or half a pixel inside the run's side) and the mirrored run, read backwards,
  follows the rest of the loop from ``i1`` forward to ``i0``.
* Vertex counts of corresponding parts agree only for maps that keep the pixel grid (half
  and quarter turns, grid-line mirrors): a staircase at angle a has |cos a| + |sin a|
  vertices per unit length, so "about n / k vertices" is only approximate in general.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.curves.distance import nearest
from pde2cad.errors import InputError

__all__ = ["Symmetry", "boundary_gap", "could_be_symmetric", "detect_symmetry", "fill_loop", "fundamental_split"]

# Loops below these sizes carry too few pixels for an IoU to mean anything.
_MIN_VERTICES = 16
_MIN_AREA = 16.0
# Second moments this close to isotropic leave the PCA axes undefined (any k-fold rotation
# with k >= 3 makes them exactly isotropic), so the mirror axis is found by an angle scan.
_ISOTROPY = 0.1
# Pixel budgets: the scan and the local search use subsamples, the reported IoU uses every
# pixel up to this many (beyond it the subsample error, ~1/sqrt(N), is far below the IoU
# tolerances).
_SEARCH_PIXELS = 40_000
_SCAN_PIXELS = 4_000
_REPORT_PIXELS = 1_000_000
_SNAP_DEG = 0.5
# Bounding boxes above this many pixels are sampled instead of listed pixel by pixel.
_DENSE_PIXELS = 4_000_000


@dataclass(frozen=True, eq=False)
class Symmetry:
    """An isometry that maps a loop's region onto itself: ``x' = matrix @ (x - center) + center``.

    Attributes
    ----------
    kind : str
        ``"mirror"`` or ``"rotation"``.
    matrix : (2, 2) float
        Linear part: ``I - 2 n n^T`` for a mirror with unit axis normal ``n`` (the corrected
        Eq. 3.1), or the rotation by ``+-2 pi / order`` oriented with the loop (module docs).
    center : (2,) float
        A fixed point: the rotation centre, or the point of the mirror axis nearest the
        region's area centroid.
    order : int
        2 for a mirror; ``k`` for a rotation by ``2 pi / k``.
    axis : (2,) float or None
        Unit direction of the mirror axis through ``center``; None for a rotation.
    iou : float
        Intersection over union of the region and its image (pixel-centre sampling).
    """

    kind: str
    matrix: NDArray[np.float64]
    center: NDArray[np.float64]
    order: int
    axis: NDArray[np.float64] | None
    iou: float
    _offset: NDArray[np.float64] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        m = np.array(self.matrix, dtype=float).reshape(2, 2)
        c = np.array(self.center, dtype=float).reshape(2)
        m.setflags(write=False)
        c.setflags(write=False)
        object.__setattr__(self, "matrix", m)
        object.__setattr__(self, "center", c)
        if self.axis is not None:
            a = np.array(self.axis, dtype=float).reshape(2)
            a.setflags(write=False)
            object.__setattr__(self, "axis", a)
        off = c - m @ c
        off.setflags(write=False)
        object.__setattr__(self, "_offset", off)

    @property
    def offset(self) -> NDArray[np.float64]:
        """(2,) translation so that ``x' = matrix @ x + offset``."""
        return self._offset

    @property
    def angle(self) -> float:
        """Signed rotation angle in radians, or the mirror axis direction in [0, pi)."""
        if self.kind == "rotation":
            return float(np.arctan2(self.matrix[1, 0], self.matrix[0, 0]))
        assert self.axis is not None
        return float(np.arctan2(self.axis[1], self.axis[0]) % np.pi)

    @property
    def saving(self) -> float:
        """Fraction of the loop the fitter can skip: ``(k - 1) / k`` (rotation), 1/2 (mirror)."""
        return (self.order - 1) / self.order

    def apply(self, pts: ArrayLike) -> NDArray[np.float64]:
        """Map points ``(..., 2)`` by the symmetry."""
        p = np.asarray(pts, dtype=float)
        return p @ self.matrix.T + self._offset

    def inverse(self) -> Symmetry:
        """The inverse map (the same for a mirror; the opposite rotation otherwise)."""
        return Symmetry(self.kind, self.matrix.T, self.center, self.order, self.axis, self.iou)


# ----------------------------------------------------------------------------- raster


def _validate_loop(points: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"loop points must have shape (n, 2), got {p.shape}")
    if len(p) < 4:
        raise InputError(f"a crack loop needs at least 4 vertices, got {len(p)}")
    if not np.all(np.isfinite(p)):
        raise InputError("loop points contain NaN or inf; pass a traced pixel-boundary loop")
    if np.any(p != np.round(p)):
        raise InputError("loop points must be integer pixel corners (a crack loop)")
    d = np.roll(p, -1, axis=0) - p
    if np.any((d[:, 0] != 0) & (d[:, 1] != 0)):
        raise InputError("loop edges must be axis-aligned (a crack loop from the contour tracer)")
    return p


def fill_loop(points: ArrayLike) -> tuple[NDArray[np.bool_], tuple[int, int]]:
    """Exact raster of a crack loop's interior (even-odd rule) in its bounding box.

    Each vertical crack edge at ``x = c`` spanning row ``r`` toggles the parity of every pixel
    ``(r, j >= c)``; a cumulative XOR along each row then gives the inside pixels, so the
    area equals the shoelace area exactly.

    Parameters
    ----------
    points : (n, 2) float
        Integer-valued vertices, axis-aligned edges of any length, closed implicitly.

    Returns
    -------
    mask : (H, W) bool
        Inside pixels of the bounding box.
    origin : (int, int)
        ``(row0, col0)``: mask[r, c] is pixel ``(row0 + r, col0 + c)``.
    """
    p = _validate_loop(points).astype(np.int64)
    col0, row0 = p.min(axis=0)
    width, height = p.max(axis=0) - (col0, row0)
    q = np.roll(p, -1, axis=0)
    vert = (p[:, 0] == q[:, 0]) & (p[:, 1] != q[:, 1])
    x = p[vert, 0] - col0
    ylo = np.minimum(p[vert, 1], q[vert, 1]) - row0
    span = np.abs(p[vert, 1] - q[vert, 1])
    # Expand edges longer than one pixel into unit spans (vectorized repeat + ramp).
    rows = np.repeat(ylo, span) + (np.arange(span.sum()) - np.repeat(np.cumsum(span) - span, span))
    cols = np.repeat(x, span)
    toggles = np.bincount(rows * (width + 1) + cols, minlength=int(height * (width + 1)))
    parity = np.cumsum(toggles.reshape(height, width + 1) & 1, axis=1) & 1
    return parity[:, :width].astype(bool), (int(row0), int(col0))


@dataclass
class _Region:
    """A loop's pixel region and the data every test of it reuses."""

    mask: NDArray[np.bool_]
    padded: NDArray[np.float64]  # mask with a zero border, for bilinear sampling
    origin: tuple[int, int]
    pix: NDArray[np.float64]  # (N, 2) inside pixel centres
    signed_area: float
    centroid: NDArray[np.float64]
    cov: NDArray[np.float64]
    radius: float  # farthest pixel centre from the centroid
    scan: NDArray[np.float64]  # smaller subsample for the angle scan
    report: NDArray[np.float64]  # pix, subsampled only above _REPORT_PIXELS


def _polygon_moments(
    p: NDArray[np.float64],
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """Signed area, area centroid and central second-moment matrix of a polygon (Green).

    The crack polygon bounds the union of its pixel squares, so these are the exact moments
    of the pixel region: unlike vertex averages they do not depend on how densely the
    boundary is sampled (a staircase side has more vertices than a straight one).
    """
    ref = p.mean(axis=0)  # shift first: the moment sums then do not cancel large numbers
    x, y = (p - ref).T
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    area = 0.5 * cr.sum()
    cx = ((x + xn) * cr).sum() / (6.0 * area)
    cy = ((y + yn) * cr).sum() / (6.0 * area)
    sxx = ((x * x + x * xn + xn * xn) * cr).sum() / (12.0 * area)
    syy = ((y * y + y * yn + yn * yn) * cr).sum() / (12.0 * area)
    sxy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cr).sum() / (24.0 * area)
    cov = np.array([[sxx - cx * cx, sxy - cx * cy], [sxy - cx * cy, syy - cy * cy]])
    return float(area), np.array([cx, cy]) + ref, cov


def _subsample(pix: NDArray[np.float64], budget: int) -> NDArray[np.float64]:
    if len(pix) <= budget:
        return pix
    # A fixed seed keeps detection deterministic; random (not strided) avoids aliasing with
    # periodic shapes such as gear teeth.
    idx = np.random.default_rng(0).choice(len(pix), size=budget, replace=False)
    return pix[np.sort(idx)]


def _region(p: NDArray[np.float64]) -> _Region:
    mask, origin = fill_loop(p)
    signed, centroid, cov = _polygon_moments(p)
    if mask.size <= _DENSE_PIXELS:
        rows, cols = np.nonzero(mask)
    else:
        # Huge regions (a 10000^2 scan): a uniform random sample of the bounding box, kept
        # where it falls inside, estimates the IoU as well as every pixel would, in memory
        # bounded by the sample (listing 50M pixel centres alone took 800 MB).
        rng = np.random.default_rng(0)
        fill = max(abs(signed) / mask.size, 0.01)
        draw = int(min(_REPORT_PIXELS / fill, 20 * _REPORT_PIXELS))
        rows = rng.integers(0, mask.shape[0], draw)
        cols = rng.integers(0, mask.shape[1], draw)
        inside = mask[rows, cols]
        rows, cols = rows[inside], cols[inside]
    pix = np.column_stack([cols + origin[1] + 0.5, rows + origin[0] + 0.5])
    radius = float(np.sqrt(((pix - centroid) ** 2).sum(axis=1).max())) if len(pix) else 0.0
    return _Region(
        mask=mask,
        padded=np.pad(mask.astype(np.float32), 1),
        origin=origin,
        pix=pix,
        signed_area=signed,
        centroid=centroid,
        cov=cov,
        radius=radius,
        scan=_subsample(pix, _SCAN_PIXELS),
        report=_subsample(pix, _REPORT_PIXELS),
    )


def _sample_nearest(
    reg: _Region, x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Region membership of the pixel containing each point (nearest pixel centre)."""
    h, w = reg.mask.shape
    c = np.floor(x).astype(np.int64) - reg.origin[1]
    r = np.floor(y).astype(np.int64) - reg.origin[0]
    ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
    return np.where(ok, reg.mask.ravel()[np.where(ok, r * w + c, 0)], False).astype(float)


def _sample_bilinear(
    reg: _Region, x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Bilinear interpolation of the region's indicator (0 outside the bounding box)."""
    h, w = reg.padded.shape
    u = np.clip(x - (reg.origin[1] - 0.5), 0.0, w - 1.0)  # +1 border, -0.5 to the centre
    v = np.clip(y - (reg.origin[0] - 0.5), 0.0, h - 1.0)
    j = np.minimum(u.astype(np.int64), w - 2)
    i = np.minimum(v.astype(np.int64), h - 2)
    fu, fv = u - j, v - i
    g = reg.padded.ravel()
    k = i * w + j
    top = g[k] + (g[k + 1] - g[k]) * fu
    bot = g[k + w] + (g[k + w + 1] - g[k + w]) * fu
    return top + (bot - top) * fv


def _iou(
    reg: _Region,
    mats: NDArray[np.float64],
    offs: NDArray[np.float64],
    pts: NDArray[np.float64],
    smooth: bool = False,
) -> NDArray[np.float64]:
    """IoU of the region A and its images T(A) for a batch of maps ``x -> M x + b``.

    Only A's pixel centres are mapped: ``I = #{p in A : T p in A}`` measures ``A n T^-1 A``,
    which has the area of ``T A n A`` for an isometry, and ``|T A| = |A|``, so
    ``IoU = I / (2 |A| - I)``. This needs |A| samples instead of the union bounding box.
    ``smooth`` samples bilinearly, which makes the IoU continuous in the map's parameters
    for the local search; the reported IoU uses nearest sampling (exact pixel counts).

    Parameters
    ----------
    mats : (T, 2, 2) float
    offs : (T, 2) float
    pts : (P, 2) float
        Inside pixel centres (all, or a subsample).

    Returns
    -------
    (T,) float
    """
    sample = _sample_bilinear if smooth else _sample_nearest
    out = np.empty(len(mats))
    chunk = max(1, 2_000_000 // max(len(pts), 1))  # bound the (T, P, 2) temporaries
    for s in range(0, len(mats), chunk):
        m, b = mats[s : s + chunk, :, :, None], offs[s : s + chunk, :, None]
        # (T, 2, P): plain broadcasting, several times faster than einsum here.
        mapped = m[:, :, 0] * pts[:, 0] + m[:, :, 1] * pts[:, 1] + b
        inter = sample(reg, mapped[:, 0], mapped[:, 1]).sum(axis=1) / len(pts)
        out[s : s + chunk] = inter / (2.0 - inter)
    return out


# ----------------------------------------------------------------------------- mirror


def _mirror_maps(
    reg: _Region, phi: NDArray[np.float64], s: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Reflections about axes of direction ``phi`` through ``centroid + s n``.

    With unit normal ``n`` the reflection is ``x - 2 ((x - q) . n) n``: the corrected Eq. 3.1.
    """
    n = np.stack([-np.sin(phi), np.cos(phi)], axis=-1)
    q = reg.centroid + s[:, None] * n
    mats = np.eye(2) - 2.0 * n[:, :, None] * n[:, None, :]
    offs = 2.0 * (q * n).sum(axis=1)[:, None] * n
    return mats, offs


def _mirror_from_axis(
    reg: _Region, direction: NDArray[np.float64], point: NDArray[np.float64]
) -> Symmetry:
    """The mirror about the line through ``point`` along ``direction``, with its IoU."""
    d = direction / np.linalg.norm(direction)
    n = np.array([-d[1], d[0]])
    center = reg.centroid - ((reg.centroid - point) @ n) * n
    mat = np.eye(2) - 2.0 * np.outer(n, n)
    off = 2.0 * (center @ n) * n
    iou = float(_iou(reg, mat[None], off[None], reg.report)[0])
    return Symmetry("mirror", mat, center, 2, d, iou)


def _refine(
    objective: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    x0: NDArray[np.float64],
    steps: NDArray[np.float64],
    tol: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Compass search maximizing ``objective`` (batched over the 8 neighbour moves).

    The IoU of pixel regions has kinks (it peaks sharply at an exact pixel symmetry), which a
    derivative-free pattern search handles where a gradient method would stall.
    """
    moves = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], float)
    x = np.asarray(x0, dtype=float)
    best = float(objective(x[None])[0])
    step = np.asarray(steps, dtype=float)
    for _ in range(200):
        if np.all(step < tol):
            break
        trial = x + moves * step
        vals = objective(trial)
        k = int(np.argmax(vals))
        if vals[k] > best + 1e-12:
            x, best = trial[k], float(vals[k])
        else:
            step = step / 2.0
    return x


def _smooth_iou(reg: _Region, sym: Symmetry) -> float:
    return float(_iou(reg, sym.matrix[None], sym.offset[None], reg.report, smooth=True)[0])


def _snap_mirror(reg: _Region, sym: Symmetry) -> Symmetry:
    """Snap a nearly axis-aligned or diagonal axis onto the lines pixel grids are symmetric about.

    A pixel image can only be exactly mirror-symmetric about ``x = c`` or ``y = c`` with
    ``2c`` an integer, or about diagonals ``x -+ y = c`` with ``c`` an integer (pixel centres
    then map to pixel centres). An axis within 0.5 deg of such a direction is snapped, first
    in angle and offset, else in angle only, when that does not lower the bilinear IoU the
    search maximized. That IoU peaks (at 1) exactly on the grid line for an exactly
    symmetric image, but penalizes moving a slightly tilted or off-grid true axis, which
    nearest-pixel sampling (biased towards grid-aligned maps) would not.
    """
    assert sym.axis is not None
    phi = np.degrees(sym.angle)
    for target, direction, normal, grid in (
        (0.0, (1.0, 0.0), (0.0, 1.0), 0.5),
        (180.0, (1.0, 0.0), (0.0, 1.0), 0.5),
        (90.0, (0.0, 1.0), (1.0, 0.0), 0.5),
        (45.0, (1.0, 1.0), (1.0, -1.0), 1.0),
        (135.0, (-1.0, 1.0), (1.0, 1.0), 1.0),
    ):
        if abs(phi - target) > _SNAP_DEG:
            continue
        d = np.array(direction) / np.linalg.norm(direction)
        nrm = np.array(normal)  # unnormalized: the line is nrm . x = value
        value = float(nrm @ sym.center)
        on_grid = np.round(value / grid) * grid
        point = sym.center + (on_grid - value) * nrm / (nrm @ nrm)
        base = _smooth_iou(reg, sym) - 1e-9
        for cand in (_mirror_from_axis(reg, d, point), _mirror_from_axis(reg, d, sym.center)):
            if _smooth_iou(reg, cand) >= base:
                return cand
        return sym
    return sym


def _scan_angles(reg: _Region, max_peaks: int, floor: float) -> tuple[list[float], float]:
    """Axis angles of the best local IoU maxima of a scan over [0, pi) through the centroid.

    Returns the angles, best first, and the scan step (a true axis lies within half of it).
    """
    # Half a step off the true axis then moves the farthest pixel by at most 0.75 px, so a
    # true axis scores within a few per cent of its refined IoU (the band below iou_min).
    step = float(np.clip(1.5 / max(reg.radius, 1.0), np.radians(0.1), np.radians(1.0)))
    phi = np.arange(0.0, np.pi, step)
    mats, offs = _mirror_maps(reg, phi, np.zeros_like(phi))
    val = _iou(reg, mats, offs, reg.scan, smooth=True)
    # Local maxima over a +-3 step window (circular: axis angles have period pi).
    win = np.stack([np.roll(val, k) for k in range(-3, 4)])
    peaks = np.nonzero((val >= win.max(axis=0)) & (val >= floor))[0]
    peaks = peaks[np.argsort(-val[peaks])][:max_peaks]
    return [float(phi[i]) for i in peaks], step


def _boundary_band(reg: _Region, width: float) -> NDArray[np.float64]:
    """Inside pixel centres within ``width`` px (chessboard) of the outside, subsampled."""
    deep = _erode_square(reg.mask, int(np.floor(width)))
    rows, cols = np.nonzero(reg.mask & ~deep)
    pix = np.column_stack([cols + reg.origin[1] + 0.5, rows + reg.origin[0] + 0.5])
    return _subsample(pix, _SEARCH_PIXELS)


def _erode_square(mask: NDArray[np.bool_], r: int) -> NDArray[np.bool_]:
    """Pixels whose whole (2r+1)^2 square lies in ``mask`` (outside counts as empty).

    Separable: along each axis the AND over a window of L = 2r + 1 is that of two
    overlapping power-of-two windows, each built by doubling (O(log L) passes).
    """
    out = mask
    for axis in (0, 1):
        a = np.moveaxis(out, axis, 0)
        size = a.shape[0]
        pad = np.zeros((size + 2 * r,) + a.shape[1:], dtype=bool)
        pad[r : r + size] = a
        span, acc = 1, pad
        while 2 * span <= 2 * r + 1:
            acc = acc[:-span] & acc[span:]  # AND over [i, i + 2 span)
            span *= 2
        length = 2 * r + 1
        out = np.moveaxis(acc[:size] & acc[length - span : length - span + size], 0, axis)
    return out


def _mirrors(reg: _Region, iou_min: float, max_axes: int) -> list[Symmetry]:
    evals, evecs = np.linalg.eigh(reg.cov)
    anisotropy = (evals[1] - evals[0]) / max(evals[1] + evals[0], 1e-300)
    if anisotropy > _ISOTROPY:
        # A mirror fixes the centroid and the inertia tensor, so its axis is a principal axis.
        starts = [float(np.arctan2(v[1], v[0])) for v in evecs.T]
        dphi = np.radians(2.0)
    else:
        starts, dphi = _scan_angles(reg, 2 * max_axes, floor=iou_min - 0.05)
    if starts:
        # Cheap screen before the costly refinement: a true axis already scores within a few
        # per cent of iou_min unrefined (most loops have no mirror at all).
        mats, offs = _mirror_maps(reg, np.array(starts), np.zeros(len(starts)))
        pre = _iou(reg, mats, offs, reg.scan, smooth=True)
        starts = [s for s, v in zip(starts, pre) if v >= iou_min - 0.1]
    # Stop once the axis moves the farthest pixel by under 0.02 px: far below pixel noise.
    tol = np.array([0.02 / max(reg.radius, 1.0), 0.02])
    band = _boundary_band(reg, 3.0 + 2.0 * (reg.radius * dphi + 1.0))

    def objective(params: NDArray[np.float64]) -> NDArray[np.float64]:
        # Pixels deeper inside than the search moves anything map inside for every map
        # tried, so they add a constant to the overlap: the band alone ranks the maps the
        # same (the value is a monotone function of the IoU, not the IoU itself).
        mats, offs = _mirror_maps(reg, params[:, 0], params[:, 1])
        return _iou(reg, mats, offs, band, smooth=True)

    found: list[Symmetry] = []
    for phi0 in starts:
        phi, s = _refine(objective, np.array([phi0, 0.0]), np.array([dphi, 1.0]), tol)
        d = np.array([np.cos(phi), np.sin(phi)])
        n = np.array([-d[1], d[0]])
        sym = _snap_mirror(reg, _mirror_from_axis(reg, d, reg.centroid + s * n))
        if sym.iou < iou_min:
            continue
        dup = any(
            abs((sym.angle - o.angle + np.pi / 2) % np.pi - np.pi / 2) < np.radians(1.0)
            and abs((sym.center - o.center) @ np.array([-sym.axis[1], sym.axis[0]])) < 1.0
            for o in found
            if o.axis is not None and sym.axis is not None
        )
        if not dup:
            found.append(sym)
    found.sort(key=lambda m: -m.iou)
    return found[:max_axes]


# ----------------------------------------------------------------------------- rotation


def _rotation(theta: float) -> NDArray[np.float64]:
    c, s = np.cos(theta), np.sin(theta)
    if abs(theta % (np.pi / 2)) < 1e-12 or abs(theta % (np.pi / 2) - np.pi / 2) < 1e-12:
        c, s = np.round(c), np.round(s)  # exact quarter turns keep pixel centres on centres
    return np.array([[c, -s], [s, c]])


def _rotation_sym(reg: _Region, theta: float, center: NDArray[np.float64], k: int) -> Symmetry:
    mat = _rotation(theta)
    off = center - mat @ center
    iou = float(_iou(reg, mat[None], off[None], reg.report)[0])
    return Symmetry("rotation", mat, center, k, None, iou)


def _corner_angle(
    reg: _Region, p: NDArray[np.float64], corners: NDArray[np.intp], theta0: float
) -> float | None:
    """Least-squares rotation angle from corresponding corners (Eq. 3.2), or None.

    Each corner, rotated by the nominal ``theta0``, is paired with the nearest corner when
    that lies within 2 px (or 5 % of its radius); Eq. 3.2 is then solved for
    ``(cos theta, sin theta)`` by least squares in centroid-centred coordinates.
    """
    q = p[corners] - reg.centroid
    if len(q) < 2:
        return None
    rot = q @ _rotation(theta0).T
    dist = np.linalg.norm(rot[:, None, :] - q[None, :, :], axis=2)
    j = np.argmin(dist, axis=1)
    ok = dist[np.arange(len(q)), j] <= np.maximum(2.0, 0.05 * np.linalg.norm(q, axis=1))
    if ok.sum() < 2:
        return None
    src, dst = q[ok], q[j[ok]]
    a = np.empty((2 * len(src), 2))
    a[0::2] = np.column_stack([src[:, 0], -src[:, 1]])
    a[1::2] = np.column_stack([src[:, 1], src[:, 0]])
    cs = np.linalg.lstsq(a, dst.reshape(-1), rcond=None)[0]
    return float(np.arctan2(cs[1], cs[0]))


def _snap_center(reg: _Region, sym: Symmetry) -> Symmetry:
    """Round a centre that is a half-pixel point up to floating round-off.

    An exactly symmetric pixel region has its area centroid on the grid points it turns
    about, up to round-off; rounding keeps pixel centres mapping exactly onto pixel centres.
    A genuinely off-grid centre is kept: the centroid is then the better estimate.
    """
    grid = np.round(2.0 * sym.center) / 2.0
    if np.max(np.abs(grid - sym.center)) > 1e-6:
        return sym
    return _rotation_sym(reg, sym.angle, grid, sym.order)


def _rotations(
    reg: _Region,
    p: NDArray[np.float64],
    iou_min: float,
    max_order: int,
    corners: NDArray[np.intp] | None,
) -> list[Symmetry]:
    # Orient with the loop: a positive signed area advances by increasing angle (module docs).
    sign = 1.0 if reg.signed_area > 0 else -1.0
    found: list[Symmetry] = []
    for k in range(2, max_order + 1):
        theta = sign * 2.0 * np.pi / k
        sym = _snap_center(reg, _rotation_sym(reg, theta, reg.centroid, k))
        if corners is not None and k > 2:
            # Eq. 3.2 can only move the angle off 2 pi / k for a shape that is not exactly
            # k-fold; keep its estimate only if it fits the region better.
            refined = _corner_angle(reg, p, corners, theta)
            if refined is not None and abs(refined - theta) < np.radians(2.0):
                alt = _rotation_sym(reg, refined, sym.center, k)
                if alt.iou > sym.iou:
                    sym = alt
        if sym.iou >= iou_min:
            found.append(sym)
    return found


# ----------------------------------------------------------------------------- public


def _validate_corners(corners: ArrayLike | None, n: int) -> NDArray[np.intp] | None:
    if corners is None:
        return None
    c = np.asarray(corners)
    if c.ndim != 1 or (c.size and not np.issubdtype(c.dtype, np.integer)):
        raise InputError("corners must be a 1-D array of integer indices into points")
    if c.size and (c.min() < 0 or c.max() >= n):
        raise InputError(f"corner indices must lie in [0, {n}), got [{c.min()}, {c.max()}]")
    return c.astype(np.intp) if c.size else None


def detect_symmetry(
    points: ArrayLike,
    *,
    iou_min: float = 0.97,
    max_order: int = 8,
    corners: ArrayLike | None = None,
    max_distance: float | None = None,
) -> list[Symmetry]:
    """Mirror and rotational symmetries of a loop's region, best first (Section 3.1).

    Mirror: the region's area centroid and second moments (exact for the pixel squares; see
    :func:`_polygon_moments`) give the PCA axes the thesis tests. When the moments are
    nearly isotropic (every k-fold shape with k >= 3) the axes are undefined, so the axis
    angle is scanned instead. Each candidate is refined (angle and offset) by a compass
    search on a bilinear IoU, then snapped onto the pixel grid's symmetry lines.
    Rotation: about the area centroid by ``2 pi / k`` for k = 2..max_order, oriented with the
    loop (module docs). With ``corners``, Eq. 3.2 on corners paired by the nominal rotation
    gives a least-squares angle, kept (k >= 3) only if it raises the IoU; note that only
    ``2 pi / k`` exactly closes up after k applications.

    Parameters
    ----------
    points : (n, 2) float
        A crack loop (integer vertices, axis-aligned steps, closed implicitly).
    iou_min : float
        Keep symmetries whose IoU of region vs. image is at least this.
    max_order : int
        Highest rotation order tested (>= 2).
    corners : (m,) int, optional
        Indices of corner vertices, used by Eq. 3.2.
    max_distance : float, optional
        Also keep only the symmetries that map every loop vertex within this distance
        (px) of a loop vertex (:func:`boundary_gap`): the test a fitter within a tolerance
        needs (twice the tolerance, plus half a pixel for vertex spacing), which thin
        features pass where an IoU fails (a 12 px stem 1 px thicker on one side already
        scores 0.94). ``iou_min`` is then only a coarse screen.

    Returns
    -------
    list of Symmetry
        Every rotation order and mirror axis passing ``iou_min``, sorted by the share of the
        loop they save (``(k - 1) / k`` for rotation k, 1/2 for a mirror), then by IoU; so
        the first rotation listed is the highest order found. Empty for loops under 16
        vertices or 16 px of area, or with no symmetry.
    """
    p = _validate_loop(points)
    if not 0.0 < iou_min <= 1.0:
        raise InputError(f"iou_min must lie in (0, 1], got {iou_min}")
    if int(max_order) < 2:
        raise InputError(f"max_order must be at least 2, got {max_order}")
    c = _validate_corners(corners, len(p))
    x, y = p[:, 0], p[:, 1]
    shoelace = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))
    if len(p) < _MIN_VERTICES or shoelace < _MIN_AREA:
        return []
    reg = _region(p)
    cands = _rotations(reg, p, iou_min, int(max_order), c) + _mirrors(reg, iou_min, min(int(max_order), 8))
    if max_distance is not None:
        cands = [s for s in cands if boundary_gap(p, s) <= max_distance]
    cands.sort(key=lambda s: (-s.saving, -s.iou))
    return cands


def boundary_gap(points: ArrayLike, sym: Symmetry, reach: int = 4) -> float:
    """Largest distance from a mapped loop vertex to the nearest loop vertex (px).

    Steps: 1. the loop's vertices (integer points) are marked in a raster of its
    bounding box; 2. each mapped vertex looks at the lattice points within ``reach`` of
    its rounded position; 3. the nearest marked one gives its distance (inf if none).
    O(n reach^2), no KD-tree.

    Parameters
    ----------
    points : (n, 2) float
        The loop (integer vertices).
    sym : Symmetry
    reach : int
        Lattice radius searched; gaps beyond it come out as inf.

    Returns
    -------
    float
        0 for an exact pixel symmetry; about 1 px for a true symmetry off the pixel grid
        (two staircases around one curve).
    """
    p = _validate_loop(points).astype(np.int64)
    lo = p.min(axis=0)
    size = p.max(axis=0) - lo + 1
    marked = np.zeros((size[1], size[0]), dtype=bool)
    marked[p[:, 1] - lo[1], p[:, 0] - lo[0]] = True
    q = sym.apply(p.astype(float)) - lo
    base = np.round(q).astype(np.int64)
    r = np.arange(-reach, reach + 1)
    off = np.stack(np.meshgrid(r, r), axis=-1).reshape(-1, 2)  # (m, 2) as (dx, dy)
    cand = base[:, None, :] + off[None, :, :]
    ok = (cand >= 0).all(axis=2) & (cand[..., 0] < size[0]) & (cand[..., 1] < size[1])
    hit = np.zeros(ok.shape, dtype=bool)
    hit[ok] = marked[cand[..., 1][ok], cand[..., 0][ok]]
    dist = np.where(hit, np.linalg.norm(cand - q[:, None, :], axis=2), np.inf)
    return float(dist.min(axis=1).max())


def could_be_symmetric(points: ArrayLike, max_distance: float, max_order: int = 8, bins: int = 360) -> bool:
    """False when no rotation about the centroid (order 2..max_order) and no mirror through it
    can map every loop vertex within ``max_distance`` of a loop vertex; O(n + bins^2).

    Steps: 1. ``h``: the farthest vertex from the area centroid in each angular bin;
    2. a map T fixing the centroid takes that vertex to the angle of bin ``b``'s image,
    where a vertex at most ``L`` away lies (``L``: ``max_distance`` plus a pixel for the
    centroid and axis offset), within ``asin(L / r)`` of that angle and at radius at least
    ``h[b] - L``; 3. so the maximum of ``h`` over that window must reach ``h[b] - L``.
    Bins nearer than half the farthest radius are not tested (their windows are wide).
    A necessary condition of :func:`boundary_gap` <= ``max_distance``: True is no promise.
    """
    p = _validate_loop(points)
    _, centroid, _ = _polygon_moments(p)
    d = p - centroid
    r = np.hypot(d[:, 0], d[:, 1])
    reach = float(max_distance) + 1.0
    big = 0.5 * r.max()
    if big <= 2.0 * reach:
        return True  # too small for the angular windows to mean anything
    b = np.floor((np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)) % 1.0 * bins).astype(np.int64) % bins
    h = np.full(bins, -np.inf)
    np.maximum.at(h, b, r)
    half = int(np.ceil(np.arcsin(reach / (big - reach)) * bins / (2 * np.pi))) + 2  # +1 bin, +1 rounding
    wide = np.max([np.roll(h, j) for j in range(-half, half + 1)], axis=0)  # wide[i]: max near bin i
    src = np.flatnonzero(h >= big)
    need = h[src] - reach
    for k in range(2, int(max_order) + 1):
        for sign in (1, -1):
            if np.all(wide[(src + sign * int(round(bins / k))) % bins] >= need):
                return True
    # Mirror about the axis at angle m pi / bins: bin b goes to bin m - b.
    dst = (np.arange(bins)[:, None] - src[None, :] - 1) % bins
    return bool(np.any(np.all(wide[dst] >= need[None, :], axis=1)))


def _cyclic_gap(a: NDArray[np.intp] | int, b: NDArray[np.intp] | int, n: int) -> NDArray[np.intp]:
    """Forward index distance from ``a`` to ``b`` on a loop of ``n`` vertices."""
    return np.mod(np.asarray(b) - np.asarray(a), n)


def _mirror_split(p: NDArray[np.float64], sym: Symmetry) -> tuple[int, int]:
    n_pts = len(p)
    assert sym.axis is not None
    nrm = np.array([-sym.axis[1], sym.axis[0]])
    d = (p - sym.center) @ nrm
    on = np.abs(d) < 1e-9
    sgn = np.sign(np.where(on, 0.0, d))
    nz = np.nonzero(~on)[0]
    if len(nz) < 2:
        raise InputError("the loop lies on the mirror axis; it is not a mirror-symmetric loop")
    # Sign changes between consecutive off-axis vertices a -> b (forward, maybe with on-axis
    # vertices in between). The run covers the positive side, so it starts where the loop
    # enters it and ends where it leaves: at an on-axis vertex when there is one, else at
    # the positive end of the crossing edge (half a pixel off an axis between vertices).
    nxt = np.roll(nz, -1)
    change = sgn[nz] != sgn[nxt]
    a, b = nz[change], nxt[change]
    if len(a) < 2:
        raise InputError("the loop does not cross the mirror axis twice; check the symmetry")
    mid = np.mod(a + _cyclic_gap(a, b, n_pts) // 2, n_pts)
    entering = sgn[b] > 0
    cross = np.where(on[mid], mid, np.where(entering, b, a))
    if len(cross) > 2:
        # Raster noise can add crossings; the true two are the loop's fixed points under the
        # mirror (a direction-reversing map of a circle fixes exactly two points), one
        # entering and one leaving the positive side, about half a loop apart.
        img = nearest(p, sym.apply(p[cross]))[1]
        fix = np.minimum(_cyclic_gap(cross, img, n_pts), _cyclic_gap(img, cross, n_pts))
        half = np.abs(_cyclic_gap(cross[:, None], cross[None, :], n_pts) - n_pts / 2.0)
        score = fix[:, None] + fix[None, :] + half
        score[entering[:, None] == entering[None, :]] = np.inf
        i, j = np.unravel_index(np.argmin(score), score.shape)
        cross, entering = cross[[i, j]], entering[[i, j]]
    i0 = int(cross[entering][0]) if entering.any() else int(cross[0])
    i1 = int(cross[~entering][0]) if (~entering).any() else int(cross[1])
    return i0, i1


def _rotation_split(
    p: NDArray[np.float64], sym: Symmetry, corners: NDArray[np.intp] | None
) -> tuple[int, int]:
    n_pts = len(p)
    k = sym.order
    if k > 2:
        signed = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        if np.sign(sym.angle) != np.sign(signed):
            raise InputError(
                "the rotation turns against the loop's direction (the loop was reversed after "
                "detection); use sym.inverse()"
            )
    if corners is not None:
        # A corner is a natural curve end; prefer the one whose image lands on another corner.
        img = sym.apply(p[corners])
        dist = np.linalg.norm(img[:, None, :] - p[corners][None, :, :], axis=2).min(axis=1)
        i0 = int(corners[np.argmin(dist)])
    else:
        # Prefer a vertex whose image lands on a vertex (exact for quarter and half turns),
        # then the straightest such vertex, so the joins between mapped parts are smooth.
        dist = nearest(p, sym.apply(p))[0]
        w = max(2, n_pts // (8 * k))
        before = p - np.roll(p, w, axis=0)
        after = np.roll(p, -w, axis=0) - p
        cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
        turn = np.abs(np.arctan2(cross, (before * after).sum(axis=1)))
        good = dist <= dist.min() + 0.25
        i0 = int(np.argmin(np.where(good, turn, np.inf)))
    m = n_pts / k
    # Congruent parts have different vertex counts off the pixel grid (staircases), so the
    # image of points[i0] is searched a third of a part around the nominal n / k.
    win = max(2, int(np.ceil(m / 3)))
    idx = np.mod(i0 + int(round(m)) + np.arange(-win, win + 1), n_pts)
    target = sym.apply(p[i0])
    err = np.linalg.norm(p[idx] - target, axis=1) + 1e-6 * np.abs(np.arange(-win, win + 1))
    return i0, int(idx[np.argmin(err)])


def fundamental_split(
    points: ArrayLike, sym: Symmetry, corners: ArrayLike | None = None
) -> tuple[int, int]:
    """The fundamental part of a symmetric loop: the cyclic run ``points[i0], ..., points[i1]``.

    Mirror: ``i0`` and ``i1`` are where the loop enters and leaves the side of the positive
    axis normal ``(-axis[1], axis[0])``: on-axis vertices, or for an axis between vertices
    the vertices half a pixel inside that side. The run is that side; mirrored and read
    backwards it follows the rest of the loop, from ``i1`` forward to ``i0`` (exactly, vertex
    for vertex, for an exact pixel symmetry: ``sym.apply(points[i0 + j]) == points[i0 - j]``
    on an on-axis split). A fitter should end the curves on the axis (project the ends).
    Rotation of order k: ``i0`` is a corner (when given) or a vertex whose image lands on a
    vertex, preferring straight parts; ``i1`` is the vertex nearest ``sym.apply(points[i0])``
    about n / k vertices forward. ``sym`` must be oriented with the loop, as
    :func:`detect_symmetry` returns it: ``sym.apply`` then maps the run onto the next run
    forward (module docs). A fitter should end the fundamental curves at
    ``sym.apply(points[i0])`` rather than ``points[i1]`` so the mapped parts close exactly.

    Parameters
    ----------
    points : (n, 2) float
        The loop passed to :func:`detect_symmetry`.
    sym : Symmetry
        One of its results.
    corners : (m,) int, optional
        Corner indices; a rotation split starts at one.

    Returns
    -------
    (int, int)
        ``(i0, i1)``; the run wraps past the end of ``points`` when ``i1 < i0``.

    Raises
    ------
    InputError
        If the loop does not fit the symmetry (no two axis crossings; a rotation reversed
        against the loop's direction).
    """
    p = _validate_loop(points)
    c = _validate_corners(corners, len(p))
    if sym.kind == "mirror":
        return _mirror_split(p, sym)
    if sym.kind == "rotation":
        return _rotation_split(p, sym, c)
    raise InputError(f"unknown symmetry kind {sym.kind!r}; expected 'mirror' or 'rotation'")
