"""Diagnostic plots of fitted surfaces: fit-error maps and zebra (reflection-line) renders.

Surfaces follow the patch protocol of :mod:`pde2cad.surfaces`: ``evaluate(u, v) -> (..., 3)``
and ``derivatives(u, v) -> (S_u, S_v)`` over ``(u, v)`` in ``[0, 1]^2``.

matplotlib is optional (``pip install 'pde2cad[plots]'``) and is imported only inside the
functions that draw. Figures are built with :class:`matplotlib.figure.Figure` and the Agg
canvas, never ``pyplot``, so no global state (backend, current figure) is touched. Files are
written atomically; the format follows the suffix (``.png``, ``.svg`` or ``.pdf``).

Zebra mapping
-------------
:func:`zebra` and :func:`zebra_image` use reflection lines at infinity, the mapping of the
"zebra" tools of CAD systems. The environment is a sphere at infinity painted with
``stripes`` latitude bands of equal angular width around the stripe axis ``a``. A ray from
the eye along the view direction ``e`` (the camera of the render, orthographic) is reflected
by the unit normal ``n``::

    r = e - 2 (e . n) n,     phase = arccos(r . a) / pi  in [0, 1],
    value = floor(stripes * phase) mod 2                  (0 black, 1 white),

that is ``value = 1`` where ``sin(stripes * pi * phase) < 0`` and 0 where it is positive
(up to the band edges). ``r`` does not change when ``n`` flips, so patches with opposite
orientations still compare. The phase is a continuous function of the normal: across a
shared edge the stripes run on without a break where the normals agree (G1, e.g. a C1 join)
and jump where they do not (G0 only, a crease). A curvature jump (G1 but not G2) shows as a
kink in the stripes.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import ExportError, InputError
from pde2cad.io.atomic import atomic_path

__all__ = ["error_map", "zebra", "zebra_image"]

_FORMATS = {".png": "png", ".svg": "svg", ".pdf": "pdf"}
_MAX_DRAWN_POINTS = 20_000
_DEFAULT_VIEW = (30.0, -60.0)  # matplotlib's default (elev, azim) in degrees
_DPI = 150


# --------------------------------------------------------------------------------------------
# shared helpers
# --------------------------------------------------------------------------------------------


def _check_surface(surface: Any, needs: tuple[str, ...]) -> None:
    missing = [name for name in needs if not callable(getattr(surface, name, None))]
    if missing:
        raise InputError(
            f"surface {type(surface).__name__} lacks {', '.join(missing)}; pass a patch with "
            "evaluate(u, v) -> (..., 3) and derivatives(u, v) -> (S_u, S_v), such as "
            "BilinearCoons"
        )


def _check_format(path: str | Path) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in _FORMATS:
        raise InputError(
            f"cannot tell the plot format of {path}: use a .png, .svg or .pdf file name"
        )
    return _FORMATS[suffix]


def _check_resolution(resolution: int) -> int:
    if isinstance(resolution, bool) or int(resolution) != resolution or resolution < 2:
        raise InputError(f"resolution must be an integer >= 2, got {resolution!r}")
    return int(resolution)


def _grid(surface: Any, resolution: int) -> NDArray[np.float64]:
    """``S`` on a uniform ``resolution x resolution`` grid, indexed ``[i_u, j_v]``: (r, r, 3)."""
    t = np.linspace(0.0, 1.0, resolution)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    pts = np.asarray(surface.evaluate(uu, vv), dtype=float)
    if pts.shape != (resolution, resolution, 3):
        raise InputError(
            f"surface.evaluate on a ({resolution}, {resolution}) grid returned shape {pts.shape}; "
            "plots need 3D points (..., 3)"
        )
    return pts


def _import_matplotlib() -> Any:
    try:
        import matplotlib  # noqa: F401
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3d projection)
    except ImportError as exc:  # optional dependency
        raise ExportError(
            "surface plots need matplotlib; install it with: pip install 'pde2cad[plots]'"
        ) from exc
    return Figure, FigureCanvasAgg


def _equal_box(ax: Any, pts: NDArray[np.float64]) -> None:
    """Equal scaling on all three axes so that angles (and reflections) look true."""
    finite = pts[np.all(np.isfinite(pts), axis=1)]
    lo, hi = finite.min(axis=0), finite.max(axis=0)
    span = hi - lo
    size = float(span.max()) if span.max() > 0 else 1.0
    span = np.maximum(span, 0.02 * size)  # a flat patch still gets a visible box
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - span[0] / 2, mid[0] + span[0] / 2)
    ax.set_ylim(mid[1] - span[1] / 2, mid[1] + span[1] / 2)
    ax.set_zlim(mid[2] - span[2] / 2, mid[2] + span[2] / 2)
    ax.set_box_aspect(tuple(span / size))
    from matplotlib.ticker import MaxNLocator

    for axis, extent in zip((ax.xaxis, ax.yaxis, ax.zaxis), span / size, strict=True):
        axis.set_major_locator(MaxNLocator(nbins=max(1, int(round(5 * extent)))))
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")


@contextmanager
def _export(path: str | Path) -> Iterator[Path]:
    """Atomic write; any OSError becomes an ExportError naming the file."""
    try:
        with atomic_path(path) as tmp:
            yield tmp
    except ExportError:
        raise
    except OSError as exc:
        raise ExportError(f"cannot write {path}: {exc}") from exc


def _save(canvas: Any, path: str | Path, fmt: str) -> None:
    with _export(path) as tmp:
        canvas.print_figure(str(tmp), format=fmt, dpi=_DPI)


# --------------------------------------------------------------------------------------------
# error map
# --------------------------------------------------------------------------------------------


def _nearest_errors(
    surface: Any, pts: NDArray[np.float64], resolution: int
) -> NDArray[np.float64]:
    """Distance from each point to the surface without known parameters.

    Start at the nearest of a dense grid of surface samples (cKDTree), then take a few
    clamped Gauss-Newton steps on ``|S(u, v) - P|`` with the first derivatives, keeping the
    smallest distance seen, so the result never exceeds the grid estimate.
    """
    from scipy.spatial import cKDTree

    n = max(4 * resolution, 200)
    t = np.linspace(0.0, 1.0, n)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    samples = np.asarray(surface.evaluate(uu, vv), dtype=float).reshape(-1, 3)
    best, idx = cKDTree(samples).query(pts)
    best = np.asarray(best, dtype=float)
    u = uu.reshape(-1)[idx]
    v = vv.reshape(-1)[idx]
    if not callable(getattr(surface, "derivatives", None)):
        return best
    for _ in range(4):
        s = np.asarray(surface.evaluate(u, v), dtype=float)
        su, sv = (np.asarray(d, dtype=float) for d in surface.derivatives(u, v))
        r = pts - s
        a11 = np.einsum("nk,nk->n", su, su)
        a12 = np.einsum("nk,nk->n", su, sv)
        a22 = np.einsum("nk,nk->n", sv, sv)
        b1 = np.einsum("nk,nk->n", su, r)
        b2 = np.einsum("nk,nk->n", sv, r)
        det = a11 * a22 - a12 * a12
        ok = np.abs(det) > 1e-300
        safe = np.where(ok, det, 1.0)
        du = np.where(ok, (a22 * b1 - a12 * b2) / safe, 0.0)
        dv = np.where(ok, (a11 * b2 - a12 * b1) / safe, 0.0)
        u = np.clip(u + du, 0.0, 1.0)
        v = np.clip(v + dv, 0.0, 1.0)
        d = np.linalg.norm(pts - np.asarray(surface.evaluate(u, v), dtype=float), axis=1)
        best = np.minimum(best, d)
    return best


def error_map(
    surface: Any,
    points: ArrayLike,
    params: ArrayLike | None,
    path: str | Path,
    *,
    title: str | None = None,
    resolution: int = 60,
    cmap: str = "viridis",
) -> dict[str, float | int]:
    """Render a surface with the data points coloured by their fit error; write it to a file.

    The surface is drawn as a light grey mesh evaluated on a ``resolution x resolution``
    grid; the points are scattered on top, coloured by ``|P - S(u, v)|`` with a colour bar in
    data units. At most about 20 000 points (a fixed random subset) are drawn; the errors and
    the returned statistics use all of them.

    Parameters
    ----------
    surface : patch
        ``evaluate(u, v) -> (..., 3)`` (and ``derivatives`` when ``params`` is None).
    points : (N, 3) float
        The data points.
    params : (N, 2) float or None
        The ``(u, v)`` of each point (e.g. ``Patch.params``); the error is
        ``|P - S(u, v)|``. If None, the error is the distance to the surface: nearest of a
        dense surface sample (cKDTree), refined by a few Gauss-Newton steps.
    path : str or Path
        Output file; ``.png``, ``.svg`` or ``.pdf`` picks the format. Written atomically.
    title : str, optional
        Figure title; default states the mean and max error and the point count.
    resolution : int
        Grid size of the drawn surface (and the base of the sample when ``params`` is None).
    cmap : str
        matplotlib colour map of the errors.

    Returns
    -------
    dict
        ``{"mean": float, "max": float, "n": int}`` over all points.

    Raises
    ------
    InputError
        Wrong shapes, NaN/inf, a surface without ``evaluate``, or an unknown file suffix.
    ExportError
        matplotlib is missing, the folder does not exist, or the file cannot be written.
    """
    fmt = _check_format(path)
    resolution = _check_resolution(resolution)
    _check_surface(surface, ("evaluate",) if params is not None else ("evaluate", "derivatives"))
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise InputError(f"points must have shape (N, 3) with N >= 1, got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        bad = int(np.argmax(~np.all(np.isfinite(pts), axis=1)))
        raise InputError(f"points contain NaN or inf (first at row {bad}); drop those rows first")

    if params is not None:
        uv = np.asarray(params, dtype=float)
        if uv.shape != (pts.shape[0], 2):
            raise InputError(
                f"params must have shape ({pts.shape[0]}, 2) to match the points, got {uv.shape}"
            )
        if not np.all(np.isfinite(uv)):
            raise InputError("params contain NaN or inf")
        fitted = np.asarray(surface.evaluate(uv[:, 0], uv[:, 1]), dtype=float)
        errors = np.linalg.norm(pts - fitted, axis=1)
    else:
        errors = _nearest_errors(surface, pts, resolution)

    stats: dict[str, float | int] = {
        "mean": float(errors.mean()),
        "max": float(errors.max()),
        "n": int(pts.shape[0]),
    }

    Figure, FigureCanvasAgg = _import_matplotlib()
    grid = _grid(surface, resolution)

    if pts.shape[0] > _MAX_DRAWN_POINTS:
        keep = np.random.default_rng(0).choice(pts.shape[0], _MAX_DRAWN_POINTS, replace=False)
        keep.sort()
    else:
        keep = np.arange(pts.shape[0])

    fig = Figure(figsize=(7.5, 6.0))
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    ax.plot_surface(
        grid[..., 0],
        grid[..., 1],
        grid[..., 2],
        color="lightgrey",
        alpha=0.45,
        linewidth=0,
        antialiased=False,
        rcount=resolution,
        ccount=resolution,
    )
    vmax = stats["max"] if stats["max"] > 0 else 1.0
    sc = ax.scatter(
        pts[keep, 0],
        pts[keep, 1],
        pts[keep, 2],
        c=errors[keep],
        cmap=cmap,
        vmin=0.0,
        vmax=vmax,
        s=4 if keep.size > 2000 else 10,
        depthshade=False,
        linewidths=0,
    )
    cbar = fig.colorbar(sc, ax=ax, shrink=0.7, pad=0.14)
    cbar.set_label("|P - S(u, v)|  (data units)")
    _equal_box(ax, np.concatenate([grid.reshape(-1, 3), pts[keep]]))
    if title is None:
        drawn = "" if keep.size == pts.shape[0] else f" ({keep.size} drawn)"
        title = (
            f"fit error: mean {stats['mean']:.3g}, max {stats['max']:.3g}, "
            f"n = {stats['n']}{drawn}"
        )
    ax.set_title(title)
    _save(canvas, path, fmt)
    return stats


# --------------------------------------------------------------------------------------------
# zebra
# --------------------------------------------------------------------------------------------


def _view_vectors(
    view: tuple[float, float], direction: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(e, a)``: the unit view direction (eye towards the scene) and the unit stripe axis."""
    elev, azim = np.deg2rad(np.asarray(view, dtype=float))
    camera = np.array(
        [np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim), np.sin(elev)]
    )  # from the scene towards the eye, as matplotlib places it
    if direction is None:
        # Screen "up": d(camera)/d(elev). Stripes then run horizontally on the screen.
        axis = np.array(
            [-np.sin(elev) * np.cos(azim), -np.sin(elev) * np.sin(azim), np.cos(elev)]
        )
    else:
        axis = np.asarray(direction, dtype=float)
        norm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
        if not np.isfinite(norm) or norm == 0.0:
            raise InputError(
                f"direction must be a non-zero 3-vector (the stripe axis), got {direction!r}"
            )
        axis = axis / norm
    return -camera, axis


def _as_surface_list(surfaces: Any) -> list[Any]:
    items = [surfaces] if callable(getattr(surfaces, "evaluate", None)) else list(surfaces)
    if not items:
        raise InputError("zebra needs at least one surface")
    for s in items:
        _check_surface(s, ("evaluate", "derivatives"))
    return items


def _phase(
    surface: Any,
    u: NDArray[np.float64],
    v: NDArray[np.float64],
    eye: NDArray[np.float64],
    axis: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Reflection-line phase ``arccos(r . a) / pi`` in [0, 1]; NaN where the normal vanishes."""
    su, sv = (np.asarray(d, dtype=float) for d in surface.derivatives(u, v))
    normal = np.cross(su, sv)
    length = np.linalg.norm(normal, axis=-1)
    scale = np.maximum(np.linalg.norm(su, axis=-1) * np.linalg.norm(sv, axis=-1), 1e-300)
    ok = length > 1e-12 * scale  # degenerate (collapsed side) -> no normal
    n = normal / np.where(ok, length, 1.0)[..., None]
    en = n @ eye
    r = eye - 2.0 * en[..., None] * n
    phase = np.arccos(np.clip(r @ axis, -1.0, 1.0)) / np.pi
    return np.where(ok, phase, np.nan)


def _stripe_values(phase: NDArray[np.float64], stripes: int) -> NDArray[np.float64]:
    with np.errstate(invalid="ignore"):
        band = np.floor(stripes * phase)
        band = np.minimum(band, stripes - 1)  # phase == 1 belongs to the last band
        return np.where(np.isfinite(phase), np.mod(band, 2.0), np.nan)


def _check_stripes(stripes: int) -> int:
    if isinstance(stripes, bool) or int(stripes) != stripes or stripes < 1:
        raise InputError(f"stripes must be a positive integer, got {stripes!r}")
    return int(stripes)


def zebra_image(
    surfaces: Sequence[Any] | Any,
    *,
    stripes: int = 12,
    direction: ArrayLike | None = (0.0, 0.0, 1.0),
    view: tuple[float, float] = _DEFAULT_VIEW,
    resolution: int = 200,
    phase: bool = False,
) -> NDArray[np.float64]:
    """Zebra stripe values of each surface on a uniform ``(u, v)`` grid.

    Uses the reflection-line mapping of the module docstring: the stripe of a point is
    ``floor(stripes * arccos(r . a) / pi) mod 2`` with ``r`` the view direction reflected by
    the unit normal ``(S_u x S_v) / |S_u x S_v|``.

    Parameters
    ----------
    surfaces : patch or sequence of patches
        Each with ``evaluate(u, v)`` and ``derivatives(u, v)``.
    stripes : int
        Number of bands on the environment sphere from pole to pole.
    direction : (3,) float or None
        Stripe axis ``a`` (the bands are latitudes around it). None uses the screen "up"
        vector of ``view``, so the environment stripes run horizontally on the screen.
    view : (elev, azim)
        Camera angles in degrees, as matplotlib's ``view_init``; fixes the view direction.
    resolution : int
        Grid points per parameter, including both ends.
    phase : bool
        Return the continuous phase ``arccos(r . a) / pi`` in [0, 1] instead of the 0/1
        stripe values.

    Returns
    -------
    (k, resolution, resolution) float
        Entry ``[s, i, j]`` belongs to surface ``s`` at ``u = i / (resolution - 1)``,
        ``v = j / (resolution - 1)``: 0 (black) or 1 (white), or the phase; NaN where the
        normal is undefined (``S_u x S_v = 0``).

    Raises
    ------
    InputError
        No surfaces, a surface without the needed methods, or bad options.
    """
    items = _as_surface_list(surfaces)
    stripes = _check_stripes(stripes)
    resolution = _check_resolution(resolution)
    eye, axis = _view_vectors(view, direction)
    t = np.linspace(0.0, 1.0, resolution)
    uu, vv = np.meshgrid(t, t, indexing="ij")
    fields = np.stack([_phase(s, uu, vv, eye, axis) for s in items])
    return fields if phase else _stripe_values(fields, stripes)


def zebra(
    surfaces: Sequence[Any] | Any,
    path: str | Path,
    *,
    stripes: int = 12,
    direction: ArrayLike | None = (0.0, 0.0, 1.0),
    view: tuple[float, float] = _DEFAULT_VIEW,
    resolution: int = 200,
    title: str | None = None,
) -> None:
    """Render zebra stripes over one or more patches in a shared view; write to a file.

    Stripes that run on without a break across a shared edge show a G1 join (equal normals);
    stripes that jump there show a G0-only join (a crease); a kink in otherwise continuous
    stripes shows a curvature jump. All patches go into one polygon collection, so the depth
    ordering is shared, and the axes are equally scaled with an orthographic camera so that
    the rendered view matches the view direction of the mapping (see the module docstring).

    Parameters
    ----------
    surfaces : patch or sequence of patches
        Each with ``evaluate(u, v) -> (..., 3)`` and ``derivatives(u, v)``.
    path : str or Path
        Output file; ``.png``, ``.svg`` or ``.pdf`` picks the format. Written atomically.
    stripes : int
        Number of bands on the environment sphere from pole to pole.
    direction : (3,) float or None
        Stripe axis; None uses the screen "up" vector (see :func:`zebra_image`).
    view : (elev, azim)
        Camera angles in degrees (matplotlib ``view_init``); default matplotlib's own.
    resolution : int
        Grid points per parameter and patch; each patch is drawn as
        ``(resolution - 1)^2`` quads coloured by the stripe at the quad centre.
    title : str, optional
        Figure title.

    Raises
    ------
    InputError
        No surfaces, a surface without the needed methods, bad options or file suffix.
    ExportError
        matplotlib is missing, the folder does not exist, or the file cannot be written.
    """
    fmt = _check_format(path)
    items = _as_surface_list(surfaces)
    stripes = _check_stripes(stripes)
    resolution = _check_resolution(resolution)
    eye, axis = _view_vectors(view, direction)
    Figure, FigureCanvasAgg = _import_matplotlib()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    mid = (np.arange(resolution - 1) + 0.5) / (resolution - 1)
    uc, vc = np.meshgrid(mid, mid, indexing="ij")
    quads, colours, corners = [], [], []
    shades = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 1.0], [0.5, 0.5, 0.5, 1.0]])
    for s in items:
        g = _grid(s, resolution)
        corners.append(g.reshape(-1, 3))
        quad = np.stack([g[:-1, :-1], g[1:, :-1], g[1:, 1:], g[:-1, 1:]], axis=2)
        quads.append(quad.reshape(-1, 4, 3))
        value = _stripe_values(_phase(s, uc, vc, eye, axis), stripes).reshape(-1)
        colours.append(shades[np.where(np.isnan(value), 2, value).astype(int)])

    fig = Figure(figsize=(7.0, 6.0))
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    ax.set_proj_type("ortho")
    ax.view_init(elev=view[0], azim=view[1])
    poly = Poly3DCollection(
        np.concatenate(quads),
        facecolors=np.concatenate(colours),
        edgecolors="none",
        linewidths=0,
        antialiased=False,
    )
    ax.add_collection3d(poly)
    _equal_box(ax, np.concatenate(corners))
    if title is not None:
        ax.set_title(title)
    _save(canvas, path, fmt)
