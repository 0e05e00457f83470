"""Binary image -> outline drawing: the whole of thesis Chapter 3.

Pipeline: threshold -> pixel-boundary loops with nesting -> corners -> per loop, optional
symmetry (fit the fundamental part, map the curves) -> least-squares cubics with bisection
break points, per-piece optimal parameterization and G1 joins -> :class:`Drawing`.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.curves import bezier
from pde2cad.curves.distance import nearest, points_to_curves
from pde2cad.curves.fit import NEWTON_ROUNDS, CubicFit
from pde2cad.curves.merge import merge_closed
from pde2cad.curves.parameterize import METHODS
from pde2cad.curves.piecewise import (
    PIECE_ROUNDS, SAFETY, ChainFit, DeadlineExceeded, clear_fit_cache, corner_positions, denoise, fit_chain, fit_closed,
    fit_closed_free, line_chain,
)
from pde2cad.errors import InputError
from pde2cad.image.contours import ContourLoop, trace_loops
from pde2cad.image.corners import CORNER_ANGLE, CORNER_SCALE, detect_corners
from pde2cad.image.drawing import Drawing, OutlineLoop
from pde2cad.image.raster import read_image, to_mask

# A symmetric outline may be this many curves longer than the plain fit of the loop, or
# longer by as many curves as its fitted part saves (see _written_limit).
_SYMMETRY_GROWTH = 1
# Symmetry detection: a coarse IoU screen, then the boundary test within the tolerance;
# rotation orders up to this (gears have many teeth).
_SYMMETRY_IOU = 0.85
_SYMMETRY_MAX_ORDER = 24
# The symmetry search may take this many times the plain fit's CPU time (plus a floor, s),
# checked between candidates.
_SYMMETRY_TIME = 5.0
_SYMMETRY_MIN_S = 0.5
# Crossing curves at most this many apart in a loop are replaced by the crack polygon
# between them, in at most this many rounds per loop.
_PATCH_SPAN = 3
_PATCH_ROUNDS = 20
# How many symmetry candidates (best saving first) get a fit of their fundamental part.
_SYMMETRY_CANDIDATES = 3
# Loops smaller than this are not worth a symmetry search.
_SYMMETRY_MIN_POINTS = 40
#: Most boundary edges (unit cracks) an image may have: tracing costs ~150 bytes per edge,
#: so this keeps the trace under ~3 GB whatever the image size.
MAX_EDGES = 20_000_000
# A lower bound of the fitting time per boundary point (seconds), measured on this
# project's slowest-to-fastest images (~60-400 us per point): used only to refuse, before
# any work, an image that cannot finish within ``max_seconds``.
_SECONDS_PER_POINT = 2e-5


def vectorize(
    image: str | Path | NDArray[Any],
    tolerance: float = 1.0,
    *,
    threshold: float | None = None,
    invert: bool = False,
    symmetry: bool = True,
    g1: bool = True,
    parameterization: str = "optimal",
    corner_angle: float = CORNER_ANGLE,
    dpi: float | None = None,
    scale: float | None = None,
    min_area: int = 2,
    max_seconds: float | None = None,
) -> Drawing:
    """Vectorize the boundary of a binary image into cubic Béziers.

    Parameters
    ----------
    image : path or (H, W) / (H, W, C) array
        PNG, BMP, PBM/PGM, JPEG or TIFF file, or an array (bool arrays are used as they are).
    tolerance : float
        Maximum distance in pixels from the pixel boundary to the curves (> 0).
    threshold : float, optional
        Grey level 0..255 separating foreground (dark) from background; Otsu by default.
    invert : bool
        Light pixels are the foreground.
    symmetry : bool
        Fit only the fundamental part of mirror- or rotation-symmetric loops when that saves
        curves within the tolerance.
    g1 : bool
        Tangent-continuous joins where a break point is not a corner (default).
    parameterization : str
        "optimal" (per piece the best of uniform, chord, centripetal, Foley) or one of them.
    corner_angle : float
        Minimum turn in degrees (over 4 px) for a corner.
    dpi, scale : float, optional
        Physical size: dots per inch, or millimetres per pixel (give at most one).
    min_area : int
        Drop specks and fill holes of at most this many pixels (potrace's turdsize,
        default 2); 0 keeps everything. ``Drawing.specks`` counts the loops dropped.
    max_seconds : float, optional
        Stop with :class:`FitError` when the image cannot be done in this time (checked
        before tracing from the boundary length, and between and inside loop fits).

    Returns
    -------
    Drawing

    Raises
    ------
    InputError
        Bad options, no foreground, or a boundary longer than :data:`MAX_EDGES`.
    FitError
        ``max_seconds`` exceeded.
    """
    started = time.perf_counter()
    deadline = None if max_seconds is None else started + float(max_seconds)
    if not (isinstance(min_area, (int, np.integer)) and min_area >= 0):
        raise InputError(f"min_area must be an integer >= 0 (pixels), got {min_area!r}; try 2")
    if max_seconds is not None and not (np.isfinite(max_seconds) and max_seconds > 0):
        raise InputError(f"max_seconds must be > 0, got {max_seconds!r}")
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be a number > 0 (pixels), got {tolerance!r}; try 1.0")
    if parameterization != "optimal" and parameterization not in METHODS:
        raise InputError(
            f"unknown parameterization {parameterization!r}; use optimal, " + ", ".join(METHODS)
        )
    if not 0 < corner_angle < 180:
        raise InputError(f"corner angle must be in (0, 180) degrees, got {corner_angle}")
    mm_per_px = _scale(dpi, scale)
    if isinstance(image, (str, Path)):
        mask = read_image(image, threshold=threshold, invert=invert)
        name = str(image)
    else:
        mask = to_mask(image, threshold=threshold, invert=invert)
        name = "the image"
    if not mask.any():
        raise InputError(
            f"{name} has no foreground pixels after thresholding; "
            "check --threshold or use --invert for light shapes on a dark background"
        )
    _check_size(mask, name, max_seconds)
    contours, specks = despeckle(trace_loops(mask), min_area)
    budget = None if max_seconds is None else max_seconds - (time.perf_counter() - started)
    if budget is not None and sum(len(c.points) for c in contours) * _SECONDS_PER_POINT > budget:
        raise _too_slow(name, max_seconds)
    loops = []
    clear_fit_cache()
    try:
        for c in contours:
            if deadline is not None and time.perf_counter() > deadline:
                raise DeadlineExceeded("past the deadline between loops")
            loops.append(_fit_loop(c, tolerance, symmetry, g1, parameterization, corner_angle, deadline))
    except DeadlineExceeded:
        raise _too_slow(name, max_seconds) from None
    finally:
        clear_fit_cache()
    return Drawing(
        width=int(mask.shape[1]),
        height=int(mask.shape[0]),
        loops=loops,
        tolerance=float(tolerance),
        mm_per_px=mm_per_px,
        time_s=time.perf_counter() - started,
        specks=specks,
    )


def despeckle(contours: list[ContourLoop], min_area: int) -> tuple[list[ContourLoop], int]:
    """Drop the loops enclosing at most ``min_area`` pixels (potrace's turdsize).

    Steps: 1. only loops of at most 4 * min_area vertices can enclose that little (an
    8-connected shape of A pixels has at most 4A boundary edges); 2. their shoelace areas
    are computed per group of equal length, all loops of a group at once; 3. a dropped outer
    loop removes a speck, a dropped hole fills it (the holes of a dropped speck are smaller
    still, so they go with it).

    Returns
    -------
    (kept loops, number dropped)
    """
    if min_area <= 0:
        return contours, 0
    sizes = np.fromiter((len(c.points) for c in contours), dtype=np.int64, count=len(contours))
    drop = np.zeros(len(contours), bool)
    for size in np.unique(sizes[sizes <= 4 * min_area]):
        group = np.flatnonzero(sizes == size)
        pts = np.stack([contours[i].points for i in group])  # (m, size, 2)
        nxt = np.roll(pts, -1, axis=1)
        area = 0.5 * (pts[..., 0] * nxt[..., 1] - nxt[..., 0] * pts[..., 1]).sum(axis=1)
        drop[group] = np.abs(area) <= min_area
    kept = [c for c, d in zip(contours, drop.tolist()) if not d]
    return kept, int(drop.sum())


def _check_size(mask: NDArray[np.bool_], name: str, max_seconds: float | None) -> None:
    """Refuse, before tracing, a mask whose boundary is too long to trace in bounded memory.

    Counts the cracks between foreground and background in row blocks (no full-size
    temporary beyond one block).
    """
    edges = 0
    rows = max(1, (1 << 22) // max(mask.shape[1], 1))
    for r in range(0, mask.shape[0], rows):
        block = mask[r : r + rows + 1]
        edges += int(np.count_nonzero(block[:-1] != block[1:])) if len(block) > 1 else 0
        own = mask[r : r + rows]
        edges += int(np.count_nonzero(own[:, 1:] != own[:, :-1])) + int(own[:, 0].sum() + own[:, -1].sum())
    edges += int(mask[0].sum() + mask[-1].sum())
    if edges > MAX_EDGES:
        raise InputError(
            f"{name} has {edges:,} boundary edges, more than the limit of {MAX_EDGES:,} "
            "(the trace would need several GB); this is noise rather than a drawing: "
            "blur or downscale the image, or raise --threshold/--invert so that only the shapes remain"
        )


def _too_slow(name: str, max_seconds: float | None):
    from pde2cad.errors import FitError

    return FitError(
        f"vectorizing {name} would take more than --max-seconds {max_seconds:g} s; raise the "
        "limit, despeckle more (--min-area) or downscale the image"
    )


def _flag_lines(curves: NDArray[np.float64], slack: float) -> tuple[NDArray[np.float64], list[bool]]:
    """Replace the cubics that lie within ``slack`` of their chord by the chord, flagged.

    A cubic lies in the hull of its control points, so its distance to the chord is at most
    that of p1 and p2, and the chord is as close to the cubic: moving to the chord changes
    both directed distances to the pixel boundary by at most ``slack``.
    """
    if slack <= 0 or not len(curves):
        return curves, [False] * len(curves)
    p0, p3 = curves[:, 0], curves[:, 3]
    d = p3 - p0
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-24)
    dev = np.zeros(len(curves))
    for i in (1, 2):
        t = np.clip(np.sum((curves[:, i] - p0) * d, axis=1) / length2, 0.0, 1.0)
        dev = np.maximum(dev, np.linalg.norm(curves[:, i] - (p0 + t[:, None] * d), axis=1))
    flat = dev <= slack
    out = curves.copy()
    out[flat, 1] = p0[flat] + d[flat] / 3.0
    out[flat, 2] = p0[flat] + 2.0 * d[flat] / 3.0
    return out, flat.tolist()


def _scale(dpi: float | None, scale: float | None) -> float | None:
    if dpi is not None and scale is not None:
        raise InputError("give either dpi or scale (mm per pixel), not both")
    if dpi is not None:
        if not (np.isfinite(dpi) and dpi > 0):
            raise InputError(f"dpi must be > 0, got {dpi}")
        return 25.4 / float(dpi)
    if scale is not None:
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"scale must be > 0 mm per pixel, got {scale}")
        return float(scale)
    return None


def _fit_loop(
    contour: ContourLoop, tol: float, symmetry: bool, g1: bool, method: str, corner_angle: float,
    deadline: float | None = None,
) -> OutlineLoop:
    """One loop's outline. Steps: 1. the plain fit (:func:`_plain_fit`) and its untangling,
    refitted with converged pieces where crack lines were patched in
    (:func:`_fewer_crack_lines`); 2. the symmetric fit where it saves curves; 3. the
    untangled curves, or the fitted ones when nothing crossed."""
    pts = contour.points
    corners = detect_corners(pts, angle=corner_angle)
    begun = time.thread_time()
    chain = _plain_fit(pts, corners, tol, g1, method, deadline, PIECE_ROUNDS)
    plain_s = time.thread_time() - begun  # CPU time: a loaded machine does not change it
    chain, untangled = _fewer_crack_lines(pts, corners, tol, g1, method, deadline, chain)
    curves, methods, n_corners = chain.curves, chain.methods, len(chain.corners)
    max_err, mean_err = chain.max_error, chain.mean_error
    is_line = list(chain.lines) or [False] * len(curves)
    sym_name = None
    fitted = len(curves)
    if symmetry and len(pts) >= _SYMMETRY_MIN_POINTS and len(curves) > 1:
        found = _search_symmetric(pts, corners, tol, g1, method, len(curves), plain_s, deadline)
        taken = None if found is None else _symmetric_outline(pts, found, tol)
        if taken is not None:
            curves, methods, n_corners, max_err, mean_err, sym_name, fitted, is_line = taken
            untangled = _untangle(pts, _close_gaps(curves), is_line, tol)
    curves = _close_gaps(curves)
    if untangled is not None:
        curves, is_line, max_err, mean_err = untangled
        if sym_name is None:
            fitted = len(curves)  # crack-polygon lines are independent curves too
        if len(methods) != len(curves):
            methods = ["crack"] * len(curves)
    return OutlineLoop(
        curves=curves,
        is_hole=contour.is_hole,
        shape=contour.shape,
        depth=contour.depth,
        max_error=float(max_err),
        mean_error=float(mean_err),
        parameterizations=list(methods),
        corners=int(n_corners),
        symmetry=sym_name,
        fitted_curves=int(fitted),
        is_line=is_line,
    )


def _plain_fit(
    pts: NDArray[np.float64], corners: NDArray[np.int64], tol: float, g1: bool, method: str,
    deadline: float | None, rounds: int,
) -> ChainFit:
    """A loop's fit without symmetry, its pieces fitted with ``rounds`` Levenberg-Marquardt
    rounds. Steps: 1. :func:`fit_closed` with the corners as forced breaks; 2. with G1, the
    fit with only straight sides' corners forced (or none), kept where it has fewer pieces
    (on noisy outlines the corners-forced fit can be far cheaper); 3. neighbouring pieces
    merged (:func:`merge_closed`; straight sides are lines spanning both chords of the
    corner test)."""
    chain, offset = fit_closed(pts, tol, corners=corners, g1=g1, method=method, deadline=deadline, rounds=rounds)
    hard = _straight_side_corners(pts, corners, tol) if g1 else corners
    if len(hard) < len(corners) and len(chain.fits) > 1:
        if hard.size:
            soft, at = fit_closed(pts, tol, corners=hard, method=method, deadline=deadline, soft_corners=corners,
                                  rounds=rounds)
        else:
            soft, at = fit_closed_free(pts, tol, corners=corners, method=method, deadline=deadline, rounds=rounds)
        if len(soft.fits) < len(chain.fits):
            chain, offset = soft, at
    chain, _ = merge_closed(chain, pts, offset, tol, param_points=denoise(pts, closed=True)[0],
                            method=method, deadline=deadline, side=2.0 * CORNER_SCALE, rounds=rounds)
    return chain


def _fewer_crack_lines(
    pts: NDArray[np.float64], corners: NDArray[np.int64], tol: float, g1: bool, method: str,
    deadline: float | None, chain: ChainFit,
) -> tuple[ChainFit, tuple[NDArray[np.float64], list[bool], float, float] | None]:
    """The plain fit and its untangling (:func:`_untangle`), the fit redone with converged
    pieces where untangling patched crack-polygon lines in.

    Steps: 1. untangle ``chain``; 2. if that made the loop longer (pieces of the break
    search's few rounds, :data:`PIECE_ROUNDS`, looped or crossed and their span became
    crack lines), fit the loop again with :data:`NEWTON_ROUNDS` (converged pieces bend
    less freely at their ends) and untangle that; 3. keep the shorter untangled loop (the
    first on ties).
    """
    lines = list(chain.lines) or [False] * len(chain.curves)
    untangled = _untangle(pts, _close_gaps(chain.curves), lines, tol)
    if untangled is None or len(untangled[0]) <= len(chain.curves):
        return chain, untangled
    again = _plain_fit(pts, corners, tol, g1, method, deadline, NEWTON_ROUNDS)
    lines = list(again.lines) or [False] * len(again.curves)
    redone = _untangle(pts, _close_gaps(again.curves), lines, tol)
    if len(again.curves if redone is None else redone[0]) < len(untangled[0]):
        return again, redone
    return chain, untangled


def _symmetric_outline(pts: NDArray[np.float64], found: tuple, tol: float) -> tuple | None:
    """The symmetric fit with its straight curves flagged; None when its curves cross so
    that :func:`_untangle` would patch crack lines in (the outline would no longer be
    symmetric, and can grow by hundreds of lines: a small snowflake's arms)."""
    curves, methods, n_corners, max_err, mean_err, sym_name, fitted = found
    curves, is_line = _flag_lines(curves, tol * SAFETY - max_err)
    if any(is_line):
        errors = points_to_curves(pts, curves)
        max_err, mean_err = float(errors.max()), float(errors.mean())
    untangled = _untangle(pts, _close_gaps(curves), is_line, tol)
    if untangled is not None and len(untangled[0]) != len(curves):
        return None
    return curves, methods, n_corners, max_err, mean_err, sym_name, fitted, is_line


def _close_gaps(curves: NDArray[np.float64]) -> NDArray[np.float64]:
    """Make every curve start exactly where the previous one ends.

    ``fit_closed`` can return a loop with a join open by up to half a pixel (5 of 141
    loops of matplotlib's grace_hopper.jpg thresholded), which no CAD wire accepts. Both
    ends move to their midpoint, each with its neighbouring control point, so the end
    tangents keep their directions; the error is measured again afterwards by callers
    that trim, and the move is at most half the gap.
    """
    nxt = np.roll(curves, -1, axis=0)
    gap = nxt[:, 0] - curves[:, 3]
    open_ = np.linalg.norm(gap, axis=1) > 1e-9
    if not open_.any():
        return curves
    out = curves.copy()
    half = 0.5 * gap * open_[:, None]
    out[:, 2:] += half[:, None, :]
    idx = (np.arange(len(curves)) + 1) % len(curves)
    out[idx, :2] -= half[:, None, :]
    return out


def _untangle(
    pts: NDArray[np.float64], curves: NDArray[np.float64], is_line: list[bool], tol: float,
) -> tuple[NDArray[np.float64], list[bool], float, float] | None:
    """Remove the crossings of a loop's curves with each other; None if there are none.

    Steps: 1. trim each crossing of consecutive curves (tiny loops at sharp corners;
    :func:`pde2cad.image.crossings.trim_corner_crossings` holds the boundary within
    ``tol`` near the corner); 2. a crossing left (a curve looping on itself, or curves at
    most :data:`_PATCH_SPAN` apart) has its span of curves replaced by the crack polygon
    between their ends, as lines (exact; lines from the curve ends to the polygon),
    repeated while that removes crossings; 3. what still crosses is kept (a face of it
    may fail: :func:`pde2cad.occ.drawing.drawing_faces` says which); 4. if the result is
    not within ``tol`` of the crack vertices and edge midpoints, the loop stays as fitted.
    """
    from pde2cad.image.crossings import find_crossings, trim_corner_crossings

    # Held at the crack edges' midpoints too, with the fitter's safety margin.
    crack = np.vstack([pts, 0.5 * (pts + np.roll(pts, -1, axis=0))])
    trimmed, fixed, left = trim_corner_crossings(curves, crack, tol * SAFETY)
    if fixed + left == 0:
        return None
    lines = list(is_line)
    for _ in range(_PATCH_ROUNDS if left else 0):
        k = len(trimmed)
        pairs = [(c.a, c.b) if (c.b - c.a) % k <= k // 2 else (c.b, c.a) for c in find_crossings([trimmed])]
        spans = [(a, b) for a, b in pairs if (b - a) % k <= _PATCH_SPAN]
        if not spans or (spans[0][1] - spans[0][0]) % k + 1 >= k - 1:
            break  # nothing short to patch, or the patch would be the whole loop
        trimmed, lines = _crack_patch(pts, trimmed, lines, *spans[0])
    errors = points_to_curves(crack, trimmed)
    if errors.max() > tol * SAFETY:
        return None  # never trade accuracy for validity: keep the fit as it was
    errors = errors[: len(pts)]
    return trimmed, lines, float(errors.max()), float(errors.mean())


def _crack_patch(
    pts: NDArray[np.float64], curves: NDArray[np.float64], is_line: list[bool], first: int, last: int,
) -> tuple[NDArray[np.float64], list[bool]]:
    """Curves ``first..last`` (cyclic) replaced by lines along the crack polygon ``pts``."""
    n = len(pts)
    k = len(curves)
    order = (first + np.arange(k)) % k  # rotate so that the span starts the loop
    curves, is_line = curves[order], [is_line[i] for i in order]
    span = (last - first) % k + 1
    a, b = curves[0, 0], curves[span - 1, 3]
    i0 = int(np.argmin(np.sum((pts - a) ** 2, axis=1)))
    i1 = int(np.argmin(np.sum((pts - b) ** 2, axis=1)))
    run = pts[(i0 + np.arange((i1 - i0) % n + 1)) % n]
    step = np.diff(run, axis=0)
    turn = np.flatnonzero(np.any(step[1:] != step[:-1], axis=1)) + 1
    verts = np.vstack([a, run[0], run[turn], run[-1], b])
    keep = np.r_[True, np.linalg.norm(np.diff(verts, axis=0), axis=1) > 1e-6]
    verts = verts[keep]
    p, q = verts[:-1], verts[1:]
    patch = np.stack([p, p + (q - p) / 3.0, p + 2.0 * (q - p) / 3.0, q], axis=1)
    return np.concatenate([patch, curves[span:]]), [True] * len(patch) + is_line[span:]


def _search_symmetric(
    pts: NDArray[np.float64], corners: NDArray[np.int64], tol: float, g1: bool, method: str,
    plain: int, plain_s: float, deadline: float | None,
) -> tuple | None:
    """:func:`_fit_symmetric`, its candidates tried while their CPU time stays within
    :data:`_SYMMETRY_TIME` times the plain fit's (plus :data:`_SYMMETRY_MIN_S`).

    CPU time of this thread, and checked between candidates only, so the outcome does not
    depend on the machine's load (a wall-clock deadline inside the part fits cut them short
    on a loaded machine: a cog and a bean lost their symmetry). Past the caller's own
    ``deadline`` the error propagates.
    """
    try:
        return _fit_symmetric(pts, corners, tol, g1, method, plain, plain_s, deadline)
    except DeadlineExceeded:
        if deadline is not None and time.perf_counter() > deadline:
            raise
        return None


def _straight_side_corners(pts: NDArray[np.float64], corners: NDArray[np.int64], tol: float) -> NDArray[np.int64]:
    """The corners at either end of a straight side: a run between consecutive corners at
    least ``2 * CORNER_SCALE`` long (the span of the corner test) whose points lie within
    the tolerance of its chord. Those stay crisp; the other corners of a jagged raster
    (level sets, small glyphs) are often turns one cubic follows within the tolerance."""
    n = len(pts)
    if len(corners) < 2:
        return np.arange(0)
    hard: list[int] = []
    for a, b in zip(corners, np.r_[corners[1:], corners[0] + n]):
        run = pts[np.arange(a, b + 1) % n]
        if np.linalg.norm(run[-1] - run[0]) >= 2 * CORNER_SCALE and line_chain(run, run[0], run[-1], tol) is not None:
            hard.extend((int(a), int(b) % n))
    return np.unique(np.asarray(hard, dtype=np.int64))


def _fit_symmetric(
    pts: NDArray[np.float64], corners: NDArray[np.int64], tol: float, g1: bool, method: str, plain: int,
    plain_s: float = np.inf, deadline: float | None = None,
) -> tuple | None:
    """Fit the fundamental part of the best symmetry that saves curves; None if none does.

    A symmetric loop is stored as its fitted part plus the transform (Section 3.1): it
    "saves curves" when the fitted part has fewer curves than the plain fit of the whole
    loop, and it is only taken when the written outline (part + mapped copies) stays within
    :func:`_written_limit` of the plain one (an exactly symmetric outline with fewer
    independent curves is worth that much to a user who edits it) and within the tolerance
    of the real boundary everywhere, both ways; else the plain fit stays.
    Steps: 0. the cheap screen :func:`could_be_symmetric`; 1. candidates from
    :func:`detect_symmetry`; 2. the boundary test
    (:func:`_symmetry_gap`); 3. the corners every copy shares; 4. the pooled part fit.
    """
    from pde2cad.image.symmetry import could_be_symmetric, detect_symmetry

    limit = 2.0 * tol * SAFETY + 0.5  # two staircases within tol of one curve
    if not could_be_symmetric(pts, limit, _SYMMETRY_MAX_ORDER):
        return None  # ~1 ms: most loops of a thresholded photo stop here
    found = detect_symmetry(pts, corners=corners, iou_min=_SYMMETRY_IOU, max_order=_SYMMETRY_MAX_ORDER)
    budget_end = time.thread_time() + _SYMMETRY_TIME * plain_s + _SYMMETRY_MIN_S
    # Candidates come best saving first, those with at most one copy per plain curve
    # ahead (only they can write at most _SYMMETRY_GROWTH more curves). The first that
    # passes that test is kept, else the one writing the fewest; only the first few of
    # each group are tried (each costs a fit of its fundamental part).
    copies = lambda s: 2 if s.kind == "mirror" else s.order  # noqa: E731
    best = None
    tries = [0, 0]
    for sym in sorted(found, key=lambda s: copies(s) > plain):
        group = int(copies(sym) > plain)
        if best is not None and len(best[0]) <= plain + _SYMMETRY_GROWTH:
            break
        if tries[group] == _SYMMETRY_CANDIDATES or copies(sym) > _written_limit(plain, 1):
            continue
        if _symmetry_gap(pts, sym) > limit:
            continue
        if sum(tries) and time.thread_time() > budget_end:
            break  # the first candidate always runs to its end
        tries[group] += 1
        fit = _try_symmetry(pts, corners, sym, tol, g1, method, plain, limit, deadline)
        if fit is not None and (best is None or len(fit[0]) < len(best[0])):
            best = fit
    return best


def _try_symmetry(pts, corners, sym, tol: float, g1: bool, method: str, plain: int, limit: float,
                  deadline: float | None) -> tuple | None:
    """The outline of one symmetry's pooled part fit, or None when it is not cheaper in
    independent curves, writes too many, or misses the loop by more than the tolerance."""
    from pde2cad.image.symmetry import fundamental_split

    copies = 2 if sym.kind == "mirror" else sym.order
    shared = _shared_corners(pts, corners, sym, limit)
    i0, i1 = fundamental_split(pts, sym, corners=shared if shared.size else None)
    part = _fit_part(pts, shared, sym, i0, i1, tol, g1, method, plain, deadline)
    if part is None:
        return None
    chain, full, part_corners = part
    if len(full) > _written_limit(plain, len(chain.curves)) or len(chain.curves) >= plain:
        return None
    # The edge midpoints too: the pooled fit saw other copies' points between this loop's
    # vertices, not its edges (a 20-tooth gear missed an edge midpoint by 1.14 px).
    errors = points_to_curves(np.vstack([pts, 0.5 * (pts + np.roll(pts, -1, axis=0))]), full)
    if errors.max() > tol * SAFETY or not _curves_near_loop(full, pts, tol * SAFETY):
        return None
    errors = errors[: len(pts)]
    name = "mirror" if sym.kind == "mirror" else f"rotation:{sym.order}"
    return (full, chain.methods * copies, part_corners * copies,
            float(errors.max()), float(errors.mean()), name, len(chain.curves))


def _symmetry_gap(pts: NDArray[np.float64], sym) -> float:
    """:func:`~pde2cad.image.symmetry.boundary_gap` of ``sym`` and, for a rotation of order
    k, of its power k // 2: a rotation by 2 pi / 19 maps a 20-tooth gear within a pixel of
    itself (0.017 rad off), but nine of them miss it by a third of a tooth.
    """
    from pde2cad.image.symmetry import Symmetry, boundary_gap

    gap = boundary_gap(pts, sym)
    if sym.kind != "rotation" or sym.order < 4:
        return gap
    power = np.linalg.matrix_power(sym.matrix, sym.order // 2)
    far = Symmetry("rotation", power, sym.center, sym.order, None, sym.iou)
    return max(gap, boundary_gap(pts, far))


def _written_limit(plain: int, fitted: int) -> int:
    """Most curves a symmetric outline of ``fitted`` independent curves may write for a loop
    whose plain fit has ``plain``: ``plain + _SYMMETRY_GROWTH``, or as many more as the part
    saves (written + fitted <= 2 plain). A rotation by 2 pi / k is no symmetry of the pixel
    grid, so the part must hold every copy's staircase within the tolerance and needs more
    curves per turn than the plain fit; a smooth star then writes more curves than it fits.
    """
    return max(plain + _SYMMETRY_GROWTH, 2 * plain - fitted)


def _shared_corners(pts: NDArray[np.float64], corners: NDArray[np.int64], sym, reach: float) -> NDArray[np.int64]:
    """The corners whose images under every power of ``sym`` land within ``reach`` of a corner.

    Off the pixel grid each copy is a different staircase, so the corner test fires on
    some copies only (a smooth star's tips); a corner forced into the fundamental part is
    forced into every copy, where it bends a curve off that copy's pixels.
    """
    if corners.size == 0:
        return corners
    where = pts[corners]
    keep = np.ones(len(corners), bool)
    image = where
    for _ in range(1 if sym.kind == "mirror" else sym.order - 1):
        image = sym.apply(image)
        gap = np.linalg.norm(image[:, None, :] - where[None, :, :], axis=2).min(axis=1)
        keep &= gap <= reach
    return corners[keep]


def _corner_tips(pts: NDArray[np.float64], corners: NDArray[np.int64], sym, tol: float) -> dict[int, NDArray[np.float64]]:
    """Where each corner's curves end: the sharpened corner for an exact pixel symmetry,
    else the corner vertex averaged with its copies' nearest corners mapped back.

    A tip sharpened on one copy's staircase extrapolates that copy's raster; mapped onto
    a copy that is a different staircase it can land over a pixel off it (star tips).
    """
    from pde2cad.image.symmetry import boundary_gap

    if corners.size == 0:
        return {}
    if boundary_gap(pts, sym) < 1e-9:
        return dict(zip(corners.tolist(), corner_positions(pts, corners, max_shift=0.75 * tol)))
    where = pts[corners]
    total, image = where.copy(), where
    powers = 1 if sym.kind == "mirror" else sym.order - 1
    for j in range(1, powers + 1):
        image = sym.apply(image)
        back = where[nearest(where, image)[1]]
        for _ in range(j):
            back = sym.inverse().apply(back)
        total += back
    return dict(zip(corners.tolist(), total / (powers + 1)))


def _fit_part(pts, corners, sym, i0: int, i1: int, tol: float, g1: bool, method: str, plain: int,
              deadline: float | None = None):
    """Fit the run i0..i1 with exact end points on the symmetry and map it around."""
    n = len(pts)
    length = (i1 - i0) % n
    if length < 4:
        return None
    idx = (i0 + np.arange(length + 1)) % n
    run = pts[idx]
    near = lambda i: corners.size > 0 and np.min(np.abs((corners - i + n // 2) % n - n // 2)) <= 2  # noqa: E731
    pos, tan = denoise(run, closed=False)
    c_start, c_end = near(i0), near(i1)
    # The same sharpened corner points as the plain fit (corners between straight sides).
    tips = _corner_tips(pts, corners, sym, tol)
    if sym.kind == "mirror":
        axis, center = sym.axis, sym.center
        p_start = center + np.dot(run[0] - center, axis) * axis
        p_end = center + np.dot(run[-1] - center, axis) * axis
        normal = np.array([-axis[1], axis[0]])
        t_start = None if c_start else normal * np.sign(np.dot(normal, tan[0]) or 1.0)
        t_end = None if c_end else normal * np.sign(np.dot(normal, tan[-1]) or 1.0)
    else:
        p_start = tips.get(int(i0), run[0]) if c_start else pos[0]
        p_end = sym.apply(p_start)
        t_start = None if c_start else tan[0]
        t_end = None if c_start else sym.matrix @ tan[0]
    local = np.sort(((corners - i0) % n)[((corners - i0) % n) <= length]) if corners.size else np.arange(0)
    local = local[(local > 2) & (local < length - 2)]
    merged, cuts, copies = _pooled_run(pts, sym, i0, i1, run, local)
    # Past this the outline grows too much (each junction may still merge two lines).
    budget = min(plain - 1, max((plain + _SYMMETRY_GROWTH + copies) // copies, (2 * plain + copies) // (copies + 1)))
    cut_points = [tips[int((i0 + c) % n)] for c in local] if len(cuts) == len(local) else None
    chain, over = _fit_run(merged, cuts, tol, p_start, p_end, t_start, t_end, g1, method, copies, budget,
                           cut_points, deadline)
    if chain is None and not over and (cut_points or (c_start and sym.kind != "mirror")):
        # Sharpened tips come from this part's own raster; the other parts' rasters can
        # disagree (non-grid rotations), so retry on the corner points themselves.
        if sym.kind != "mirror" and c_start:
            p_start = run[0]
            p_end = sym.apply(p_start)
        chain, _ = _fit_run(merged, cuts, tol, p_start, p_end, t_start, t_end, g1, method, copies, budget,
                            None, deadline)
    if chain is None:
        return None
    if sym.kind == "mirror":
        mirrored = sym.apply(chain.curves)[::-1, ::-1]
        full = np.concatenate([chain.curves, mirrored])
    else:
        copies = [chain.curves]
        for _ in range(sym.order - 1):
            copies.append(sym.apply(copies[-1]))
        full = np.concatenate(copies)
    full = _merge_junction_lines(full, len(chain.curves), 0.25 * tol)
    part_corners = len(local) + (1 if c_start else 0)
    return chain, full, part_corners


def _merge_junction_lines(full: NDArray[np.float64], m: int, slack: float) -> NDArray[np.float64]:
    """Join the two straight curves that meet at every junction between mapped parts.

    A straight edge crossing a mirror axis (the bar of an H) is fitted as two halves;
    when both curves at every junction lie within ``slack`` of the chord from the first's
    start to the second's end, each pair becomes one straight cubic. All junctions are
    congruent, so either all merge (the outline stays exactly symmetric) or none.

    Parameters
    ----------
    full : (K, 4, 2) float
        The closed outline, parts of ``m`` curves each.
    """
    k = len(full) // m
    if k < 2 or m < 2:
        return full
    ends = np.arange(1, k + 1) * m - 1  # last curve of each part
    nxt = (ends + 1) % len(full)
    a, b = full[ends, 0], full[nxt, 3]
    d = b - a
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-24)[:, None]
    ctrl = np.concatenate([full[ends], full[nxt]], axis=1)  # (k, 8, 2)
    t = np.clip(np.sum((ctrl - a[:, None]) * d[:, None], axis=2) / length2, 0.0, 1.0)
    dev = np.linalg.norm(ctrl - (a[:, None] + t[..., None] * d[:, None]), axis=2).max(axis=1)
    if dev.max() > slack:
        return full
    line = np.stack([a, a + d / 3.0, a + 2.0 * d / 3.0, b], axis=1)
    out = full.copy()
    out[ends] = line
    keep = np.ones(len(full), bool)
    keep[nxt] = False
    return out[keep]


def _pooled_run(pts, sym, i0: int, i1: int, run, local):
    """The fundamental run with every other part mapped back onto it, ordered along it.

    A rotation by 2 pi / k (or a tilted mirror) is no symmetry of the pixel grid: each part
    is a different staircase around the same curve. Fitting all of them at once averages
    their raster noise and makes the tolerance test hold for every copy by construction.

    Returns the pooled points, the positions of the run's corners in them, and the number
    of parts pooled.
    """
    n = len(pts)
    inverse = sym.inverse()
    parts = [run]
    if sym.kind == "mirror":
        other = pts[(i1 + np.arange((i0 - i1) % n + 1)) % n]
        parts.append(sym.apply(other)[::-1])
    else:
        m = len(run) - 1
        starts = [i0]
        for j in range(1, sym.order + 1):
            target = pts[i0]
            for _ in range(j):
                target = sym.apply(target)
            guess = (i0 + j * m) % n
            window = (guess + np.arange(-m // 3, m // 3 + 1)) % n
            starts.append(int(window[np.argmin(np.sum((pts[window] - target) ** 2, axis=1))]))
        starts[-1] = i0
        for j in range(1, sym.order):
            seg = pts[(starts[j] + np.arange((starts[j + 1] - starts[j]) % n + 1)) % n]
            for _ in range(j):
                seg = inverse.apply(seg)
            parts.append(seg)
    params, owner = [], []
    for j, part in enumerate(parts):
        params.append(_corner_param(part, run, local))
        owner.append(np.full(len(part), j))
    s = np.concatenate(params)
    own = np.concatenate(owner)
    order = np.lexsort((own, s))
    merged = np.concatenate(parts)[order]
    # The run's own first and last points bound the pooled run (its exact ends).
    position = np.empty(len(order), dtype=np.int64)
    position[order] = np.arange(len(order))
    first = position[0]
    last = position[len(run) - 1]
    keep = np.ones(len(merged), bool)
    keep[: first] = False
    keep[last + 1 :] = False
    offset_run = np.flatnonzero(own == 0)  # rows of the run in the concatenation
    cuts = position[offset_run[local]] - first
    merged = merged[keep]
    return merged, np.sort(cuts[(cuts > 0) & (cuts < len(merged) - 1)]), len(parts)


def _corner_param(part: NDArray[np.float64], run: NDArray[np.float64], local: NDArray[np.int64]) -> NDArray[np.float64]:
    """Parameters of a copy's points (mapped onto the run) for pooling: ``i + f`` on the
    stretch between the copy's points nearest the run's corners ``i`` and ``i + 1``, ``f``
    its arc-length fraction there.

    Congruent copies off the pixel grid have stretches of different lengths (a stem one
    pixel wider), so one arc-length fraction over the whole run would pool points from
    beyond a corner into the next piece, which then cannot be straight.
    """
    inner = np.argmin(((part[None, :, :] - run[local][:, None, :]) ** 2).sum(axis=2), axis=1) if len(local) else local
    anchors = np.r_[0, inner, len(part) - 1].astype(np.int64)
    if np.any(np.diff(anchors) <= 0):
        anchors = np.array([0, len(part) - 1])
    step = np.linalg.norm(np.diff(denoise(part, closed=False)[0], axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(step)]
    seg = np.clip(np.searchsorted(anchors, np.arange(len(part)), side="right") - 1, 0, len(anchors) - 2)
    lo, hi = arc[anchors[seg]], arc[anchors[seg + 1]]
    return seg + (arc - lo) / np.maximum(hi - lo, 1e-12)


def _fit_run(
    run, local_corners, tol, p_start, p_end, t_start, t_end, g1, method, copies=1, budget=None,
    cut_points=None, deadline: float | None = None,
) -> tuple[ChainFit | None, bool]:
    """Fit an open run split at its corners, with given end points and end tangents.

    Returns the chain, or None when some piece cannot meet the tolerance or the run needs
    more than ``budget`` pieces (the symmetry is then not worth it), and whether the budget
    was the reason (other corner points would not help then: a symmetric part with more
    pieces than the budget is always rejected, so the fit stops at the budget).
    ``cut_points`` are the corners' positions (default: their points in ``run``).
    The pieces take the single fits' round count, not the pixel runs' fewer: the pooled
    points of several copies zigzag between the copies, so their polyline bounds little
    and the points' distances decide the test, which converged fits hold best."""
    cuts = np.r_[0, local_corners, len(run) - 1].astype(int)
    curves: list[NDArray[np.float64]] = []
    fits: list[CubicFit] = []
    breaks = [0]
    for j, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        sub = run[a : b + 1]
        pos, tan = denoise(sub, closed=False, pos_window=7 * copies, tan_window=17 * copies)
        first, last = j == 0, j == len(cuts) - 2
        allowed = None if budget is None else budget - len(fits) - 1
        if allowed is not None and allowed < 0:
            return None, True
        start_at = p_start if first else (None if cut_points is None else cut_points[j - 1])
        end_at = p_end if last else (None if cut_points is None else cut_points[j])
        chain = fit_chain(
            sub, tol,
            p_start=start_at, p_end=end_at,
            tan_start=t_start if first else None, tan_end=t_end if last else None,
            g1=g1, param_points=pos, join_tangents=tan, method=method, c0_fallback=False,
            rounds=NEWTON_ROUNDS,
            # fit_chain's max_pieces allows one more piece (the one reaching the end).
            max_pieces=allowed, edge_midpoints=True,
            deadline=deadline,
        )
        if not chain.ok:
            return None, allowed is not None and len(chain.fits) > allowed
        curves.append(chain.curves)
        fits.extend(chain.fits)
        breaks.extend(int(a) + chain.breaks[1:])
    return ChainFit(np.concatenate(curves), fits, np.asarray(breaks, dtype=np.int64)), False


def _curves_near_loop(curves: NDArray[np.float64], pts: NDArray[np.float64], tol: float) -> bool:
    """True when samples of every curve lie within ``tol`` of the closed loop polygon."""
    closed = np.vstack([pts, pts[:1]])

    # Dense samples of the polygon edges make a KD-tree query exact to 1/8 px.
    steps = 8
    seg = closed[:-1, None, :] + (np.arange(steps) / steps)[None, :, None] * np.diff(closed, axis=0)[:, None, :]
    samples = bezier.sample_chain(curves, 24)
    d, _ = nearest(seg.reshape(-1, 2), samples)
    # Sample spacing only overestimates the distance, so the test stays conservative.
    return bool(d.max() <= tol)
