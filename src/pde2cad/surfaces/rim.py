"""Open rims where the sampled surface really ends, not where its last samples happen to lie.

A surface sampled up to its rim has no sample on the rim: along a stretch of rim of length
``L`` the outermost of uniformly random samples (density ``rho`` per unit area) lies an
exponentially distributed gap of mean ``1 / (rho L)`` inside, and the alpha-shape loop that
joins such outermost points zigzags between them, about half a spacing inside on average. A
side fitted to that loop sits inside the true rim and waves; worse, the loop points' heights
are single noisy samples, so the side's height above the surface carries the sample noise
into every patch that keeps the side fixed.

:func:`locate_rim` replaces the loop by rim points estimated from all samples near it:

1. Reference: the provisional rim curve (the side fitted to the loop), sampled densely by arc
   length. The sample spacing ``s = 1 / sqrt(rho)`` comes from the k-nearest-neighbour
   distances (:func:`sample_spacing`), so every length below is in spacings: the estimate
   does not depend on the scale or the position of the cloud.
2. Stations every ``RIM_STEP`` spacings along the rim, each with a window ``RIM_WINDOW``
   spacings long and ``RIM_DEPTH`` spacings (and at least ``NOISE_DEPTH`` noise sigmas) deep.
   In a window: the surface normal ``N`` (PCA of the window's points), the rim tangent ``T``
   and the outward direction ``O = T x N`` in the tangent plane; each point's outward offset
   ``d`` from the reference curve, and its height over the tangent plane.
3. Height: a quadric ``h(x, y)`` fitted to the window's points by least squares; its residual
   RMS is the noise ``sigma`` (isotropic noise: the same in the tangent plane).
4. Rim offset: the offsets of uniform samples of a surface ending at offset ``e``, blurred by
   Gaussian noise ``sigma`` and cut at depth ``c``, have the density
   ``Phi((e - d) / sigma) / (e - c)`` on ``d > c``; ``e`` is its maximum-likelihood value. For
   ``sigma -> 0`` that is the outermost offset ``d_max``, whose gap to ``e`` has mean
   ``(e - c) / (n + 1)`` for ``n`` points: that is added back, weighted by how much of the
   likelihood's width the gap is (none once noise dominates, where the maximum-likelihood
   estimate is nearly unbiased). A window whose outermost offsets form a row (a grid's
   last row of samples: several within a tenth of the gap) has its rim on that row.
5. The rim point: ``Q + e O + h(0, e) N`` at the station's reference point ``Q``, i.e. the
   surface extrapolated to the estimated rim.

Samples within a window depth of the rim's ends are left out (the other side of a corner
would cut the windows' depth there); the ends are left to the corner estimate of the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree
from scipy.special import log_ndtr

from pde2cad.curves.piecewise import denoise
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.sheets import SHEET_LINK, SHEET_STRETCH, one_sheet

#: Window length along the rim, in sample spacings: ~RIM_WINDOW x RIM_DEPTH points per window.
RIM_WINDOW = 12.0
#: Station spacing along the rim, in sample spacings (windows overlap by half).
RIM_STEP = 6.0
#: Window depth into the surface, in sample spacings ...
RIM_DEPTH = 4.0
#: ... and at least this many noise sigmas (so the noise blur of the rim lies inside it).
NOISE_DEPTH = 4.0
#: Farthest a rim point may lie from the provisional side, in sample spacings (or
#: NOISE_DEPTH noise sigmas); a window that moves it farther is dropped.
RIM_MOST = 3.0
#: Neighbour rank whose distance gives the density (rho = k / (pi r_k^2)).
DENSITY_RANK = 10
#: A window needs this many points for its quadric (6 unknowns) and offset estimate.
MIN_WINDOW_POINTS = 18
#: Offsets within a tenth of the mean gap of the outermost one that make a window's rim a
#: sampled row (random samples put 0.1 there on average, a grid row ~RIM_WINDOW).
SAMPLED_ROW = 3
#: Points of the density estimate (a strided subsample of the cloud).
_DENSITY_SAMPLE = 20_000
#: Loop points a polyline reference is smoothed over (odd).
REFERENCE_WINDOW = 31
#: Offsets tried per station by the likelihood search (then refined by a parabola).
_GRID = 33


@dataclass(frozen=True)
class RimEstimate:
    """Rim points estimated along one open side.

    Attributes
    ----------
    points : (J, 3) float
        The rim at the stations, in order along the side.
    arc : (J,) float
        Arc length of each station along the reference curve, from its start.
    length : float
        Arc length of the reference curve.
    shift : (J,) float
        Outward move of each station from the reference curve (negative: inwards).
    noise : (J,) float
        Noise sigma estimated in each window (quadric residual RMS).
    sampled : (J,) bool
        Windows whose rim is a row of samples (structured data): there the boundary loop
        already runs on the rim.
    """

    points: NDArray[np.float64]
    arc: NDArray[np.float64]
    length: float
    shift: NDArray[np.float64]
    noise: NDArray[np.float64]
    sampled: NDArray[np.bool_]


def sample_spacing(points: NDArray[np.float64], tree: cKDTree | None = None) -> float:
    """Sample spacing ``s = 1 / sqrt(rho)`` of points on a surface, ``rho`` per unit area.

    ``rho = k / (pi r_k^2)`` with ``r_k`` the median distance to the ``DENSITY_RANK``-th
    neighbour (over a strided subsample): unbiased for uniformly random samples, and within
    ~15 % for a square grid (spacing ``h``: ``s = 0.88 h`` at k = 10). ``tree``: a KD-tree
    of ``points`` (built when omitted).
    """
    tree = cKDTree(points) if tree is None else tree
    query = points[:: max(1, len(points) // _DENSITY_SAMPLE)]
    k = min(DENSITY_RANK, len(points) - 1)
    dist, _ = tree.query(query, k=k + 1, workers=-1)
    r = float(np.median(dist[:, -1]))
    return r * float(np.sqrt(np.pi / k))


def locate_rim(
    points: NDArray[np.float64],
    reference: PiecewiseBezier | NDArray[np.float64],
    spacing: float,
    tree: cKDTree | None = None,
    least: int = 1,
) -> RimEstimate | None:
    """Rim points of an open side from the samples near it (see the module docstring).

    Parameters
    ----------
    points : (N, 3) float
        The samples of the surface the side bounds (others may be included if they lie
        farther than a window depth from the side).
    reference : PiecewiseBezier or (m, 3) float
        The provisional side, e.g. fitted to the boundary loop, or the ordered loop points
        themselves: within about a window depth of the true rim, and oriented either way.
    spacing : float
        Sample spacing (:func:`sample_spacing`).
    tree : cKDTree, optional
        KD-tree of ``points`` (built when omitted).
    least : int
        Fewest stations: a short side gets them closer than ``RIM_STEP`` spacings (windows
        overlapping more), so an edge fit has enough data.

    Returns
    -------
    RimEstimate or None
        None when the side is too short for one station away from its ends.
    """
    ref, tangent, arc = _reference(reference, 0.5 * spacing)
    length = float(arc[-1])
    tree = cKDTree(points) if tree is None else tree
    depth = RIM_DEPTH * spacing
    half = 0.5 * RIM_WINDOW * spacing
    # First pass at the nominal depth; a second one if the noise needs a deeper window.
    est = _stations(points, tree, ref, tangent, arc, half, depth, spacing, least)
    if est is not None and NOISE_DEPTH * float(np.median(est.noise)) > depth:
        depth = NOISE_DEPTH * float(np.median(est.noise))
        est = _stations(points, tree, ref, tangent, arc, half * depth / (RIM_DEPTH * spacing),
                        depth, spacing, least)
    return est


def _reference(
    curve: PiecewiseBezier | NDArray[np.float64], step: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Samples of ``curve`` about ``step`` apart by arc length, unit tangents and arc.

    A polyline (m, 3) (e.g. a run of an alpha-shape loop) is smoothed first
    (Savitzky-Golay over REFERENCE_WINDOW points), so its zigzag does not turn the tangents.
    """
    if isinstance(curve, PiecewiseBezier):
        fine = curve.evaluate(np.linspace(0.0, 1.0, 2049))
    else:
        fine, _ = denoise(np.asarray(curve, dtype=float), closed=False, pos_window=REFERENCE_WINDOW)
    seg = np.linalg.norm(np.diff(fine, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    count = max(int(np.ceil(arc[-1] / step)), 2) + 1
    s = np.linspace(0.0, arc[-1], count)
    ref = np.stack([np.interp(s, arc, fine[:, d]) for d in range(fine.shape[1])], axis=1)
    tangent = np.gradient(ref, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return ref, tangent, s


def _stations(
    points: NDArray[np.float64],
    tree: cKDTree,
    ref: NDArray[np.float64],
    tangent: NDArray[np.float64],
    arc: NDArray[np.float64],
    half: float,
    depth: float,
    spacing: float,
    least: int,
) -> RimEstimate | None:
    """Steps 2-5 of the module docstring for windows ``2 half`` long and ``depth`` deep."""
    length = float(arc[-1])
    # The offsets of samples within a window depth of an end are left out: past a corner of
    # at least 45 degrees they all lie inside the window depth of this side only. The
    # windows nearest the ends are cut short there, which leaves the offsets' distribution
    # as it is; their quadrics (heights) still use all samples of the window.
    margin = depth
    usable = length - 2.0 * margin
    if usable <= 0:
        return None
    count = max(int(np.floor(usable / (RIM_STEP * spacing))) + 1, least)
    station_arc = margin + np.arange(count) * (usable / max(count - 1, 1))
    if count == 1:
        station_arc = np.array([0.5 * length])
    # Samples near the reference: each with its nearest reference sample and arc position.
    reach = depth + 2.0 * spacing
    # Balls every reach / 2 along the reference, a little wider, cover the same tube as
    # balls at every reference sample (half a spacing apart) with ~8x fewer repeated hits.
    stride = max(1, int(0.5 * reach / max(float(arc[1] - arc[0]), 1e-300)))
    centres = np.vstack([ref[::stride], ref[-1:]])
    balls = tree.query_ball_point(centres, 1.04 * reach, workers=-1)
    near = np.unique(np.concatenate(balls).astype(np.int64))
    if not len(near):
        return None
    # The side's own sheet only: a thin lip's far side lies within the tube.
    near = near[one_sheet(points[near], ref, SHEET_LINK * spacing, SHEET_STRETCH * reach,
                          len(near) // 4)]
    p = points[near]
    _, k = cKDTree(ref).query(p)
    a = arc[k] + np.einsum("ij,ij->i", p - ref[k], tangent[k])
    inner = (a >= margin) & (a <= length - margin)
    # (station, point) pairs: every point in the windows covering its arc position.
    first = np.searchsorted(station_arc, a - half)
    last = np.searchsorted(station_arc, a + half)
    reps = last - first
    pt = np.repeat(np.arange(len(p)), reps)
    st = np.repeat(first, reps) + (np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps))
    q = np.stack([np.interp(station_arc, arc, ref[:, d]) for d in range(3)], axis=1)
    t = np.stack([np.interp(station_arc, arc, tangent[:, d]) for d in range(3)], axis=1)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    rel = p[pt] - q[st]
    normal = _window_normals(rel, st, count, t)
    outward = np.cross(t, normal)
    # Outward: away from the bulk of the window's points.
    side = np.bincount(st, weights=np.einsum("ij,ij->i", rel, outward[st]), minlength=count)
    outward[side > 0] *= -1.0
    # Curvilinear offset: from the nearest reference sample, in that station's outward sense.
    o_pt = outward[st] - np.einsum("ij,ij->i", outward[st], tangent[k[pt]])[:, None] * tangent[k[pt]]
    o_pt /= np.linalg.norm(o_pt, axis=1, keepdims=True)
    d = np.einsum("ij,ij->i", p[pt] - ref[k[pt]], o_pt)
    keep = d > -depth
    st, rel, d, use = st[keep], rel[keep], d[keep], inner[pt[keep]]
    n = np.bincount(st[use], minlength=count)
    ok = n >= MIN_WINDOW_POINTS
    if not ok.any():
        return None
    x = np.einsum("ij,ij->i", rel, t[st]) / half
    y = np.einsum("ij,ij->i", rel, outward[st]) / half
    h = np.einsum("ij,ij->i", rel, normal[st])
    coef, sigma = _quadrics(x, y, h, st, count)
    e, sampled = _rim_offsets(d[use], st[use], count, sigma, -depth)
    yy = e / half
    height = coef[:, 0] + coef[:, 2] * yy + coef[:, 5] * yy * yy
    rim = q + e[:, None] * outward + height[:, None] * normal
    # The rim lies about half a spacing (noise: a few sigmas) beyond the loop; a station
    # moved farther read a window that is no height field (a lip's crest within its depth).
    # The noise is the windows' median: a window reading its own misfit as noise would
    # excuse itself.
    noise = float(np.median(sigma[ok]))
    ok &= np.linalg.norm(rim - q, axis=1) <= max(RIM_MOST * spacing, NOISE_DEPTH * noise)
    if not ok.any():
        return None
    return RimEstimate(
        points=rim[ok], arc=np.asarray(station_arc[ok], dtype=np.float64), length=length, shift=e[ok], noise=sigma[ok],
        sampled=sampled[ok],
    )


def _window_normals(
    rel: NDArray[np.float64], st: NDArray[np.int64], count: int, tangent: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Unit surface normal per window: the least-spread PCA axis of its points, made
    orthogonal to the rim tangent."""
    mean = np.stack([np.bincount(st, weights=rel[:, i], minlength=count) for i in range(3)], 1)
    n = np.maximum(np.bincount(st, minlength=count), 1)[:, None]
    centred = rel - (mean / n)[st]
    cov = np.zeros((count, 3, 3))
    np.add.at(cov, st, centred[:, :, None] * centred[:, None, :])
    _, vec = np.linalg.eigh(cov + 1e-300 * np.eye(3))
    normal = vec[:, :, 0]
    normal -= np.einsum("ij,ij->i", normal, tangent)[:, None] * tangent
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def _quadrics(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    h: NDArray[np.float64],
    st: NDArray[np.int64],
    count: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least-squares ``h = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2`` per window.

    Returns the coefficients (count, 6) and the residual RMS (count,) with 6 degrees of
    freedom taken off (0 where a window has too few points).
    """
    design = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    gram = np.zeros((count, 6, 6))
    np.add.at(gram, st, design[:, :, None] * design[:, None, :])
    rhs = np.zeros((count, 6))
    np.add.at(rhs, st, design * h[:, None])
    n = np.bincount(st, minlength=count)
    scale = np.maximum(np.einsum("kii->k", gram), 1e-300)[:, None, None]
    # A tiny ridge keeps empty or degenerate windows solvable (they are dropped later).
    coef = np.linalg.solve(gram + 1e-12 * scale * np.eye(6), rhs[:, :, None])[:, :, 0]
    resid = h - np.einsum("ij,ij->i", design, coef[st])
    rss = np.bincount(st, weights=resid * resid, minlength=count)
    sigma = np.sqrt(rss / np.maximum(n - 6, 1))
    return coef, sigma


def _rim_offsets(
    d: NDArray[np.float64],
    st: NDArray[np.int64],
    count: int,
    sigma: NDArray[np.float64],
    cut: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Maximum-likelihood rim offset per window (step 4 of the module docstring), and
    whether the window's rim is a sampled row.

    The log-likelihood of ``e`` for the offsets ``d_i > cut`` of one window is
    ``sum_i log Phi((e - d_i) / sigma) - n log(e - cut)``; it is evaluated on a grid around
    the outermost offset and refined by a parabola through the best grid value and its
    neighbours, all windows at once (padded to the fullest window).
    """
    n = np.bincount(st, minlength=count)
    order = np.argsort(st, kind="stable")
    rank = np.arange(len(st)) - np.repeat(np.cumsum(n) - n, n)
    pad = np.full((count, max(int(n.max(initial=1)), 1)), np.nan)
    pad[st[order], rank] = d[order]
    dmax = np.nanmax(np.where(np.isnan(pad), -np.inf, pad), axis=1)
    dmax = np.where(np.isfinite(dmax), dmax, cut)
    nn = np.maximum(n, 1)
    gap = (dmax - cut) / nn  # the noise-free gap's mean, (e - c) / (n + 1) ~ (d_max - c) / n
    sig = np.maximum(sigma, 1e-9 * gap + 1e-300)
    lo = dmax - 4.0 * sig
    hi = dmax + 2.0 * sig + gap
    grid = np.linspace(0.0, 1.0, _GRID)[None, :] * (hi - lo)[:, None] + lo[:, None]  # (J, G)
    z = (grid[:, :, None] - pad[:, None, :]) / sig[:, None, None]
    ll = np.nansum(log_ndtr(z), axis=2) - nn[:, None] * np.log(np.maximum(grid - cut, 1e-300))
    best = np.clip(ll.argmax(axis=1), 1, _GRID - 2)
    rows = np.arange(count)
    f0, f1, f2 = (ll[rows, best + i] for i in (-1, 0, 1))
    denom = f0 - 2.0 * f1 + f2
    step = np.where(denom < 0, 0.5 * (f0 - f2) / np.where(denom < 0, denom, -1.0), 0.0)
    width = (hi - lo) / (_GRID - 1)
    mle = grid[rows, best] + np.clip(step, -1.0, 1.0) * width
    # Noise-free, the estimate is d_max and misses the mean gap; with noise the likelihood's
    # width ~ sigma exceeds the gap and the estimate is nearly unbiased.
    e = mle + gap * gap / np.sqrt(gap * gap + sigma * sigma)
    # A sampled rim (a grid's last row): several offsets within a tenth of the gap of d_max,
    # where random samples would put 0.1 on average. The rim is that row, not beyond it.
    top = np.nansum(pad >= (dmax - 0.1 * gap)[:, None], axis=1)
    sampled = (top >= SAMPLED_ROW) & (sigma < 0.1 * gap)
    return np.where(sampled, dmax, e), sampled


def surface_normal(
    points: NDArray[np.float64], tree: cKDTree, at: NDArray[np.float64], spacing: float
) -> NDArray[np.float64] | None:
    """Unit normal (3,) of the samples within ``RIM_WINDOW`` spacings of ``at`` (their
    least-spread PCA axis), or None with fewer than ``MIN_WINDOW_POINTS`` of them."""
    near = np.asarray(tree.query_ball_point(at, RIM_WINDOW * spacing), dtype=np.int64)
    if len(near) < MIN_WINDOW_POINTS:
        return None
    rel = points[near] - points[near].mean(axis=0)
    return np.linalg.eigh(rel.T @ rel)[1][:, 0]


def onto_surface(
    points: NDArray[np.float64], tree: cKDTree, at: NDArray[np.float64], spacing: float
) -> NDArray[np.float64]:
    """``at`` (3,) moved along the local normal onto the surface the samples near it show.

    A corner extrapolated from its two rims' tangent lines is right in the tangent plane but
    off the surface by the sagitta of a curved surface over the extrapolation; the quadric
    of the samples within ``RIM_WINDOW`` spacings (as for a station) gives its height.
    ``at`` is returned unchanged with fewer than ``MIN_WINDOW_POINTS`` samples there.
    """
    radius = RIM_WINDOW * spacing
    near = np.asarray(tree.query_ball_point(at, radius), dtype=np.int64)
    if len(near) < MIN_WINDOW_POINTS:
        return at
    rel = points[near] - at
    st = np.zeros(len(near), dtype=np.int64)
    _, vec = np.linalg.eigh((rel - rel.mean(axis=0)).T @ (rel - rel.mean(axis=0)))
    frame = vec[:, ::-1].T  # two tangent directions, then the normal
    x, y, h = (rel @ frame.T / np.array([radius, radius, 1.0])).T
    coef, _ = _quadrics(x, y, h, st, 1)
    return at + coef[0, 0] * frame[2]


#: Most uniform pieces of a rim side's spline (see :func:`fit_rim_spline`).
RIM_PIECES = 8
#: Rounds of parameter correction of a rim side's spline fit.
_SPLINE_ROUNDS = 3


def fit_rim_spline(
    run: NDArray[np.float64], start: NDArray[np.float64], end: NDArray[np.float64]
) -> tuple[PiecewiseBezier, float]:
    """A C2 cubic spline side through ordered rim points ``run`` (m, D), from ``start`` to
    ``end`` exactly, on 1..``RIM_PIECES`` uniform pieces: the count with the least Bayesian
    information criterion ``n log(RSS / (m D)) + k log n`` for ``k`` free control-point
    coordinates and ``n = m D / 2`` independent ones among the ``m D`` data (neighbouring
    stations share half their window, so their noise is correlated: with ``n = m D`` a
    noisy flag's sides took 3-6 pieces that followed it).

    A G1 chain of Béziers changes speed at its joints; a bilinear Coons patch blends the
    side across the whole patch, so a speed jump there draws a crease through the interior
    that no smooth deformation removes (a held-out wave: 2.8e-4 D inside against 7.7e-5 D
    for one-piece sides). A spline in one parameter is C2 there. The piece count is not
    set by a tolerance: rim points scatter more across the rim than in height, and a
    tolerance loose enough for that scatter let two pieces miss a wave's rim heights by
    half a spacing. Each fit is least squares on chord-length parameters, corrected
    ``_SPLINE_ROUNDS`` times by Newton steps to each point's closest parameter.

    Returns
    -------
    (PiecewiseBezier, largest distance of a rim point)
    """
    seg = np.linalg.norm(np.diff(run, axis=0), axis=1)
    s0 = np.concatenate([[0.0], np.cumsum(seg)]) / max(float(seg.sum()), 1e-300)
    count = run.size
    best: tuple[float, BSpline, NDArray[np.float64], float] | None = None
    for pieces in range(1, int(np.clip(len(run) - 3, 1, RIM_PIECES)) + 1):
        breaks = np.linspace(0.0, 1.0, pieces + 1)
        knots = np.concatenate([[0.0] * 3, breaks, [1.0] * 3])
        s = s0.copy()
        for _ in range(_SPLINE_ROUNDS):
            spline = _held_spline(run, s, knots, start, end)
            s = _closest_parameters(spline, run, s)
        miss = np.linalg.norm(spline(s) - run, axis=1)
        rss = max(float(miss @ miss), 1e-300 * count)
        score = 0.5 * count * np.log(rss / count) + (pieces + 1) * run.shape[1] * np.log(
            0.5 * count
        )
        if best is None or score < best[0]:
            best = score, spline, breaks, float(miss.max())
    assert best is not None
    _, spline, breaks, error = best
    values = spline(breaks)
    values[0], values[-1] = start, end
    side = PiecewiseBezier.from_hermite(values, spline.derivative()(breaks), breaks)
    return side, error


def _held_spline(
    run: NDArray[np.float64], s: NDArray[np.float64], knots: NDArray[np.float64],
    start: NDArray[np.float64], end: NDArray[np.float64],
) -> BSpline:
    """Least-squares cubic spline on ``knots`` through ``run`` at parameters ``s``, its end
    control points held at ``start`` and ``end``."""
    design = BSpline.design_matrix(np.clip(s, 0.0, 1.0), knots, 3).toarray()
    rhs = run - np.outer(design[:, 0], start) - np.outer(design[:, -1], end)
    inner = np.linalg.lstsq(design[:, 1:-1], rhs, rcond=None)[0]
    return BSpline(knots, np.vstack([start, inner, end]), 3)


def _closest_parameters(
    spline: BSpline, run: NDArray[np.float64], s: NDArray[np.float64]
) -> NDArray[np.float64]:
    """One Newton step of every point's parameter towards its closest spline point (the
    corners keep 0 and 1)."""
    rel = spline(s) - run
    d1, d2 = spline.derivative(1)(s), spline.derivative(2)(s)
    slope = np.einsum("ij,ij->i", rel, d1)
    curve = np.einsum("ij,ij->i", d1, d1) + np.einsum("ij,ij->i", rel, d2)
    out = np.clip(s - slope / np.where(curve > 0, curve, np.inf), 0.0, 1.0)
    out[0], out[-1] = 0.0, 1.0
    return np.maximum.accumulate(out)
