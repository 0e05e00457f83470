"""An independent error measure for vectorized outlines, and a potrace runner for comparison.

Everything here is computed directly from the binary mask with numpy/scipy; nothing is shared
with the tracer or the fitter, so the numbers can be used to check their promises.

Conventions (same as :mod:`pde2cad.image.drawing`): x to the right, y downwards, pixel
(row i, col j) is the unit square ``[j, j+1] x [i, i+1]``. The mask is treated as padded with
background, so foreground pixels on the image border contribute the border edges.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

__all__ = [
    "boundary_edges",
    "boundary_samples",
    "outline_error",
    "parse_svg_paths",
    "read_mask",
    "run_potrace",
    "write_pbm",
]

_CHUNK = 100_000  # query points per chunk


# ----------------------------------------------------------------------------------------------
# Pixel boundary
# ----------------------------------------------------------------------------------------------


def boundary_edges(mask: ArrayLike) -> NDArray[np.float64]:
    """All unit crack edges between foreground and background pixels.

    Parameters
    ----------
    mask : (H, W) bool
        Foreground pixels; the outside of the image counts as background.

    Returns
    -------
    (E, 2, 2) float
        Edge end points ``(x, y)``. Horizontal edges run left to right, vertical edges top to
        bottom (the orientation carries no meaning).
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 2:
        raise ValueError(f"mask must be 2-D, got shape {m.shape}")
    p = np.pad(m, 1, constant_values=False)
    # Horizontal edges: between padded rows r-1 and r, i.e. at y = r - 1 for columns x = c - 1.
    hr, hc = np.nonzero(p[1:, 1:-1] != p[:-1, 1:-1])  # hr in [0, H], hc in [0, W)
    # Vertical edges: between padded cols c-1 and c, i.e. at x = c - 1 for rows y = r - 1.
    vr, vc = np.nonzero(p[1:-1, 1:] != p[1:-1, :-1])  # vr in [0, H), vc in [0, W]
    h = np.empty((hr.size, 2, 2))
    h[:, 0, 0], h[:, 0, 1] = hc, hr
    h[:, 1, 0], h[:, 1, 1] = hc + 1, hr
    v = np.empty((vr.size, 2, 2))
    v[:, 0, 0], v[:, 0, 1] = vc, vr
    v[:, 1, 0], v[:, 1, 1] = vc, vr + 1
    return np.concatenate([h, v], axis=0)


def _edge_samples(
    edges: NDArray[np.float64], step: float
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.float64], int]:
    """Points every ``1/n`` (n = ceil(1/step)) along each edge, both end points included.

    Returns points (E*(n+1), 2), edge index and edge parameter per point, and n.
    """
    n = max(1, int(np.ceil(1.0 / step - 1e-9)))
    t = np.linspace(0.0, 1.0, n + 1)
    a, b = edges[:, 0, :], edges[:, 1, :]
    pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    eidx = np.repeat(np.arange(len(edges)), n + 1)
    tt = np.tile(t, len(edges))
    return pts.reshape(-1, 2), eidx, tt, n


def boundary_samples(mask: ArrayLike, step: float = 0.25) -> NDArray[np.float64]:
    """Points densely sampled along the exact pixel boundary of a binary mask.

    Every unit crack edge between a foreground and a background pixel (image border included
    where the foreground touches it) is sampled every ``1/ceil(1/step)`` px, end points
    included; duplicate points (shared pixel corners) are removed. For a simple closed
    boundary the count is therefore ``perimeter / step``.

    Parameters
    ----------
    mask : (H, W) bool
    step : float
        Sample spacing along each unit edge, in pixels (rounded so that it divides 1).

    Returns
    -------
    (n, 2) float
        ``(x, y)`` pixel coordinates, sorted lexicographically.
    """
    edges = boundary_edges(mask)
    if len(edges) == 0:
        return np.zeros((0, 2))
    pts, _, _, _ = _edge_samples(edges, step)
    return np.unique(pts, axis=0)


# ----------------------------------------------------------------------------------------------
# Cubic Béziers (kept local so this module stays independent of pde2cad.curves)
# ----------------------------------------------------------------------------------------------


def _bez(c: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points of curves ``c`` (N, 4, 2) at per-curve parameters ``t`` (N,)."""
    s = 1.0 - t
    w = np.stack([s**3, 3.0 * s * s * t, 3.0 * s * t * t, t**3], axis=-1)
    return np.einsum("nk,nkd->nd", w, c)


def _bez_d1(c: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    s = 1.0 - t
    d = np.diff(c, axis=1)
    w = np.stack([s * s, 2.0 * s * t, t * t], axis=-1)
    return 3.0 * np.einsum("nk,nkd->nd", w, d)


def _bez_d2(c: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.diff(c, n=2, axis=1)
    w = np.stack([1.0 - t, t], axis=-1)
    return 6.0 * np.einsum("nk,nkd->nd", w, d)


def _stack_curves(curves_list: list[ArrayLike] | ArrayLike) -> NDArray[np.float64]:
    if isinstance(curves_list, np.ndarray) and curves_list.ndim == 3:
        curves_list = [curves_list]
    items: list[ArrayLike] = list(curves_list)  # type: ignore[arg-type]  # a sequence of (K, 4, 2)
    arrs = [np.asarray(c, dtype=float).reshape(-1, 4, 2) for c in items]
    arrs = [a for a in arrs if len(a)]
    return np.concatenate(arrs, axis=0) if arrs else np.zeros((0, 4, 2))


class _CurveSet:
    """Dense samples of a set of cubics plus Newton refinement of point-to-curve distances."""

    def __init__(self, curves: NDArray[np.float64], samples_per_curve: int, spacing: float) -> None:
        self.curves = curves
        poly = np.linalg.norm(np.diff(curves, axis=1), axis=-1).sum(axis=1)  # >= arc length
        n = np.clip(np.ceil(poly / spacing).astype(int), samples_per_curve, 20_000)
        self.n = n
        self.cidx = np.repeat(np.arange(len(curves)), n + 1)
        starts = np.concatenate([[0], np.cumsum(n + 1)[:-1]])
        local = np.arange(self.cidx.size) - np.repeat(starts, n + 1)
        self.t = local / n[self.cidx]
        self.points = np.empty((self.cidx.size, 2))
        for lo in range(0, self.cidx.size, _CHUNK):
            sl = slice(lo, lo + _CHUNK)
            self.points[sl] = _bez(curves[self.cidx[sl]], self.t[sl])
        self.tree = cKDTree(self.points)

    def distance(self, q: NDArray[np.float64], k: int = 3, iters: int = 3) -> NDArray[np.float64]:
        """Distance from points ``q`` (N, 2) to the nearest point on any curve (~1e-6 px)."""
        out = np.empty(len(q))
        k = min(k, len(self.points))
        for lo in range(0, len(q), _CHUNK):
            qq = q[lo : lo + _CHUNK]
            d, idx = self.tree.query(qq, k=k)
            d = d.reshape(len(qq), k)
            idx = idx.reshape(len(qq), k)
            best = d.min(axis=1)
            p = np.repeat(qq, k, axis=0)
            ii = idx.ravel()
            ci = self.cidx[ii]
            c = self.curves[ci]
            t = self.t[ii].copy()
            dt_max = 2.0 / self.n[ci]
            for _ in range(iters):
                b = _bez(c, t)
                b1 = _bez_d1(c, t)
                b2 = _bez_d2(c, t)
                r = b - p
                f = np.einsum("nd,nd->n", r, b1)
                fp = np.einsum("nd,nd->n", b1, b1) + np.einsum("nd,nd->n", r, b2)
                ok = fp > 1e-12
                step = np.where(ok, f / np.where(ok, fp, 1.0), 0.0)
                step = np.clip(step, -dt_max, dt_max)
                t = np.clip(t - step, 0.0, 1.0)
                dn = np.linalg.norm(_bez(c, t) - p, axis=1).reshape(len(qq), k)
                best = np.minimum(best, dn.min(axis=1))
            out[lo : lo + _CHUNK] = best
        return out


class _EdgeSet:
    """Exact point-to-pixel-boundary distances (boundary = union of unit crack edges)."""

    def __init__(self, edges: NDArray[np.float64], step: float = 0.25) -> None:
        self.edges = edges
        pts, self.eidx, _, _ = _edge_samples(edges, step)
        self.tree = cKDTree(pts)

    def distance(self, q: NDArray[np.float64], k: int = 8) -> NDArray[np.float64]:
        out = np.empty(len(q))
        k = min(k, len(self.eidx))
        for lo in range(0, len(q), _CHUNK):
            qq = q[lo : lo + _CHUNK]
            _, idx = self.tree.query(qq, k=k)
            e = self.edges[self.eidx[idx.reshape(len(qq), k)]]  # (N, k, 2, 2)
            a, b = e[..., 0, :], e[..., 1, :]
            ab = b - a
            s = np.einsum("nkd,nkd->nk", qq[:, None, :] - a, ab) / np.einsum("nkd,nkd->nk", ab, ab)
            s = np.clip(s, 0.0, 1.0)
            foot = a + s[..., None] * ab
            out[lo : lo + _CHUNK] = np.linalg.norm(foot - qq[:, None, :], axis=-1).min(axis=1)
        return out


def _refine_max(
    point_fn: Any,
    dist_fn: Any,
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    iters: int = 24,
) -> NDArray[np.float64]:
    """Golden-section maximisation of ``dist_fn(point_fn(s))`` for each interval [lo, hi]."""
    g = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo.copy(), hi.copy()
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = dist_fn(point_fn(x1)), dist_fn(point_fn(x2))
    best = np.maximum(np.maximum(f1, f2), np.maximum(dist_fn(point_fn(lo)), dist_fn(point_fn(hi))))
    for _ in range(iters):
        left = f1 > f2  # maximum lies in [a, x2]
        b = np.where(left, x2, b)
        a = np.where(left, a, x1)
        x2n = np.where(left, x1, a + g * (b - a))
        x1n = np.where(left, b - g * (b - a), x2)
        f2n = np.where(left, f1, np.nan)
        f1n = np.where(left, np.nan, f2)
        need1, need2 = np.isnan(f1n), np.isnan(f2n)
        if need1.any():
            f1n[need1] = dist_fn(point_fn(x1n)[need1])
        if need2.any():
            f2n[need2] = dist_fn(point_fn(x2n)[need2])
        x1, x2, f1, f2 = x1n, x2n, f1n, f2n
        best = np.maximum(best, np.maximum(f1, f2))
    return best


def outline_error(
    mask: ArrayLike,
    curves_list: list[ArrayLike] | ArrayLike,
    samples_per_curve: int = 64,
    step: float = 0.05,
) -> dict[str, Any]:
    """Distances between the exact pixel boundary of ``mask`` and a set of cubic Béziers.

    The boundary is sampled every ``step`` px (pixel corners included); each sample's
    distance to the curves is found with a k-d tree over dense curve samples (at least
    ``samples_per_curve`` per curve and one per 0.1 px of control-polygon length) followed by
    Newton steps on the curve parameter, so distances are accurate to well below 1e-3 px. The
    maxima are then refined by a golden-section search along the boundary edge (resp. along
    the curve), so they do not depend on the sampling either.

    Parameters
    ----------
    mask : (H, W) bool
        The original binary image (foreground True).
    curves_list : list of (K, 4, 2) float, or one (K, 4, 2) array
        Cubic Béziers in pixel coordinates (x right, y down); lines as degenerate cubics.
    samples_per_curve : int
        Minimum number of samples per curve.
    step : float
        Boundary sample spacing in pixels.

    Returns
    -------
    dict
        ``max_boundary_to_curve``: max over the boundary of the distance to the nearest curve
        point (the tolerance check); ``mean_boundary_to_curve``: its arc-length mean;
        ``max_curve_to_boundary``: max over the curves of the distance to the boundary;
        ``worst_boundary_point``: the boundary sample (x, y) next to the maximum, or None;
        ``n_boundary_samples`` (``(1/step + 1)`` per unit edge), ``n_curve_samples``,
        ``n_curves``. Empty curves against a non-empty boundary give ``inf``.

    Notes
    -----
    Memory and time grow with ``perimeter / step``; for very large drawings raise ``step``
    (the refinement keeps the maxima exact, only the mean gets coarser).
    """
    m = np.asarray(mask, dtype=bool)
    curves = _stack_curves(curves_list)
    edges = boundary_edges(m)
    result: dict[str, Any] = {
        "max_boundary_to_curve": 0.0,
        "mean_boundary_to_curve": 0.0,
        "max_curve_to_boundary": 0.0,
        "worst_boundary_point": None,
        "n_boundary_samples": 0,
        "n_curve_samples": 0,
        "n_curves": int(len(curves)),
    }
    if len(edges) == 0 and len(curves) == 0:
        return result
    if len(edges) == 0 or len(curves) == 0:
        result["max_boundary_to_curve"] = float("inf") if len(edges) else 0.0
        result["mean_boundary_to_curve"] = float("inf") if len(edges) else 0.0
        result["max_curve_to_boundary"] = float("inf") if len(curves) else 0.0
        return result

    cs = _CurveSet(curves, samples_per_curve, spacing=0.1)
    es = _EdgeSet(edges)

    # Boundary -> curves.
    pts, eidx, et, n = _edge_samples(edges, step)
    d = cs.distance(pts)
    w = np.ones(n + 1)
    w[0] = w[-1] = 0.5  # trapezoid rule along each unit edge -> arc-length mean
    mean = float((d.reshape(-1, n + 1) * w).sum() / (len(edges) * n))
    dmax = float(d.max())
    cand = np.nonzero(d >= dmax - 1.0 / n)[0]  # a local max can hide between samples
    cand = cand[np.argsort(-d[cand])[:5000]]
    a, b = edges[eidx[cand], 0], edges[eidx[cand], 1]

    def edge_point(s: NDArray[np.float64]) -> NDArray[np.float64]:
        return a + s[:, None] * (b - a)

    h = 1.0 / n
    refined = _refine_max(
        edge_point,
        cs.distance,
        np.clip(et[cand] - h, 0.0, 1.0),
        np.clip(et[cand] + h, 0.0, 1.0),
    )
    j = int(np.argmax(refined))
    if refined[j] > dmax:
        dmax = float(refined[j])
    worst = pts[cand[j]]

    # Curves -> boundary.
    dc = es.distance(cs.points)
    cmax = float(dc.max())
    cc = np.nonzero(dc >= cmax - 0.2)[0]
    cc = cc[np.argsort(-dc[cc])[:5000]]
    cidx, ct = cs.cidx[cc], cs.t[cc]
    ccurves = curves[cidx]
    dt = 1.0 / cs.n[cidx]
    refined_c = _refine_max(
        lambda s: _bez(ccurves, s),
        es.distance,
        np.clip(ct - dt, 0.0, 1.0),
        np.clip(ct + dt, 0.0, 1.0),
    )
    cmax = max(cmax, float(refined_c.max()))

    result.update(
        max_boundary_to_curve=dmax,
        mean_boundary_to_curve=mean,
        max_curve_to_boundary=cmax,
        worst_boundary_point=(float(worst[0]), float(worst[1])),
        n_boundary_samples=int(len(pts)),
        n_curve_samples=int(len(cs.points)),
    )
    return result


# ----------------------------------------------------------------------------------------------
# SVG paths
# ----------------------------------------------------------------------------------------------

_TOKEN = re.compile(r"[MmLlCcZzHhVvSsQqTtAa]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_TRANSFORM = re.compile(r"(matrix|translate|scale|rotate|skewX|skewY)\s*\(([^)]*)\)")


def _parse_transform(text: str | None) -> NDArray[np.float64]:
    """SVG transform attribute -> 3x3 affine matrix (applied to column vectors)."""
    out = np.eye(3)
    if not text:
        return out
    for name, args in _TRANSFORM.findall(text):
        v = [float(x) for x in re.split(r"[\s,]+", args.strip()) if x]
        mtx = np.eye(3)
        if name == "matrix":
            a, b, c, d, e, f = v
            mtx = np.array([[a, c, e], [b, d, f], [0, 0, 1]])
        elif name == "translate":
            mtx[0, 2] = v[0]
            mtx[1, 2] = v[1] if len(v) > 1 else 0.0
        elif name == "scale":
            mtx[0, 0] = v[0]
            mtx[1, 1] = v[1] if len(v) > 1 else v[0]
        elif name == "rotate":
            th = np.radians(v[0])
            r = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
            if len(v) == 3:
                t1 = np.array([[1, 0, v[1]], [0, 1, v[2]], [0, 0, 1]])
                t2 = np.array([[1, 0, -v[1]], [0, 1, -v[2]], [0, 0, 1]])
                r = t1 @ r @ t2
            mtx = r
        elif name == "skewX":
            mtx[0, 1] = np.tan(np.radians(v[0]))
        elif name == "skewY":
            mtx[1, 0] = np.tan(np.radians(v[0]))
        out = out @ mtx
    return out


def _line_cubic(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([p, (2.0 * p + q) / 3.0, (p + 2.0 * q) / 3.0, q])


def _parse_d(d: str) -> tuple[list[NDArray[np.float64]], int]:
    """One path ``d`` -> list of subpath curve arrays (untransformed) and a segment count."""
    tokens = _TOKEN.findall(d)
    subpaths: list[list[NDArray[np.float64]]] = []
    cur: list[NDArray[np.float64]] = []
    pos = np.zeros(2)
    start = np.zeros(2)
    segments = 0
    cmd = ""
    i = 0

    def num() -> float:
        nonlocal i
        val = float(tokens[i])
        i += 1
        return val

    def is_num(k: int) -> bool:
        return k < len(tokens) and not tokens[k].isalpha()

    while i < len(tokens):
        if tokens[i].isalpha():
            cmd = tokens[i]
            i += 1
        elif not cmd:
            raise ValueError(f"path data must start with a command: {d[:40]!r}")
        rel = cmd.islower()
        c = cmd.upper()
        if c == "Z":
            if np.linalg.norm(pos - start) > 1e-12:
                cur.append(_line_cubic(pos.copy(), start.copy()))
                segments += 1
            pos = start.copy()
            if cur:
                subpaths.append(cur)
            cur = []
            cmd = ""
            continue
        if not is_num(i):
            raise ValueError(f"missing coordinates after {cmd!r} in path data")
        if c == "M":
            p = np.array([num(), num()]) + (pos if rel else 0.0)
            if cur:
                subpaths.append(cur)
            cur = []
            pos = p
            start = p.copy()
            cmd = "l" if rel else "L"  # implicit lineto for further pairs
        elif c in "LHV":
            if c == "L":
                q = np.array([num(), num()]) + (pos if rel else 0.0)
            elif c == "H":
                x = num()
                q = np.array([x + pos[0] if rel else x, pos[1]])
            else:
                y = num()
                q = np.array([pos[0], y + pos[1] if rel else y])
            cur.append(_line_cubic(pos.copy(), q))
            segments += 1
            pos = q
        elif c == "C":
            off = pos if rel else 0.0
            p1 = np.array([num(), num()]) + off
            p2 = np.array([num(), num()]) + off
            p3 = np.array([num(), num()]) + off
            cur.append(np.array([pos.copy(), p1, p2, p3]))
            segments += 1
            pos = p3
        else:
            raise ValueError(f"unsupported SVG path command {cmd!r}")
    if cur:
        subpaths.append(cur)
    return [np.array(sp) for sp in subpaths], segments


def parse_svg_paths(svg_text: str) -> tuple[list[NDArray[np.float64]], int]:
    """Cubic Béziers of all ``<path>`` elements of an SVG document, in pixel coordinates.

    Handles the commands M/m, L/l, H/h, V/v, C/c and Z/z (implicit repetition included) and the
    ``transform`` attributes of the path and all its ancestor groups (potrace puts
    ``translate(0,H) scale(0.1,-0.1)`` on a group), so the result is in the SVG user space of
    the root element, i.e. pixels with y down for potrace's output.

    Segment count: every lineto (L, H, V) and every curveto (C) counts once, also when written
    as an implicit repetition; ``M`` counts nothing; ``Z`` counts one line only when the current
    point differs from the subpath start (potrace's paths always close exactly, so its ``z``
    adds nothing). Zero-length lines written explicitly are counted.

    Parameters
    ----------
    svg_text : str
        The SVG document, or a bare path ``d`` string.

    Returns
    -------
    curves : list of (K, 4, 2) float
        One array per closed (or open) subpath; lines as degenerate cubics with control points
        at 1/3 and 2/3.
    segment_count : int
    """
    text = svg_text.strip()
    if not text.startswith("<"):
        subs, n = _parse_d(text)
        return subs, n
    root = ET.fromstring(text)
    curves: list[NDArray[np.float64]] = []
    total = 0

    def walk(el: ET.Element, mtx: NDArray[np.float64]) -> None:
        nonlocal total
        m2 = mtx @ _parse_transform(el.get("transform"))
        tag = el.tag.rsplit("}", 1)[-1]
        if tag == "path" and el.get("d"):
            subs, n = _parse_d(el.get("d", ""))
            total += n
            for s in subs:
                xy = s.reshape(-1, 2)
                xy = xy @ m2[:2, :2].T + m2[:2, 2]
                curves.append(xy.reshape(-1, 4, 2))
        for child in el:
            walk(child, m2)

    walk(root, np.eye(3))
    return curves, total


# ----------------------------------------------------------------------------------------------
# Images and potrace
# ----------------------------------------------------------------------------------------------


def read_mask(path: str | Path, threshold: int = 128) -> NDArray[np.bool_]:
    """Read an image file as a binary mask: dark pixels (luminance < threshold) are foreground.

    Transparent pixels (alpha < 128) count as background. PBM files keep their own meaning
    (1 = black = foreground).
    """
    from PIL import Image

    with Image.open(path) as im:
        if im.mode == "1":
            return ~np.asarray(im, dtype=bool)
        if im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info):
            rgba = np.asarray(im.convert("RGBA"))
            lum = np.asarray(im.convert("RGBA").convert("L"))
            return (lum < threshold) & (rgba[..., 3] >= 128)
        return np.asarray(im.convert("L")) < threshold


def write_pbm(mask: ArrayLike, path: str | Path) -> None:
    """Write a binary PBM (P4): foreground True -> 1 (black)."""
    m = np.asarray(mask, dtype=bool)
    h, w = m.shape
    data = np.packbits(m, axis=1).tobytes()
    Path(path).write_bytes(f"P4\n{w} {h}\n".encode("ascii") + data)


def run_potrace(
    mask_or_pbm_path: ArrayLike | str | Path,
    repeats: int = 3,
    extra_args: list[str] | None = None,
) -> dict[str, Any]:
    """Trace a mask with potrace (SVG backend, default options) and parse its curves.

    Parameters
    ----------
    mask_or_pbm_path : (H, W) bool array, or path to a PBM (or any image Pillow reads; dark
        pixels are foreground)
    repeats : int
        The potrace run is timed this many times; the best wall time is reported.
    extra_args : list of str, optional
        Extra command-line options (none by default: turdsize 2, alphamax 1,
        opttolerance 0.2, unit 10).

    Returns
    -------
    dict
        ``curves`` (list of (K, 4, 2) float in pixel coordinates, y down), ``segments``
        (curveto + lineto count, see :func:`parse_svg_paths`), ``time_s`` (best subprocess
        wall time), ``svg`` (the SVG text), ``width``, ``height``.
    """
    exe = shutil.which("potrace")
    if exe is None:
        raise FileNotFoundError("the potrace command is not installed (Debian package potrace)")
    with tempfile.TemporaryDirectory(prefix="pde2cad-potrace-") as tmp:
        src = Path(tmp) / "in.pbm"
        if isinstance(mask_or_pbm_path, (str, Path)):
            p = Path(mask_or_pbm_path)
            if p.suffix.lower() == ".pbm":
                src = p
            else:
                write_pbm(read_mask(p), src)
        else:
            write_pbm(mask_or_pbm_path, src)
        out = Path(tmp) / "out.svg"
        cmd = [exe, "-s", *(extra_args or []), "-o", str(out), str(src)]
        best = float("inf")
        for _ in range(max(1, repeats)):
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            best = min(best, time.perf_counter() - t0)
        svg = out.read_text()
    curves, segments = parse_svg_paths(svg)
    root = ET.fromstring(svg)
    vb = [float(v) for v in (root.get("viewBox") or "0 0 0 0").split()]
    return {
        "curves": curves,
        "segments": segments,
        "time_s": best,
        "svg": svg,
        "width": vb[2],
        "height": vb[3],
    }
