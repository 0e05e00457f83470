"""Multi-patch reconstruction of a segmented point cloud: cloud -> B-spline surfaces -> shape.

Two stages, split at the CAD kernel:

- :func:`fit_surfaces` (numpy/scipy only, runs inside FreeCAD's Python too) makes the
  kernel-neutral :class:`SurfaceModel`:

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
  4. :func:`~pde2cad.bspline.convert.patch_to_bspline` per patch.

- A kernel adapter turns the model into a shape: :func:`pde2cad.occ.build.build_shape` (OCP:
  faces, sewing; :func:`reconstruct` uses it) or ``pde2cad.fc.shape.build_shape`` (FreeCAD).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from pde2cad.bspline.convert import patch_to_bspline
from pde2cad.bspline.data import BSplineSurface
from pde2cad.errors import FitError, InputError
from pde2cad.frame import Frame
from pde2cad.io.clouds import as_labels, first_of_repeats
from pde2cad.layout import Layout, build_layout
from pde2cad.layout.edges import EdgeNetwork, build_edges
from pde2cad.layout.known import KnownCorners, with_known_corners
from pde2cad.layout.ribbons import shared_ribbons
from pde2cad.layout.split import SplitReport, split_segments
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.patch import Continuity, Patch, fit_patch

if TYPE_CHECKING:
    import build123d
    import cadquery

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
#: ... and not when its deformation somewhere on the patch is more than this multiple of its
#: largest at the points (swinging out where no point holds it: a 3-sided piece of a k-means
#: capsule measured 46x, 3e-2 of the diagonal off the capsule; sound fits stay under 1.7x).
C1_SWING_RATIO = 4.0
#: Progress callback: ``progress(stage, done, total)``.
Progress = Callable[[str, int, int], None]


def _report(progress: Progress | None, stage: str, done: int, total: int) -> None:
    if progress is not None:
        progress(stage, done, total)


@dataclass
class SurfaceModel:
    """Kernel-neutral result of :func:`fit_surfaces`: everything a CAD adapter needs.

    All geometry is in the caller's coordinates (the fit itself runs in a centred,
    normalised frame, see :func:`fit_surfaces`).

    Attributes
    ----------
    surfaces : dict[int, BSplineSurface]
        B-spline surface per segment label.
    labels : list of int
        Segment labels in face order (sorted).
    patches : dict[int, Patch]
        Fitted patch per segment label.
    network : EdgeNetwork
        Corners, side loops, edge curves and their fit errors.
    layout : Layout
        Adjacency, borders and rough corners (without its KD-tree).
    edges : dict[(int, int), PiecewiseBezier]
        The shared curve of each edge, keyed by sorted global corner ids, running from the
        smaller id to the larger (``network.curves``).
    edge_errors : dict[(int, int), float]
        Largest distance of the points fitted to each edge curve (bin means of the border
        band for shared edges).
    corners : (C, 3) float
        The corner positions used (the network's).
    diagonal : float
        Bounding-box diagonal of the cloud.
    c0_fallback : list of int
        With ``continuity="c1"``: segments fitted C0 instead (too sparse for ribbons, or
        whose C1 fit was more than ``C1_ERROR_RATIO`` times worse and above
        ``C1_ERROR_FLOOR`` of the diagonal, or whose deformation swings out between the
        points, ``C1_SWING_RATIO``); their edges are only positionally joined.
        3-sided segments are fitted C1 like 4-sided ones (bicubic base with a collapsed top,
        see :func:`~pde2cad.surfaces.coons.apex_ribbon`).
    timings : dict[str, float]
        Seconds per stage.
    splits : SplitReport
        The input segments split into 3/4-sided pieces (:mod:`pde2cad.layout.split`) and
        their pieces' labels (the keys of ``patches``).
    frame : Frame
        The centred, normalised frame the fit ran in (``local = (world - centre) / scale``).
    """

    surfaces: dict[int, BSplineSurface]
    labels: list[int]
    patches: dict[int, Patch]
    network: EdgeNetwork
    layout: Layout
    edges: dict[tuple[int, int], PiecewiseBezier]
    edge_errors: dict[tuple[int, int], float]
    corners: NDArray[np.float64]
    diagonal: float
    c0_fallback: list[int] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    splits: SplitReport = field(default_factory=SplitReport)
    frame: Frame | None = None

    @property
    def sew_tolerance(self) -> float:
        """Tolerance for sewing the faces (``SEW_TOLERANCE`` x diagonal; shared edges are
        identical curves, so any kernel can sew this tight)."""
        return SEW_TOLERANCE * self.diagonal


@dataclass
class Reconstruction:
    """Result of :func:`reconstruct`: a :class:`SurfaceModel` made into an OCP shape.

    Attributes
    ----------
    shape : TopoDS_Shape
        Sewn shell (or solid when closed).
    patches, surfaces, labels, layout, edges, edge_errors, corners, diagonal, timings,
    network, c0_fallback, splits
        As in :class:`SurfaceModel`.
    faces : list of TopoDS_Face
        One face per segment, in ``labels`` order.
    sew_info : SewInfo
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

    def write_step(
        self, path: str | Path, units: str = "MM", *, schema: str = "AP214",
        name: str | None = None, author: str | None = None, organization: str | None = None,
    ) -> Path:
        """Write the sewn shape to a STEP file, faces named after their segments (see
        :func:`pde2cad.occ.export.export_step`)."""
        from pde2cad.occ.export import export_step

        return export_step(self, path, schema=schema, units=units, name=name, author=author,
                           organization=organization)

    def write_iges(
        self, path: str | Path, units: str = "MM", *, name: str | None = None,
        author: str | None = None, organization: str | None = None,
    ) -> Path:
        """Write the sewn shape to an IGES file (see :func:`pde2cad.occ.export.export_iges`)."""
        from pde2cad.occ.export import export_iges

        return export_iges(self, path, units=units, name=name, author=author,
                           organization=organization)

    def to_build123d(self) -> build123d.Shape:
        """The shape as a build123d ``Solid`` (closed) or ``Shell`` (open)."""
        from pde2cad.occ import to_build123d

        return to_build123d(self.shape)

    def to_cadquery(self) -> cadquery.Shape:
        """The shape as a CadQuery ``Solid`` (closed) or ``Shell`` (open)."""
        from pde2cad.occ import to_cadquery

        return to_cadquery(self.shape)


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


Terms = Union[int, Literal["auto"]]


def check_cloud(points: ArrayLike, labels: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Validate a labelled cloud at the API's door.

    Parameters
    ----------
    points : (N, 3) array_like of numbers
    labels : (N,) array_like of integers (or floats that are whole numbers)

    Returns
    -------
    points : (N, 3) float
    labels : (N,) int64

    Raises
    ------
    InputError
        Wrong types (strings, None, ragged lists), wrong shapes, NaN/inf coordinates, a
        label count that differs from the point count, or labels that are not whole numbers.
    """
    try:
        raw = np.asarray(points)
    except (TypeError, ValueError) as exc:
        raise InputError(f"points must be an (N, 3) array of numbers; could not read them ({exc})") from None
    if raw.dtype.kind not in "iuf" or raw.ndim != 2 or raw.shape[1] != 3 or len(raw) == 0:
        raise InputError(
            f"points must be an (N, 3) array of numbers, got shape {raw.shape} of dtype {raw.dtype}"
        )
    pts = raw.astype(np.float64)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise InputError(
            f"points contain {int(bad.sum())} NaN/inf coordinates (first at point "
            f"{int(np.flatnonzero(bad)[0])}); drop or repair them first"
        )
    if labels is None or isinstance(labels, (str, bytes)):
        raise InputError(f"labels must be one integer per point, got {labels!r}")
    try:
        lab = np.asarray(labels)
    except (TypeError, ValueError) as exc:
        raise InputError(f"labels must be one integer per point; could not read them ({exc})") from None
    return pts, as_labels(lab, len(pts), "the labels argument")


def _check_options(m: object, n: object, continuity: str, tolerance: float | None,
                   cad_tolerance: float | None) -> None:
    for name, terms in (("m", m), ("n", n)):
        if terms != "auto" and (isinstance(terms, bool)
                                or not isinstance(terms, (int, np.integer)) or terms < 1):
            raise InputError(f'{name} must be a whole number >= 1 or "auto", got {terms!r}')
    for name, value in (("tolerance", tolerance), ("cad_tolerance", cad_tolerance)):
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
            raise InputError(f"{name} must be a positive number, got {value!r}")
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number, got {value}")
    if continuity not in ("c0", "c1"):
        raise InputError(f"continuity must be 'c0' or 'c1', got {continuity!r}")


def _distinct(
    world: NDArray[np.float64], lab: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The points without exact repeats, the first of each kept, in input order (every point
    repeated left no nearest-neighbour spacing: "all points coincide")."""
    keep = first_of_repeats(world)
    return (world, lab) if keep is None else (world[keep], lab[keep])


def _build_network(
    pts: NDArray[np.float64], lab: NDArray[np.int64], continuity: str,
    timings: dict[str, float], progress: Progress | None, corners: KnownCorners | None = None,
    fenced: bool = False,
) -> tuple[NDArray[np.int64], Layout, EdgeNetwork, SplitReport]:
    """Steps 1-2 of :func:`fit_surfaces`: the layout (segments that are no 3/4-sided
    region relabelled into pieces; with known ``corners``, those corners instead), then the
    edge network; returns the piece labels too."""
    t0 = time.perf_counter()
    _report(progress, "layout", 0, 1)
    layout = build_layout(pts, lab, check=False)
    # The layout's own KD-tree of the points when it keeps one; otherwise a sliding-midpoint
    # tree (a third faster to build on a million points, the same exact queries).
    tree = getattr(layout, "tree", None)
    if tree is None:
        tree = cKDTree(pts, balanced_tree=False)
    if corners is not None:
        layout, splits = with_known_corners(layout, corners, pts, lab, tree), SplitReport()
    else:
        # Segments with 5+ corners (merged patches, T-junctions) -> 3/4-sided pieces.
        lab, layout, splits = split_segments(pts, lab, layout, tree, fenced)
    timings["layout"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    _report(progress, "edges", 0, 1)
    # Seams the split cut through one segment: fitted fair (build_edges).
    cuts = {frozenset((a, b)) for pieces in splits.pieces.values()
            for a in pieces for b in pieces if a != b}
    network = build_edges(pts, lab, layout, tree, cuts)
    if continuity == "c1":
        # 3-sided patches: put their apex where a C1 pole can form (e.g. triangles around it).
        network = apex_first(network)
    timings["edges"] = time.perf_counter() - t0
    return lab, layout, network, splits


def _swing(patch: Patch) -> float:
    """The patch's largest deformation (distance to its base) on a 21 x 21 parameter grid
    over its largest at the points' own parameters."""
    g = np.linspace(0.0, 1.0, 21)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    q = patch.params[~patch.outside]
    grid = np.linalg.norm(patch.evaluate(u, v) - patch.base.evaluate(u, v), axis=1).max()
    at = np.linalg.norm(patch.evaluate(q[:, 0], q[:, 1]) - patch.base.evaluate(q[:, 0], q[:, 1]), axis=1)
    return float(grid / max(float(at.max(initial=0.0)), 1e-12))


def _swings(c1: Patch, c0: Patch) -> bool:
    """Whether the C1 fit swings out between the points (``_swing`` above
    ``C1_SWING_RATIO``) where the C0 fit swings less (on a k-means capsule some C0 fits
    swing too, 3x further off the capsule than their C1 fits: those stay C1)."""
    ratio = _swing(c1)
    return ratio > C1_SWING_RATIO and ratio > _swing(c0)


def _fit_c1(
    patches: dict[int, Patch], network: EdgeNetwork, m: Terms, n: Terms,
    tolerance: float | None, tick: Callable[[], None],
) -> list[int]:
    """Refit every patch C1 on the shared ribbons; returns the labels kept C0."""
    order = sorted(patches)
    # The ribbons are estimated from the C0 fits' own parameters (no second projection).
    ribbons = shared_ribbons(network, patches)
    fallback = [label for label in order if label not in ribbons]
    for label in order:
        tick()
        if label not in ribbons:
            continue
        c0 = patches[label]
        try:
            # Same points and sides as the C0 fit: reuse its bilinear parameters, and
            # its automatic term count (the same shape detail on the same points).
            m1, n1 = (c0.deformation.m, c0.deformation.n) if m == "auto" else (m, n)
            c1: Patch | None = fit_patch(
                c0.points, continuity="c1", m=m1, n=n1, tolerance=tolerance,
                boundary=c0.sides, ribbons=ribbons[label], params=c0.params,
                outside=c0.outside,
            )
        except FitError:
            c1 = None
        # A bicubic base can misbehave near degenerate corners (two sides tangent) and
        # creases (measured on the pot: 4 of its 9 patches), and a deformation swing out
        # between the points: keep the C0 fit then, and say so in c0_fallback.
        # fit_errors: the fit's own mean (Patch.errors would project every point again).
        if c1 is not None and c1.fit_errors["mean"] <= max(
            C1_ERROR_RATIO * c0.fit_errors["mean"], C1_ERROR_FLOOR  # x the unit diagonal
        ) and not _swings(c1, c0):
            patches[label] = c1
        else:
            fallback.append(label)
    return fallback


def _fit_patches(
    pts: NDArray[np.float64], lab: NDArray[np.int64], network: EdgeNetwork, m: Terms,
    n: Terms, continuity: str, tolerance: float | None, progress: Progress | None,
) -> tuple[dict[int, Patch], list[int]]:
    """Step 3 of :func:`fit_surfaces`: one C0 patch per segment, then (C1) the C1 refits.

    In the working frame (unit diagonal): ``tolerance`` already divided by the scale."""
    order = sorted(network.loops)
    steps = len(order) * (2 if continuity == "c1" else 1)
    done = iter(range(steps))

    def tick() -> None:
        _report(progress, "patches", next(done), steps)

    patches: dict[int, Patch] = {}
    for label in order:
        tick()
        patches[label] = fit_patch(
            pts[lab == label], continuity="c0", m=m, n=n, tolerance=tolerance,
            boundary=network.sides(label),
        )
    fallback = _fit_c1(patches, network, m, n, tolerance, tick) if continuity == "c1" else []
    _report(progress, "patches", steps, steps)
    return patches, fallback


def fit_surfaces(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    m: Terms = "auto",
    n: Terms = "auto",
    continuity: Continuity = "c0",
    tolerance: float | None = None,
    cad_tolerance: float | None = None,
    progress: Progress | None = None,
    corners: KnownCorners | None = None,
    sharp_borders: bool = False,
) -> SurfaceModel:
    """Fit one B-spline surface per segment of a labelled cloud, joined on shared edges.

    The kernel-neutral stage of :func:`reconstruct` (numpy/scipy only): no CAD kernel is
    imported, so it runs in FreeCAD's Python as well as with OCP.

    1. Validate the cloud (:func:`check_cloud`) and the options; move the cloud into a
       centred frame with a unit diagonal (:class:`~pde2cad.frame.Frame`), so the result
       does not depend on where the cloud sits or its unit.
    2. Layout and edge network (:func:`_build_network`).
    3. Patches, C0 then optionally C1 (:func:`_fit_patches`).
    4. Each patch to a B-spline surface within ``cad_tolerance``; surfaces, patches, edges,
       corners and errors mapped back to the caller's coordinates.

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
    corners : KnownCorners, optional
        The corners of every segment when the layout knows them (an automatic layout's
        coarse mesh, :mod:`pde2cad.layout.known`): used instead of the corners inferred
        from the labels, and no segment is split.
    sharp_borders : bool
        Every border between segments is a sharp edge (crease-bounded regions of a part):
        the pieces of split segments never merge across them.

    Returns
    -------
    SurfaceModel
    """
    world, lab = _distinct(*check_cloud(points, labels))
    _check_options(m, n, continuity, tolerance, cad_tolerance)
    frame = Frame.of(world)
    pts = frame.to_local(world)
    timings: dict[str, float] = {}
    known = None if corners is None else corners.moved(frame.to_local)
    lab, layout, network, splits = _build_network(pts, lab, continuity, timings, progress, known,
                                                  sharp_borders)

    t0 = time.perf_counter()
    try:
        patches, fallback = _fit_patches(
            pts, lab, network, m, n, continuity, frame.length_to_local(tolerance), progress
        )
    except FitError as exc:
        # The fit ran in the working frame: its figures are fractions of the diagonal.
        raise FitError(f"{exc} (lengths in this message are fractions of the cloud's "
                       f"bounding-box diagonal, {frame.scale:.6g} in its units)") from exc
    timings["patches"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    cad_tol = CAD_TOLERANCE if cad_tolerance is None else cad_tolerance / frame.scale
    _report(progress, "cad", 0, 1)
    surfaces = {
        label: frame.surface(patch_to_bspline(p.base, p.deformation, cad_tol))
        for label, p in patches.items()
    }
    world_net = frame.network(network)
    world_patches: dict[int, Patch] = {
        label: frame.patch(p, world[lab == label]) for label, p in patches.items()
    }
    timings["bspline"] = time.perf_counter() - t0
    return SurfaceModel(
        surfaces=surfaces, labels=sorted(patches), patches=world_patches, network=world_net,
        layout=frame.layout(layout), edges=world_net.curves,
        edge_errors=world_net.errors, corners=world_net.corners, diagonal=frame.scale,
        c0_fallback=fallback, timings=timings, splits=splits, frame=frame,
    )


def reconstruct(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    m: Terms = "auto",
    n: Terms = "auto",
    continuity: Continuity = "c0",
    tolerance: float | None = None,
    cad_tolerance: float | None = None,
    progress: Progress | None = None,
    corners: KnownCorners | None = None,
    sharp_borders: bool = False,
) -> Reconstruction:
    """Reconstruct a segmented cloud as B-spline faces sewn into one OCP shape.

    :func:`fit_surfaces` followed by the OCP adapter
    :func:`pde2cad.occ.build.build_shape` (faces, sewing; needs ``pde2cad[cad]``).
    Parameters as in :func:`fit_surfaces`.

    Returns
    -------
    Reconstruction
    """
    model = fit_surfaces(
        points, labels, m=m, n=n, continuity=continuity, tolerance=tolerance,
        cad_tolerance=cad_tolerance, progress=progress, corners=corners,
        sharp_borders=sharp_borders,
    )
    from pde2cad.occ.build import build_shape  # OCP is optional: imported only here

    t0 = time.perf_counter()
    shape, faces, info = build_shape(model)
    _report(progress, "cad", 1, 1)
    timings = dict(model.timings)
    timings["cad"] = timings.pop("bspline") + time.perf_counter() - t0
    return Reconstruction(
        shape=shape, patches=model.patches, surfaces=model.surfaces, faces=faces,
        labels=model.labels, sew_info=info, layout=model.layout, edges=model.edges,
        edge_errors=model.edge_errors, corners=model.corners, diagonal=model.diagonal,
        timings=timings, network=model.network, c0_fallback=model.c0_fallback,
        splits=model.splits,
    )
