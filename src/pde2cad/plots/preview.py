"""A quick picture of a multi-patch reconstruction: patches by label, edges, fit errors.

matplotlib is imported inside :func:`reconstruction_preview` (``pde2cad[plots]``); the figure
is drawn with the Agg canvas, never ``pyplot``, and written atomically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.errors import InputError
from pde2cad.plots.surfaces import _check_format, _equal_box, _export, _import_matplotlib

__all__ = ["reconstruction_preview"]

#: Points drawn in the error panel at most (scatter cost grows with the count).
_MAX_ERROR_POINTS = 8000
#: A preview, not a figure for print: 100 dpi keeps the file small and the render fast.
_DPI_PREVIEW = 100


def _view(points: NDArray[np.float64]) -> tuple[float, float]:
    """An (elev, azim) in degrees that looks at a flat-ish cloud from its face, not edge-on.

    matplotlib's default (30, -60) is kept unless it sees the cloud's thinnest PCA direction
    nearly edge-on; then the candidate view most aligned with that direction (but still
    oblique, so depth shows) is used.
    """
    centred = points - points.mean(axis=0)
    _, sing, vt = np.linalg.svd(centred[:: max(1, len(centred) // 5000)], full_matrices=False)
    normal = vt[-1]

    direction = _light
    default = (30.0, -60.0)
    flat = sing[-1] < 0.3 * sing[0]
    if not flat or abs(direction(*default) @ normal) >= 0.5:
        return default
    candidates = [(e, a) for e in (15.0, 30.0, 45.0, 60.0) for a in range(-180, 180, 15)]
    # Prefer about 60 deg off edge-on: face-on hides the shape, edge-on hides the patches.
    return min(candidates, key=lambda c: abs(abs(direction(*c) @ normal) - 0.85))


def _light(elev: float, azim: float) -> NDArray[np.float64]:
    """Unit direction towards the viewer (a headlight), in data coordinates."""
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _facets(grid: NDArray[np.float64], light: NDArray[np.float64]) -> tuple[
    NDArray[np.float64], NDArray[np.float64]
]:
    """Quads of an (r, r, 3) grid, (Q, 4, 3), and a shade in [0.45, 1] per quad.

    Two-sided headlight shading: |n . light|, so a patch whose normal points away (the
    orientation of a patch is arbitrary) is shaded like its front.
    """
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    quads = np.stack([a, b, c, d], axis=2).reshape(-1, 4, 3)
    normal = np.cross((c - a).reshape(-1, 3), (d - b).reshape(-1, 3))
    length = np.linalg.norm(normal, axis=1)
    cosine = np.abs(normal @ light) / np.where(length > 0, length, 1.0)
    return quads, 0.45 + 0.55 * cosine


def _point_errors(patch: Any) -> NDArray[np.float64]:
    """Distance of each fitted point to the surface at its fitted parameters (Eq. 5.22)."""
    uv = np.asarray(patch.params, dtype=float)
    return np.linalg.norm(np.asarray(patch.points) - patch.evaluate(uv[:, 0], uv[:, 1]), axis=1)


def reconstruction_preview(
    rec: Any,
    path: str | Path,
    *,
    errors: bool = True,
    resolution: int = 16,
    title: str | None = None,
) -> Path:
    """Draw the patches of ``rec`` coloured by label, with their edges, and the fit errors.

    Parameters
    ----------
    rec : Reconstruction
        Needs ``surfaces`` (label -> surface with ``evaluate(u, v)``), ``labels``, ``edges``
        (curves with ``evaluate(s)``), ``diagonal`` and, for the error panel, ``patches``.
    path : str or Path
        ``.png``, ``.svg`` or ``.pdf``.
    errors : bool
        Add a second panel with every fitted point coloured by its error relative to the
        bounding-box diagonal.
    resolution : int
        Grid size per patch (the B-spline surfaces are smooth: 16 x 16 facets suffice).
    title : str, optional

    Returns
    -------
    Path
        The written file.
    """
    fmt = _check_format(path)
    if int(resolution) < 2:
        raise InputError(f"resolution must be at least 2, got {resolution}")
    Figure, FigureCanvasAgg = _import_matplotlib()
    from matplotlib import colormaps

    labels = [int(label) for label in rec.labels]
    if not labels:
        raise InputError("the reconstruction has no patches to draw")
    diagonal = float(rec.diagonal) if rec.diagonal > 0 else 1.0
    t = np.linspace(0.0, 1.0, int(resolution))
    uu, vv = np.meshgrid(t, t, indexing="ij")
    grids = {}
    for label in labels:
        s = rec.surfaces[label]
        # Map [0, 1] onto the knot domain: surfaces need not be parameterised over [0, 1].
        u = s.knots_u[0] + uu * (s.knots_u[-1] - s.knots_u[0])
        v = s.knots_v[0] + vv * (s.knots_v[-1] - s.knots_v[0])
        grids[label] = np.asarray(s.evaluate(u, v), dtype=float)
    every = np.vstack([g.reshape(-1, 3) for g in grids.values()])
    elev, azim = _view(every)

    panels = 2 if errors and getattr(rec, "patches", None) else 1
    fig = Figure(figsize=(6.0 * panels, 5.2))
    canvas = FigureCanvasAgg(fig)
    cmap = colormaps["tab20" if len(labels) > 10 else "tab10"]
    ax = fig.add_subplot(1, panels, 1, projection="3d")
    # One collection for all patches, so matplotlib depth-sorts facets across patches (a
    # closed shape's back patch must not cover its front); edges and labels are drawn on
    # top of it (computed_zorder off) so that seams always show.
    ax.computed_zorder = False
    quads, colours = [], []
    light = _light(elev, azim)
    for k, label in enumerate(labels):
        q, shade = _facets(grids[label], light)
        base = np.asarray(cmap(k % cmap.N)[:3])
        quads.append(q)
        colours.append(np.clip(base[None, :] * shade[:, None], 0.0, 1.0))
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    colour = np.vstack(colours)
    # Edges in the face colour close the hairline gaps antialiasing leaves between facets.
    ax.add_collection3d(Poly3DCollection(
        np.vstack(quads), facecolors=colour, edgecolors=colour, linewidths=0.3, zorder=1,
    ))  # fmt: skip
    s = np.linspace(0.0, 1.0, 60)
    for curve in getattr(rec, "edges", {}).values():
        xyz = np.asarray(curve.evaluate(s), dtype=float)
        ax.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], color="black", linewidth=0.9, zorder=2)
    for label in labels:
        c = grids[label][resolution // 2, resolution // 2]
        ax.text(c[0], c[1], c[2], str(label), fontsize=8, ha="center", va="center", zorder=3,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7})
    _equal_box(ax, every)
    ax.view_init(elev=elev, azim=azim)
    ax.set_title(title or f"{len(labels)} patches by label, edges in black", fontsize=10)

    if panels == 2:
        ax2 = fig.add_subplot(1, 2, 2, projection="3d")
        pts = np.vstack([np.asarray(rec.patches[label].points) for label in labels])
        err = np.concatenate([_point_errors(rec.patches[label]) for label in labels]) / diagonal
        if len(pts) > _MAX_ERROR_POINTS:
            pick = np.random.default_rng(0).choice(len(pts), _MAX_ERROR_POINTS, replace=False)
            pts, err = pts[pick], err[pick]
        sc = ax2.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=err, cmap="viridis", s=2,
                         vmin=0.0, vmax=max(float(err.max()), 1e-12), depthshade=False)
        _equal_box(ax2, every)
        ax2.view_init(elev=elev, azim=azim)
        ax2.set_title("fit error / bounding-box diagonal", fontsize=10)
        fig.colorbar(sc, ax=ax2, shrink=0.7, format="%.1e")
    fig.tight_layout()
    with _export(path) as tmp:
        canvas.print_figure(str(tmp), format=fmt, dpi=_DPI_PREVIEW)
    return Path(path)
