"""Multi-patch reconstruction of a segmented point cloud: cloud -> sewn B-spline shell.

Pipeline:

1. :func:`~pde2cad.layout.build_layout`: adjacency, border points, rough corners; segments
   that are no 3/4-sided region are relabelled into pieces that are
   (:func:`~pde2cad.layout.split.split_segments`, layout built again).
2. :func:`~pde2cad.layout.edges.build_edges`: refined corners, each segment's side loop, and
   ONE curve per edge (fitted to the border midline of both segments, or to the open-boundary
   run), used by every patch on that edge (reversed where its loop runs the other way), so
   neighbours interpolate the identical curve.
3. Per segment, :func:`~pde2cad.surfaces.patch.fit_patch` with those sides: bilinear Coons +
   sine deformation (C0), or bicubic Coons with the shared ribbons of
   :func:`~pde2cad.layout.ribbons.build_ribbons` + C1 deformation (C1).
4. :func:`~pde2cad.bspline.convert.patch_to_bspline`, faces and :func:`~pde2cad.occ.sew`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from pde2cad.bspline.convert import patch_to_bspline
from pde2cad.bspline.data import BSplineSurface
from pde2cad.errors import FitError, InputError
from pde2cad.layout import Layout, build_layout
from pde2cad.layout.edges import EdgeNetwork, build_edges
from pde2cad.layout.ribbons import shared_ribbons
from pde2cad.layout.split import SplitReport, split_segments
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.patch import Patch, fit_patch

#: Default CAD (deformation -> B-spline) tolerance, relative to the cloud's bbox diagonal.
CAD_TOLERANCE = 1e-4
#: Sewing tolerance relative to the diagonal (shared edges are identical curves).
SEW_TOLERANCE = 1e-6
#: With C1, a patch keeps its C0 fit when the C1 fit's mean error is above this multiple of
#: the C0 one (the bicubic base went wrong, e.g. at degenerate corners). Not 2: the flat
#: faces of a sparse ellipsoid (5k points) fit C1 at 2.4-2.65x C0 and their C0 seams read 6.7
#: deg instead of 0.87.
C1_ERROR_RATIO = 3.0
#: ... unless the C1 fit's mean error is below this fraction of the diagonal anyway: tangent
#: continuity is worth a few 1e-5 (an ellipsoid's flat faces: C1 2.6x C0 but 3.9e-5).
C1_ERROR_FLOOR = 5e-5
#: Progress callback: ``progress(stage, done, total)``.
Progress = Callable[[str, int, int], None]


def _report(progress: Progress | None, stage: str, done: int, total: int) -> None:
    if progress is not None:
        progress(stage, done, total)


@dataclass
class Reconstruction:
    """Result of :func:`reconstruct`.

    Attributes
    ----------
    shape : TopoDS_Shape
        Sewn shell (or solid when closed).
    patches : dict[int, Patch]
        Fitted patch per segment label.
    surfaces : dict[int, BSplineSurface]
        B-spline surface per segment label.
    faces : list of TopoDS_Face
        One face per segment, in ``labels`` order.
    labels : list of int
        Segment label of each face.
    sew_info : SewInfo
    layout : Layout
    edges : dict[(int, int), PiecewiseBezier]
        The shared curve of each edge, keyed by sorted global corner ids, running from the
        smaller id to the larger.
    edge_errors : dict[(int, int), float]
        Largest distance of the points fitted to each edge curve (bin means of the border
        band for shared edges).
    corners : (C, 3) float
        The corner positions used (the layout's).
    diagonal : float
        Bounding-box diagonal of the cloud.
    timings : dict[str, float]
        Seconds per stage.
    network : EdgeNetwork
        Corners, side loops, edge curves and their fit errors.
    c0_fallback : list of int
        With ``continuity="c1"``: segments fitted C0 instead (too sparse for ribbons, or
        whose C1 fit was more than ``C1_ERROR_RATIO`` times worse and above
        ``C1_ERROR_FLOOR`` of the diagonal); their edges are only positionally joined.
        3-sided segments are fitted C1 like 4-sided ones (bicubic base with a collapsed top,
        see :func:`~pde2cad.surfaces.coons.apex_ribbon`).
    splits : SplitReport
        The input segments split into 3/4-sided pieces (:mod:`pde2cad.layout.split`) and
        their pieces' labels (the keys of ``patches``).
    """

    shape: Any
    patches: dict[int, Patch]
    surfaces: dict[int, BSplineSurface]
    faces: list[Any]
    labels: list[int]
    sew_info: Any
    layout: Layout
    edges: dict[tuple[int, int], PiecewiseBezier]
    edge_errors: dict[tuple[int, int], float]
    corners: NDArray[np.float64]
    diagonal: float
    timings: dict[str, float] = field(default_factory=dict)
    network: EdgeNetwork | None = None
    c0_fallback: list[int] = field(default_factory=list)
    splits: SplitReport = field(default_factory=SplitReport)

    def write_step(self, path: str | Path, units: str = "MM") -> Path:
        """Write the sewn shape to a STEP file."""
        from pde2cad.occ import write_step

        return write_step(self.shape, path, units=units)


def apex_first(network: EdgeNetwork) -> EdgeNetwork:
    """The network with every 3-sided loop rotated so its apex (``loop[2]``, where the
    collapsed top side of Fig. 5.11 sits) is the corner best suited to it.

    A C1 apex needs every patch at that corner to have its apex there (their ribbons all
    vanish at it, see :func:`~pde2cad.layout.ribbons.shared_ribbons`): the corner chosen is
    the one with the most 3-sided users, then the fewest other users (the pole where
    triangles meet), ties kept as the loop has them. Only the loops' starting corners
    change (a new :class:`EdgeNetwork`; curves and edges are the same objects).
    """
    users: dict[int, list[int]] = {}
    for label, ids in network.loops.items():
        for c in ids:
            users.setdefault(c, []).append(len(ids))
    loops = {}
    for label, ids in network.loops.items():
        if len(ids) != 3:
            loops[label] = ids
            continue
        score = [(users[c].count(3), -(len(users[c]) - users[c].count(3))) for c in ids]
        best = ids[2]
        for k in (2, 0, 1):
            if score[k] > score[ids.index(best)]:
                best = ids[k]
        r = (ids.index(best) - 2) % 3
        loops[label] = ids[r:] + ids[:r]
    return dataclasses.replace(network, loops=loops)


def reconstruct(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    m: int | str = "auto",
    n: int | str = "auto",
    continuity: str = "c0",
    tolerance: float | None = None,
    cad_tolerance: float | None = None,
    progress: Progress | None = None,
) -> Reconstruction:
    """Reconstruct a segmented cloud as C0-joined B-spline faces sewn into one shape.

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
        One segment label per point. A segment with more than 4 corners (merged patches, a
        neighbour's corner on its side) is split into 3/4-sided pieces, see ``splits``.
    m, n : int or "auto"
        Deformation terms per patch (see :func:`~pde2cad.surfaces.patch.fit_patch`).
        ``"auto"`` (default): per patch, the ``M = N`` that best predicts held-out points
        (6 to 16; clean random clouds: 3-8x lower true error than a fixed 6, noisy ones
        unchanged).
    continuity : {"c0", "c1"}
        ``"c0"``: neighbours share edge curves (positional continuity). ``"c1"``: they also
        share cross-boundary derivatives (tangent continuity wherever the edges pair up
        across corners; near corners where 3 or 5 patches meet only approximately).
    tolerance : float, optional
        Target for each patch's largest error to its points (model units): each patch uses
        the fewest deformation terms that reach it (``m``, ``n`` ignored). Raises
        :class:`~pde2cad.errors.FitError` when a patch cannot reach it (noise, or a
        tolerance below the edge-curve fit error).
    cad_tolerance : float, optional
        Tolerance of the deformation -> B-spline conversion. Default 1e-4 x the cloud's
        bounding-box diagonal.
    progress : callable, optional
        Called as ``progress(stage, done, total)`` with stages ``"layout"``, ``"edges"``,
        ``"patches"`` (after each patch) and ``"cad"``.

    Returns
    -------
    Reconstruction
    """
    from pde2cad.occ import make_face, sew  # OCP is optional: imported only here

    pts = np.asarray(points, dtype=float)
    lab = np.asarray(labels).astype(np.int64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(lab) != len(pts):
        raise InputError(f"points must be (N, 3) with one label each; got {pts.shape}, {lab.shape}")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be a positive number, got {tolerance}")
    if continuity not in ("c0", "c1"):
        raise InputError(f"continuity must be 'c0' or 'c1', got {continuity!r}")
    diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    _report(progress, "layout", 0, 1)
    layout = build_layout(pts, lab, check=False)
    # The layout's own KD-tree of the points when it keeps one; otherwise a sliding-midpoint
    # tree (a third faster to build on a million points, the same exact queries).
    tree = getattr(layout, "tree", None)
    if tree is None:
        tree = cKDTree(pts, balanced_tree=False)
    # Segments with 5+ corners (merged patches, T-junctions) -> 3/4-sided pieces, new labels.
    lab, layout, splits = split_segments(pts, lab, layout, tree)
    timings["layout"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    _report(progress, "edges", 0, 1)
    network = build_edges(pts, lab, layout, tree)
    if continuity == "c1":
        # 3-sided patches: put their apex where a C1 pole can form (e.g. triangles around it).
        network = apex_first(network)
    timings["edges"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    patches: dict[int, Patch] = {}
    order = sorted(network.loops)
    steps = len(order) * (2 if continuity == "c1" else 1)
    for done, label in enumerate(order):
        _report(progress, "patches", done, steps)
        patches[label] = fit_patch(
            pts[lab == label], continuity="c0", m=m, n=n, tolerance=tolerance,
            boundary=network.sides(label),
        )
    fallback: list[int] = []
    if continuity == "c1":
        # The ribbons are estimated from the C0 fits' own parameters (no second projection).
        ribbons = shared_ribbons(network, patches)
        fallback = [label for label in order if label not in ribbons]
        for done, label in enumerate(order, start=len(order)):
            _report(progress, "patches", done, steps)
            if label not in ribbons:
                continue
            c0 = patches[label]
            try:
                # Same points and sides as the C0 fit: reuse its bilinear parameters, and
                # its automatic term count (the same shape detail on the same points).
                m1, n1 = (c0.deformation.m, c0.deformation.n) if m == "auto" else (m, n)
                c1 = fit_patch(
                    c0.points, continuity="c1", m=m1, n=n1, tolerance=tolerance,
                    boundary=c0.sides, ribbons=ribbons[label], params=c0.params,
                    outside=c0.outside,
                )
            except FitError:
                c1 = None
            # A bicubic base can misbehave near degenerate corners (two sides tangent) and
            # creases (measured on the pot: 4 of its 9 patches): keep the C0 fit then, and
            # say so in c0_fallback.
            # fit_errors: the fit's own mean (Patch.errors would project every point again).
            if c1 is not None and c1.fit_errors["mean"] <= max(
                C1_ERROR_RATIO * c0.fit_errors["mean"], C1_ERROR_FLOOR * diagonal
            ):
                patches[label] = c1
            else:
                fallback.append(label)
    _report(progress, "patches", steps, steps)
    timings["patches"] = time.perf_counter() - t0

    # Step 4: B-splines, faces, sewing.
    t0 = time.perf_counter()
    cad_tol = float(cad_tolerance) if cad_tolerance is not None else CAD_TOLERANCE * diagonal
    _report(progress, "cad", 0, 1)
    surfaces = {
        label: patch_to_bspline(p.base, p.deformation, cad_tol) for label, p in patches.items()
    }
    faces = [make_face(surfaces[label]) for label in order]
    shape, info = sew(faces, tolerance=SEW_TOLERANCE * diagonal)
    _report(progress, "cad", 1, 1)
    timings["cad"] = time.perf_counter() - t0
    return Reconstruction(
        shape=shape,
        patches=patches,
        surfaces=surfaces,
        faces=faces,
        labels=order,
        sew_info=info,
        layout=layout,
        edges=network.curves,
        corners=network.corners,
        edge_errors=network.errors,
        network=network,
        c0_fallback=fallback,
        splits=splits,
        diagonal=diagonal,
        timings=timings,
    )
