"""Automatic patch layout: a coarse quad mesh of the surface -> one segment label per point.

The reconstruction pipeline (:func:`pde2cad.reconstruct.reconstruct`) needs every point to
carry the label of a 3- or 4-sided region. A coarse quad(-dominant) mesh of the same surface
(from a field-aligned remesher, see :mod:`pde2cad.io.meshes`) is such a layout: each of its
faces is a patch, its vertices of valence != 4 are the corners where 3 or 5 patches meet.
This module turns it into labels, with numpy/scipy only:

1. :func:`quads_of` pairs the remesher's triangles back into quads (it returns each quad as
   two consecutive triangles) and checks that the faces form a manifold;
   :func:`dissolve_doublets` merges the two faces around each valence-2 vertex.
2. :func:`best_layout`: of a few remeshes, each relaxed on the surface
   (:func:`relax_layout`), the one whose worst face corner (:func:`layout_quality`,
   :func:`corner_angles`) is farthest from 0 and 180 deg.
3. :func:`label_points`: every point takes the face its normal line meets first (the
   coarse mesh projected onto the surface along the normals).
4. Creases of a mesh input: :func:`crease_regions` (triangles joined across non-crease
   edges), :func:`point_regions` (each point's region), :func:`single_patch_regions`
   (flat-ish disks that are one patch each).
5. :func:`clean_labels`: a face that the projection splits into several pieces (where the
   coarse mesh cuts a thin part or lies off a strongly curved one) keeps its largest piece;
   the smaller pieces join the neighbour label they touch most, so every segment is one
   connected region as the pipeline requires; with regions, no segment crosses a crease.
6. :func:`layout_summary`: patches, sides per patch, corner valences, components and the
   creases of the input (:func:`crease_edges`), for the report.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.layout.creases import crease_mask
from pde2cad.layout.known import KnownCorners

#: Samples per face side when faces are sampled for the nearest-face rule: a face's samples
#: lie 1/SAMPLES_PER_SIDE of its side apart, well below a patch's width.
SAMPLES_PER_SIDE = 8
#: Coarse triangles (nearest centroids) whose intersection with a point's normal line is
#: tested: a coarse vertex has at most ~2 x 6 fan triangles around it.
CANDIDATES = 16
#: Smoothing passes of the coarse mesh and the fraction of the way to the neighbours'
#: centroid per pass (:func:`relax_layout`).
RELAX_ITERATIONS = 10
RELAX_STEP = 0.5
#: Coarse meshes tried by :func:`best_layout`, and the :func:`layout_quality` (deg) that
#: ends the search (clean ellipsoid layouts measured <= 133 after relaxing, folded or
#: rejected ones >= 141).
LAYOUT_TRIES = 4
GOOD_LAYOUT = 136.0
#: Largest normal turn (deg) of a crease-bounded disk that becomes a single patch.
SINGLE_PATCH_TURN = 60.0
#: Nearest triangle samples whose triangles compete for a point in :func:`point_regions`.
REGION_CANDIDATES = 6
#: Neighbours whose principal axes give a point's normal.
NORMAL_NEIGHBOURS = 16
#: Neighbours per point of the graph that decides connectivity of the labels.
GRAPH_NEIGHBOURS = 8
#: Fewest points per patch: the pipeline fits an edge-curve band and a deformation per patch;
#: a face with fewer points is merged into its neighbours.
MIN_PATCH_POINTS = 60
#: Default dihedral angle (degrees) above which an edge of the input mesh is a crease.
CREASE_ANGLE = 30.0
#: Percentile of the edge curvatures taken as the surface's (robust) largest curvature.
CURVATURE_PERCENTILE = 90.0
#: Patch side over that radius of curvature: a patch turns by at most ~this many radians,
#: so it stays a height field over its plane (a torus tube in quarters fails, see tests).
TURN_PER_PATCH = 1.0


@dataclass
class AutoLayout:
    """Result of :func:`auto_labels`.

    Attributes
    ----------
    labels : (N,) int64
        Segment label per point, 0 .. P-1.
    vertices : (V, 3) float
        The coarse mesh's vertices.
    faces : list of tuple of int
        The coarse mesh's faces (3 or 4 vertex ids); face ``i`` is label ``i`` unless it was
        merged away (then it is missing from ``labels``).
    summary : dict
        See :func:`layout_summary`.
    corners : KnownCorners or None
        The coarse vertices as every segment's corners (:func:`known_corners`), or None
        where the labels no longer match the faces one to one.
    """

    labels: NDArray[np.int64]
    vertices: NDArray[np.float64]
    faces: list[tuple[int, ...]]
    summary: dict[str, object] = field(default_factory=dict)
    corners: KnownCorners | None = None


def quads_of(triangles: ArrayLike) -> list[tuple[int, ...]]:
    """The faces of a remesher's triangulated quad(-dominant) output.

    Consecutive triangles ``(a, b, c), (a, c, d)`` sharing two vertices are one quad
    ``(a, b, c, d)``; a triangle without such a partner stays a triangle.

    Parameters
    ----------
    triangles : (F, 3) int

    Returns
    -------
    list of tuple of int
        Faces as vertex-id cycles.
    """
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    faces: list[tuple[int, ...]] = []
    i = 0
    while i < len(tri):
        a = tri[i]
        if i + 1 < len(tri):
            b = tri[i + 1]
            common = set(a.tolist()) & set(b.tolist())
            if len(common) == 2:
                odd = [v for v in b.tolist() if v not in common][0]
                # Insert the partner's free vertex between the two shared ones of ``a``.
                k = [j for j in range(3) if a[j] in common and a[(j + 1) % 3] in common][0]
                cyc = a.tolist()
                faces.append(tuple(cyc[: k + 1] + [odd] + cyc[k + 1 :]))
                i += 2
                continue
        faces.append(tuple(a.tolist()))
        i += 1
    return faces


def dissolve_doublets(faces: list[tuple[int, ...]]) -> list[tuple[int, ...]]:
    """Faces without doublets: an interior vertex of valence 2 is removed, its two faces merged.

    Two faces sharing both edges at a vertex ``v`` (a *doublet*, which quad remeshers leave
    now and then) make a layout the pipeline cannot fit: ``v`` is a border kink between two
    segments, so it is no corner, and each face becomes a 3-sided patch whose side bends by
    ~180 deg there; their Coons bases fold (measured: every folded patch of a (2, 1, 1)
    ellipsoid layout, seams at 180 deg). Merging ``(v, a, x, b)`` and ``(v, b, y, a)`` into
    ``(a, x, b, y)`` is the usual doublet collapse.

    1. Per vertex, the faces that hold it; a vertex in exactly two faces whose neighbours in
       both are the same two vertices is a doublet (a boundary vertex of valence 2 is not).
    2. Its faces are merged (each rotated to start at ``v``: ``A[1:] + B[2:-1]``); merging
       can make a neighbour a doublet, so this repeats until none is left.
    """
    out = [tuple(f) for f in faces]
    for _ in range(len(out)):
        holders: dict[int, list[int]] = {}
        for i, cyc in enumerate(out):
            for v in cyc:
                holders.setdefault(v, []).append(i)
        merged = None
        for v, owners in holders.items():
            if len(owners) != 2:
                continue
            a, b = (_rotated(out[i], v) for i in owners)
            if {a[1], a[-1]} != {b[1], b[-1]}:
                continue
            face = a[1:] + b[2:-1]
            if len(set(face)) == len(face) >= 3:
                merged = (owners, face)
                break
        if merged is None:
            break
        (i, j), face = merged
        out = [f for k, f in enumerate(out) if k not in (i, j)] + [face]
    return out


def face_edges(faces: list[tuple[int, ...]]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Undirected edges of a polygon mesh (sorted vertex pairs) and how many faces use each."""
    ed = np.asarray([(f[j], f[(j + 1) % len(f)]) for f in faces for j in range(len(f))],
                    dtype=np.int64).reshape(-1, 2)
    return np.unique(np.sort(ed, axis=1), axis=0, return_counts=True)


def relax_layout(
    points: NDArray[np.float64], vertices: NDArray[np.float64], faces: list[tuple[int, ...]],
    iterations: int = RELAX_ITERATIONS, step: float = RELAX_STEP,
    normals: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """The coarse mesh's vertices moved on the surface towards their neighbours' centroid.

    A field-aligned remesher leaves some corners of 3 faces with one face angle near 180 deg
    (the vertex sits on the line of two of its neighbours, a "T"); the patch there has two
    near-collinear sides at a corner, its Coons base degenerates and folds (measured on
    ellipsoid layouts: every folded one had a 3-valent angle of 144-167 deg, the clean ones
    at most 130). Tangential smoothing turns such T's into Y's and evens the face sizes.

    1. Neighbours from the faces' edges; vertices on an open boundary (edges of one face)
       stay where they are.
    2. ``iterations`` times: each free vertex moves ``step`` of the way to its neighbours'
       centroid, within its tangent plane, then onto the tangent plane of its nearest point
       (the surface: points with ``normals``, :func:`point_normals` when not given).
    3. The vertices after the pass with the best :func:`layout_quality` are returned (the
       input's when no pass improves it: smoothing a curved surface's mesh for long drifts).
    """
    verts = np.array(vertices, dtype=np.float64)
    edges, uses = face_edges(faces)
    if len(edges) == 0:
        return verts
    if normals is None:
        normals = point_normals(points)
    fixed = np.zeros(len(verts), dtype=bool)
    fixed[edges[uses == 1].ravel()] = True
    both = np.concatenate([edges, edges[:, ::-1]])
    degree = np.bincount(both[:, 0], minlength=len(verts)).astype(np.float64)
    used = degree > 0
    tree = cKDTree(points)
    best, best_score = verts.copy(), layout_quality(verts, faces)
    for _ in range(iterations):
        total = np.zeros_like(verts)
        np.add.at(total, both[:, 0], verts[both[:, 1]])
        target = total[used] / degree[used, None]
        _, near = tree.query(verts[used], workers=-1)
        n = normals[near]
        move = step * (target - verts[used])
        moved = verts[used] + move - n * np.einsum("ij,ij->i", move, n)[:, None]
        moved -= n * np.einsum("ij,ij->i", moved - points[near], n)[:, None]
        free = ~fixed[used]
        verts[np.flatnonzero(used)[free]] = moved[free]
        score = layout_quality(verts, faces)
        if score < best_score:
            best, best_score = verts.copy(), score
    return best


def best_layout(
    points: NDArray[np.float64],
    remesh: Callable[[int], tuple[NDArray[np.float64], list[tuple[int, ...]]]],
    tries: int = LAYOUT_TRIES, normals: NDArray[np.float64] | None = None,
    relax: bool = True,
) -> tuple[NDArray[np.float64], list[tuple[int, ...]], float]:
    """The best of a few coarse meshes (``remesh(i)``, i = 0, 1, ...), each relaxed on the
    surface.

    Remeshing costs a second or two, a reconstruction ten times that; so the layouts are
    ranked by :func:`layout_quality` before any is fitted.

    1. Up to ``tries`` times: ``remesh(i)``, then :func:`relax_layout` (if ``relax``).
    2. Stop at the first whose quality is at most ``GOOD_LAYOUT`` deg; else keep the best.

    Returns
    -------
    vertices, faces, quality
    """
    if normals is None and relax:
        normals = point_normals(points)
    best: tuple[NDArray[np.float64], list[tuple[int, ...]], float] | None = None
    for i in range(max(1, tries)):
        vertices, faces = remesh(i)
        if relax:
            vertices = relax_layout(points, vertices, faces, normals=normals)
        score = layout_quality(vertices, faces)
        if best is None or score < best[2]:
            best = (vertices, faces, score)
        if score <= GOOD_LAYOUT:
            break
    assert best is not None
    return best


def layout_quality(vertices: NDArray[np.float64], faces: list[tuple[int, ...]]) -> float:
    """How far the worst face corner of a coarse mesh is from a fittable one (degrees).

    ``max(largest corner angle, 180 - smallest)`` (:func:`corner_angles`): a corner near
    180 deg makes two sides of a patch collinear and its Coons base folds; near 0 the patch
    is a sliver. Measured on ellipsoid layouts: clean ones at most ~130, folded ones or ones
    the pipeline rejects (a border without corners) 144 and more.
    """
    if not faces:
        return 0.0
    ang, _ = corner_angles(vertices, faces)
    return float(max(ang.max(), 180.0 - ang.min()))


def corner_angles(vertices: NDArray[np.float64], faces: list[tuple[int, ...]]
                  ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Each face's angle at each of its corners (degrees, in the corner's tangent plane) and
    the corner's valence (faces around it).

    The tangent plane's normal is the sum of the unit normals of the faces at the vertex,
    each signed to agree with the first one there (a remesher's faces need not be wound
    consistently). The angle is unsigned, 0 .. 180: a reflex corner (a fold of the layout)
    reads as 360 minus it, still far from a fittable corner's.

    Returns
    -------
    angle, valence : (sum of face sizes,) float and int
        In the order of the faces' corners.
    """
    cyc = [np.asarray(f, dtype=np.int64) for f in faces]
    here = np.concatenate(cyc)
    prev = np.concatenate([np.roll(c, 1) for c in cyc])
    nxt = np.concatenate([np.roll(c, -1) for c in cyc])
    a = vertices[nxt] - vertices[here]
    b = vertices[prev] - vertices[here]
    fn = np.cross(a, b)
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    ref = np.zeros_like(vertices)
    ref[here[::-1]] = fn[::-1]  # the first corner's normal at each vertex
    sign = np.where(np.einsum("ij,ij->i", fn, ref[here]) < 0, -1.0, 1.0)
    vn = np.zeros_like(vertices)
    np.add.at(vn, here, sign[:, None] * fn)
    n = vn[here] / np.maximum(np.linalg.norm(vn[here], axis=1, keepdims=True), 1e-300)
    a -= n * np.einsum("ij,ij->i", a, n)[:, None]
    b -= n * np.einsum("ij,ij->i", b, n)[:, None]
    ang = np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1),
                                np.einsum("ij,ij->i", a, b)))
    valence = np.bincount(here, minlength=len(vertices))[here]
    return ang, valence


def _rotated(cycle: tuple[int, ...], v: int) -> tuple[int, ...]:
    """``cycle`` rotated to start at vertex ``v``."""
    k = cycle.index(v)
    return cycle[k:] + cycle[:k]


def _fan(faces: list[tuple[int, ...]]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Triangles of each face (fan from its first vertex) and the face of each triangle."""
    tris, owner = [], []
    for f, cyc in enumerate(faces):
        for j in range(1, len(cyc) - 1):
            tris.append((cyc[0], cyc[j], cyc[j + 1]))
            owner.append(f)
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3), np.asarray(owner, dtype=np.int64)


#: Cells per side of each coarse face in :func:`surface_faces`.
SUBDIVISIONS = 6


def surface_faces(
    points: NDArray[np.float64], vertices: NDArray[np.float64], faces: list[tuple[int, ...]],
    normals: NDArray[np.float64], cells: int = SUBDIVISIONS,
) -> tuple[NDArray[np.float64], list[tuple[int, ...]], NDArray[np.int64]]:
    """The coarse faces laid onto the surface: each a ``cells`` x ``cells`` grid of
    triangle pairs whose vertices lie on the surface.

    A coarse face is a chord through a curved surface; where the surface bends within one
    face (an ear, a tight fillet), the normal lines of its points meet another face first
    and a third label cuts between two neighbours (seen on the Stanford bunny on most
    layouts). A grid on the surface has no such chords.

    1. Each face's bilinear grid (a triangle is a quad with its last corner doubled).
    2. Each grid vertex moves to the tangent plane of its nearest point, twice.

    Returns
    -------
    vertices : (M, 3) float
    triangles : list of 3-tuples
    owner : (T,) int
        The coarse face of each triangle.
    """
    g = np.linspace(0.0, 1.0, cells + 1)
    s_, t_ = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    w = np.column_stack([(1 - s_) * (1 - t_), s_ * (1 - t_), s_ * t_, (1 - s_) * t_])
    quad = np.array([tuple(f) if len(f) == 4 else (f[0], f[1], f[2], f[2]) for f in faces])
    grid = np.einsum("gk,fkd->fgd", w, vertices[quad]).reshape(-1, 3)
    tree = cKDTree(points)
    for _ in range(2):
        _, near = tree.query(grid, workers=-1)
        n = normals[near]
        grid -= n * np.einsum("ij,ij->i", grid - points[near], n)[:, None]
    i, j = (a.ravel() for a in np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij"))
    v00 = i * (cells + 1) + j
    cell = np.column_stack([v00, v00 + cells + 1, v00 + cells + 2, v00 + 1])
    tri = np.concatenate([cell[:, [0, 1, 2]], cell[:, [0, 2, 3]]])
    base = (np.arange(len(faces)) * (cells + 1) ** 2)[:, None, None]
    tris = (tri[None] + base).reshape(-1, 3)
    owner = np.repeat(np.arange(len(faces)), len(tri))
    return grid, [tuple(int(x) for x in t) for t in tris], owner


def label_points(
    points: NDArray[np.float64], vertices: NDArray[np.float64], faces: list[tuple[int, ...]],
    normals: NDArray[np.float64] | None = None,
) -> NDArray[np.int64]:
    """Label of each point: the coarse face its normal line meets first.

    Projecting along the surface normal maps the coarse mesh onto the surface one to one
    where it is smooth: a point's patch is the face below or above it, and the borders
    between labels are the projections of the coarse edges, which meet at each coarse
    vertex at the coarse faces' own angles. (A nearest-sample rule instead lets the
    borders wander by the face's chord height near the corners, measured as 44-59 deg
    hooks there, and the Coons bases of those patches fold.)

    1. Each point's normal (``normals``, or :func:`point_normals`).
    2. Each face split into a fan of triangles; per point, the ``CANDIDATES`` triangles
       with the nearest centroids are intersected with the point's normal line
       (:func:`_ray_hits`); the hit nearest to the point gives its face.
    3. Points whose line meets none of them (a coarse mesh far off the surface) take the
       face of their nearest face sample (:func:`_nearest_sample_labels`).
    """
    tris, owner = _fan(faces)
    normal = point_normals(points) if normals is None else normals
    centroid = vertices[tris].mean(axis=1)
    k = min(CANDIDATES, len(tris))
    _, cand = cKDTree(centroid).query(points, k=k, workers=-1)
    cand = np.asarray(cand).reshape(len(points), k)
    t, hit = _ray_hits(points, normal, vertices[tris[cand]])
    t = np.where(hit, np.abs(t), np.inf)
    best = np.argmin(t, axis=1)
    labels = owner[cand[np.arange(len(points)), best]]
    miss = ~np.isfinite(t[np.arange(len(points)), best])
    if miss.any():
        labels[miss] = _nearest_sample_labels(points, vertices, tris, owner)[miss]
    return labels


def point_normals(points: NDArray[np.float64], k: int = NORMAL_NEIGHBOURS) -> NDArray[np.float64]:
    """Unit normals (unoriented) of a cloud: the least principal axis of each point's
    ``k`` nearest neighbours."""
    k = min(k, len(points))
    _, idx = cKDTree(points).query(points, k=k, workers=-1)
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vec = np.linalg.eigh(cov)
    return vec[:, :, 0]


def _ray_hits(
    origin: NDArray[np.float64], direction: NDArray[np.float64], tri: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Where the lines ``origin + t direction`` meet triangles (Moeller-Trumbore).

    Parameters
    ----------
    origin, direction : (N, 3) float
    tri : (N, K, 3, 3) float
        K candidate triangles per line.

    Returns
    -------
    t : (N, K) float
        Line parameter of each hit.
    hit : (N, K) bool
        Whether the line meets the triangle (edges included, to 1e-9 relative).
    """
    e1 = tri[:, :, 1] - tri[:, :, 0]
    e2 = tri[:, :, 2] - tri[:, :, 0]
    d = direction[:, None, :]
    h = np.cross(d, e2)
    det = np.einsum("nkd,nkd->nk", e1, h)
    ok = np.abs(det) > 1e-12 * np.einsum("nkd,nkd->nk", e1, e1)
    inv = 1.0 / np.where(ok, det, 1.0)
    s = origin[:, None, :] - tri[:, :, 0]
    u = inv * np.einsum("nkd,nkd->nk", s, h)
    q = np.cross(s, e1)
    v = inv * np.einsum("nkd,nkd->nk", np.broadcast_to(d, q.shape), q)
    t = inv * np.einsum("nkd,nkd->nk", e2, q)
    tol = 1e-9
    return t, ok & (u >= -tol) & (v >= -tol) & (u + v <= 1.0 + tol)


def _nearest_sample_labels(
    points: NDArray[np.float64], vertices: NDArray[np.float64], tris: NDArray[np.int64],
    owner: NDArray[np.int64],
) -> NDArray[np.int64]:
    """Label of each point by its nearest face sample (the fallback of :func:`label_points`).

    1. Each fan triangle sampled about one point spacing fine (:func:`_sample_triangles`;
       a median side takes ``SAMPLES_PER_SIDE`` to 4x that steps).
    2. Each sample moves to its nearest point, so the samples lie on the surface even where
       the coarse face cuts a chord through it.
    3. One KD-tree query per point gives its nearest sample, whose face is the label.
    """
    tree = cKDTree(points)
    side = float(np.median(np.linalg.norm(vertices[tris[:, 1]] - vertices[tris[:, 0]], axis=1)))
    step = float(np.clip(_spacing(points), side / (4 * SAMPLES_PER_SIDE), side / SAMPLES_PER_SIDE))
    samples, which = _sample_triangles(vertices, tris, step)
    sample_face = owner[which]
    _, snap = tree.query(samples, workers=-1)
    _, idx = cKDTree(points[snap]).query(points, workers=-1)
    return sample_face[idx]


def _graph(points: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Rows and columns of a k-NN graph of the points (edges no longer than 3 x median)."""
    k = min(GRAPH_NEIGHBOURS, len(points) - 1)
    dist, idx = cKDTree(points).query(points, k=k + 1, workers=-1)
    limit = 3.0 * np.median(dist[:, -1])
    rows = np.repeat(np.arange(len(points)), k)
    cols = idx[:, 1:].ravel()
    ok = dist[:, 1:].ravel() <= limit
    return rows[ok], cols[ok]


def clean_labels(
    points: NDArray[np.float64], labels: NDArray[np.int64], min_points: int = MIN_PATCH_POINTS,
    regions: NDArray[np.int64] | None = None,
) -> NDArray[np.int64]:
    """Labels where every segment is one connected piece of at least ``min_points`` points.

    With ``regions`` (one id per point, e.g. :func:`point_regions`), graph edges between
    different regions are dropped first: no segment then spans two regions, and pieces
    only join neighbours in their own region.

    1. Connected pieces of each label in the k-NN graph (edges within one label).
    2. Each label keeps its largest piece if that holds ``min_points``; the other pieces
       take the label they share the most graph edges with (repeated until none is left).
    3. Labels are renumbered 0 .. P-1 in order of their smallest old label.
    """
    lab = labels.copy()
    if regions is not None:
        # Stray points of a region (a point's nearest triangle across a crease) join it.
        regions = clean_labels(points, regions, min_points)
    rows, cols = _graph(points)
    if regions is not None:
        keep = regions[rows] == regions[cols]
        rows, cols = rows[keep], cols[keep]
        # Split every label by region first (a new label per (label, region) pair).
        _, lab = np.unique(np.column_stack([lab, regions]), axis=0, return_inverse=True)
        lab = lab.ravel().astype(np.int64)
    for _ in range(20):
        same = lab[rows] == lab[cols]
        n = len(points)
        g = coo_matrix((np.ones(int(same.sum())), (rows[same], cols[same])), shape=(n, n))
        _, piece = connected_components(g, directed=False)
        size = np.bincount(piece)
        # The keeper of each label: its largest piece.
        order = np.lexsort((-size[piece], lab))
        first = np.ones(n, dtype=bool)
        first[1:] = lab[order][1:] != lab[order][:-1]
        keeper = np.zeros(piece.max() + 1, dtype=bool)
        keeper[piece[order[first]]] = True
        keeper &= size >= min_points
        orphan = ~keeper[piece]
        if not orphan.any():
            break
        if orphan.all():
            raise InputError(
                f"the automatic layout left no patch of {min_points} points; use fewer patches "
                "(--patches N) or more points"
            )
        # Orphan pieces vote over their edges to kept neighbours.
        cross = orphan[rows] & ~orphan[cols]
        shape = (int(piece.max()) + 1, int(lab.max()) + 1)
        votes = coo_matrix(
            (np.ones(int(cross.sum())), (piece[rows[cross]], lab[cols[cross]])), shape=shape
        ).tocsr()
        best = np.asarray(votes.argmax(axis=1)).ravel()
        has = np.asarray(votes.max(axis=1).todense()).ravel() > 0
        move = orphan & has[piece]
        if not move.any():
            break
        lab[move] = best[piece[move]]
    _, lab = np.unique(lab, return_inverse=True)
    return lab.astype(np.int64)


#: Share of a coarse edge, from each end, left out of :func:`claim_sides` (near a corner
#: the other faces at that corner rightly come close), and the half-width of the strip along
#: the edge, as a share of its length.
SIDE_END = 0.15
SIDE_WIDTH = 0.2


def claim_sides(
    points: NDArray[np.float64], face_of_point: NDArray[np.int64], vertices: NDArray[np.float64],
    faces: list[tuple[int, ...]], normals: NDArray[np.float64],
) -> NDArray[np.int64]:
    """Face labels where the two faces of each coarse edge meet along it.

    Projecting the coarse mesh can let a third face's label into the strip along an edge
    (where the coarse mesh lies off a curved part): the two faces of that edge then do not
    touch in the cloud and the layout loses a side (seen on the Stanford bunny on most
    layouts). Along each interior coarse edge (u, v) with faces a and b:

    1. The strip: points within ``SIDE_WIDTH`` x |uv| of the chord, away from its ends
       (``SIDE_END``), whose normal is within 45 deg of the faces' mean normal.
    2. Its points of other labels take a or b, by the side of the plane through the
       chord along the normal they lie on (the side of a's centroid is a's).
    """
    lab = np.asarray(face_of_point, dtype=np.int64).copy()
    edge_faces: dict[tuple[int, int], list[int]] = {}
    for f, cyc in enumerate(faces):
        for a, b in zip(cyc, cyc[1:] + cyc[:1]):
            edge_faces.setdefault((min(a, b), max(a, b)), []).append(f)
    tree = cKDTree(points)
    centroid = np.array([vertices[list(c)].mean(axis=0) for c in faces])
    for (u, v), owners in edge_faces.items():
        if len(owners) != 2:
            continue
        fa, fb = owners
        pu, chord = vertices[u], vertices[v] - vertices[u]
        length = float(np.linalg.norm(chord))
        near = np.asarray(tree.query_ball_point(pu + chord / 2, length / 2), dtype=np.int64)
        near = near[(lab[near] != fa) & (lab[near] != fb)]
        if not len(near) or length == 0:
            continue
        rel = points[near] - pu
        t = rel @ chord / length**2
        off = rel - np.outer(t, chord)
        na, nb = _face_normal(vertices, faces[fa]), _face_normal(vertices, faces[fb])
        normal = na + (nb if na @ nb >= 0 else -nb)  # the remesher's windings can differ
        normal -= chord * (normal @ chord) / length**2
        normal /= max(float(np.linalg.norm(normal)), 1e-300)
        ok = ((t > SIDE_END) & (t < 1 - SIDE_END)
              & (np.linalg.norm(off, axis=1) <= SIDE_WIDTH * length)
              & (np.abs(normals[near] @ normal) >= np.cos(np.radians(45.0))))
        side = np.cross(chord, normal)
        a_side = (centroid[fa] - pu) @ side
        lab[near[ok]] = np.where((off[ok] @ side) * a_side >= 0, fa, fb)
    return lab


def _face_normal(vertices: NDArray[np.float64], cycle: tuple[int, ...]) -> NDArray[np.float64]:
    """Unit normal of a coarse face (its diagonals' cross product), oriented by its winding."""
    c = vertices[list(cycle)]
    n = np.cross(c[2] - c[0], c[-1] - c[1]) if len(c) == 4 else np.cross(c[1] - c[0], c[2] - c[0])
    return n / max(float(np.linalg.norm(n)), 1e-300)


def known_corners(
    face_of_point: NDArray[np.int64], labels: NDArray[np.int64], vertices: NDArray[np.float64],
    faces: list[tuple[int, ...]],
) -> KnownCorners | None:
    """The coarse mesh's vertices as the corners of the segments ``labels``.

    1. Each label's face: the face most of its points were projected on
       (``face_of_point``, from :func:`label_points`).
    2. Only when labels and faces match one to one (no face merged away, none split by a
       crease) are the faces' vertex cycles the segments' corners; else None.
    3. A vertex on an edge of one face lies on the open boundary.
    """
    pairs, count = np.unique(np.column_stack([labels, face_of_point]), axis=0,
                             return_counts=True)
    order = np.lexsort((-count, pairs[:, 0]))
    first = np.r_[True, pairs[order][1:, 0] != pairs[order][:-1, 0]]
    label_face = pairs[order][first]
    n_labels = int(labels.max()) + 1
    if n_labels != len(faces) or len(np.unique(label_face[:, 1])) != len(faces):
        return None
    edges, uses = face_edges(faces)
    on_open = np.zeros(len(vertices), dtype=bool)
    on_open[edges[uses == 1].ravel()] = True
    segments = {int(lab): tuple(int(v) for v in faces[int(f)]) for lab, f in label_face}
    return KnownCorners(np.asarray(vertices, dtype=np.float64), segments, on_open)


def crease_edges(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64], angle: float = CREASE_ANGLE
) -> NDArray[np.int64]:
    """Crease edges of a triangle mesh that bound a smooth region.

    1. Creases: their faces' normals differ by more than ``angle`` deg beyond what the
       surface around them bends per edge (:mod:`pde2cad.layout.creases`: the faceting of a
       coarse curved mesh is no crease).
    2. Of these, the edges whose two triangles lie in different :func:`crease_regions`: a
       fragment that closes no loop (an outlier edge where a coarse mesh has a sliver, a
       crease dying out) bounds no face of the part.

    Returns
    -------
    (E, 2) int
        Vertex ids of the crease edges.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    edges, pair = _edge_faces(tri)
    region = _smooth_components(pair, crease_mask(_normals(vertices, tri), pair, angle), len(tri))
    return edges[region[pair[:, 0]] != region[pair[:, 1]]]


def crease_regions(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64], angle: float = CREASE_ANGLE,
    min_area: float = 0.0,
) -> NDArray[np.int64]:
    """Smooth region of each triangle: triangles joined across edges that are no crease.

    1. Triangles joined across edges that are no crease (:mod:`pde2cad.layout.creases`).
    2. Regions smaller than ``min_area`` are no faces of the part: the rims of a coarse
       organic mesh's thin parts (the bunny's ears, 1-2 edges across) bend like creases and
       enclose specks of a few triangles that no patch could fill. Their triangles join
       the larger region next to them (grown across triangle edges).

    Returns
    -------
    (F,) int
        Region id per triangle, 0 .. R-1 (a mesh without creases is one region per
        connected component).
    """
    tri = np.asarray(triangles, dtype=np.int64)
    _, pair = _edge_faces(tri)
    region = _smooth_components(pair, crease_mask(_normals(vertices, tri), pair, angle), len(tri))
    if min_area > 0:
        area = np.linalg.norm(np.cross(vertices[tri[:, 1]] - vertices[tri[:, 0]],
                                       vertices[tri[:, 2]] - vertices[tri[:, 0]]), axis=1) / 2
        small = (np.bincount(region, weights=area) < min_area)[region]
        if small.any() and not small.all():
            region = _grow_into(region, ~small, pair)
    _, region = np.unique(region, return_inverse=True)
    return region.astype(np.int64)


def _smooth_components(pair: NDArray[np.int64], crease: NDArray[np.bool_], n_faces: int
                       ) -> NDArray[np.int64]:
    """Connected component of each face, faces joined across the edges that are no crease."""
    smooth = pair[~crease]
    g = coo_matrix((np.ones(len(smooth)), (smooth[:, 0], smooth[:, 1])), shape=(n_faces,) * 2)
    return connected_components(g, directed=False)[1].astype(np.int64)


def region_borders(triangles: NDArray[np.int64], region: NDArray[np.int64]) -> int:
    """Edges of a triangle mesh whose two triangles lie in different regions."""
    _, pair = _edge_faces(np.asarray(triangles, dtype=np.int64))
    return int((region[pair[:, 0]] != region[pair[:, 1]]).sum())


def _grow_into(region: NDArray[np.int64], kept: NDArray[np.bool_], pair: NDArray[np.int64]
               ) -> NDArray[np.int64]:
    """Triangles not ``kept`` take the region of a kept neighbour, ring by ring."""
    region, kept = region.copy(), kept.copy()
    both = np.concatenate([pair, pair[:, ::-1]])
    while not kept.all():
        step = both[kept[both[:, 1]] & ~kept[both[:, 0]]]
        if not len(step):
            break
        region[step[:, 0]] = region[step[:, 1]]
        kept[step[:, 0]] = True
    return region


def single_patch_regions(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64], region: NDArray[np.int64],
    max_turn: float = SINGLE_PATCH_TURN,
) -> NDArray[np.bool_]:
    """Which smooth regions can be one patch each: a disk that turns little.

    A crease-bounded face of a CAD part (a box side, a prism's cap) is best one patch whose
    sides are its creases; the coarse quad mesh, which knows nothing of the creases, would
    cut it into slivers along them. A region qualifies when

    1. it is a topological disk: Euler characteristic V - E + F = 1 over its triangles;
    2. every triangle normal is within ``max_turn`` deg of the region's area-weighted mean
       normal (the patch stays a height field over its plane).

    Regions with more than 4 corners are split into 3/4-sided pieces by the pipeline.

    Returns
    -------
    (R,) bool
    """
    tri = np.asarray(triangles, dtype=np.int64)
    n_reg = int(region.max()) + 1
    cross = np.cross(vertices[tri[:, 1]] - vertices[tri[:, 0]], vertices[tri[:, 2]] - vertices[tri[:, 0]])
    mean = np.zeros((n_reg, 3))
    np.add.at(mean, region, cross)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-300)
    unit = cross / np.maximum(np.linalg.norm(cross, axis=1, keepdims=True), 1e-300)
    cos = np.einsum("ij,ij->i", unit, mean[region])
    worst = np.full(n_reg, 1.0)
    np.minimum.at(worst, region, cos)
    n_f = np.bincount(region, minlength=n_reg)
    edges = np.sort(tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    e_reg = np.unique(np.column_stack([edges, np.repeat(region, 3)]), axis=0)
    n_e = np.bincount(e_reg[:, 2], minlength=n_reg)
    v_reg = np.unique(np.column_stack([tri.ravel(), np.repeat(region, 3)]), axis=0)
    n_v = np.bincount(v_reg[:, 1], minlength=n_reg)
    return ((n_v - n_e + n_f) == 1) & (worst >= np.cos(np.radians(max_turn)))


def point_regions(
    points: NDArray[np.float64], vertices: NDArray[np.float64], triangles: NDArray[np.int64],
    region: NDArray[np.int64],
) -> NDArray[np.int64]:
    """Region of each point: the region of the mesh triangle nearest to it.

    1. Every triangle is sampled on a barycentric grid about one point spacing fine (so a
       CAD part's long thin triangles are covered too, :func:`_sample_triangles`).
    2. The triangles of each point's ``REGION_CANDIDATES`` nearest samples are candidates;
       the one whose plane is nearest to the point wins (a point on the mesh lies in its
       own triangle's plane, so near a crease the far face's plane loses).
    """
    tri = np.asarray(triangles, dtype=np.int64)
    samples, owner = _sample_triangles(vertices, tri, _spacing(points))
    k = min(REGION_CANDIDATES, len(samples))
    _, idx = cKDTree(samples).query(points, k=k, workers=-1)
    cand = owner[np.asarray(idx).reshape(len(points), k)]
    normal = _normals(vertices, tri)
    off = np.einsum("nkd,nkd->nk", points[:, None, :] - vertices[tri[cand, 0]], normal[cand])
    best = cand[np.arange(len(points)), np.abs(off).argmin(axis=1)]
    return region[best]


def _spacing(points: NDArray[np.float64]) -> float:
    """Median nearest-neighbour distance of a cloud (on a subsample of ~2000 points)."""
    sub = points[:: max(1, len(points) // 2000)]
    return float(np.median(cKDTree(points).query(sub, k=2)[0][:, 1]))


def _sample_triangles(
    vertices: NDArray[np.float64], tri: NDArray[np.int64], spacing: float
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Points on every triangle at most ~``spacing`` apart, and the triangle of each.

    1. Per triangle, ``s`` = its longest side over ``spacing`` (at least 1).
    2. Triangles grouped by ``s``; each group sampled on the barycentric grid of step 1/s.
    """
    corners = vertices[tri]
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    steps = np.clip(np.ceil(longest / max(spacing, 1e-300)), 1, 4096).astype(np.int64)
    out, owner = [], []
    for s in np.unique(steps):
        which = np.flatnonzero(steps == s)
        i, j = np.meshgrid(np.arange(s + 1), np.arange(s + 1))
        keep = i + j <= s
        bary = np.stack([i[keep], j[keep]], axis=1) / s
        weights = np.column_stack([1.0 - bary.sum(axis=1), bary])
        out.append(np.einsum("sk,fkd->fsd", weights, corners[which]).reshape(-1, 3))
        owner.append(np.repeat(which, len(weights)))
    return np.concatenate(out), np.concatenate(owner)


def _edge_faces(tri: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Interior edges of a triangle mesh (sorted vertex pairs) and their two faces."""
    edges = np.sort(tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    face = np.repeat(np.arange(len(tri)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    e, f = edges[order], face[order]
    pair = np.flatnonzero((e[1:] == e[:-1]).all(axis=1))
    return e[pair], np.column_stack([f[pair], f[pair + 1]])


def _normals(vertices: NDArray[np.float64], tri: NDArray[np.int64]) -> NDArray[np.float64]:
    normal = np.cross(vertices[tri[:, 1]] - vertices[tri[:, 0]], vertices[tri[:, 2]] - vertices[tri[:, 0]])
    return normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)


def curvature_radius(
    vertices: NDArray[np.float64], triangles: ArrayLike, crease_angle: float = CREASE_ANGLE,
    percentile: float = CURVATURE_PERCENTILE,
) -> float:
    """A small radius of curvature of the smooth part of a mesh (model units).

    1. Per interior edge that is no crease: the angle between its faces' normals over the
       distance of their centroids (the normal curvature across the edge).
    2. The ``percentile`` of these curvatures, weighted by edge count (a robust maximum);
       its inverse is the radius. ``inf`` for a flat or all-crease mesh.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    _, pair = _edge_faces(tri)
    normal = _normals(vertices, tri)
    centroid = vertices[tri].mean(axis=1)
    cos = np.clip(np.einsum("ij,ij->i", normal[pair[:, 0]], normal[pair[:, 1]]), -1.0, 1.0)
    angle = np.arccos(cos)
    smooth = angle < np.radians(crease_angle)
    dist = np.linalg.norm(centroid[pair[:, 0]] - centroid[pair[:, 1]], axis=1)
    kappa = angle[smooth] / np.maximum(dist[smooth], 1e-300)
    if len(kappa) == 0:
        return float("inf")
    k = float(np.percentile(kappa, percentile))
    return 1.0 / k if k > 0 else float("inf")


def layout_summary(
    faces: list[tuple[int, ...]], labels: NDArray[np.int64], n_creases: int | None = None
) -> dict[str, object]:
    """Patches, their side counts, corner valences and connected components of a layout.

    Parameters
    ----------
    faces : list of tuple of int
        The coarse faces.
    labels : (N,) int
        Final point labels.
    n_creases : int, optional
        Crease edges found in the input mesh.
    """
    sides = np.bincount([len(f) for f in faces], minlength=5)
    valence = np.bincount(np.concatenate([np.asarray(f) for f in faces]))
    valence = valence[valence > 0]
    counts = np.bincount(valence)
    edges = {tuple(sorted((f[j], f[(j + 1) % len(f)]))) for f in faces for j in range(len(f))}
    ed = np.asarray(sorted(edges), dtype=np.int64).reshape(-1, 2)
    n_v = int(ed.max()) + 1 if len(ed) else 0
    g = coo_matrix((np.ones(len(ed)), (ed[:, 0], ed[:, 1])), shape=(n_v, n_v))
    used = np.zeros(n_v, dtype=bool)
    used[ed.ravel()] = True
    n_comp, comp = connected_components(g, directed=False)
    return {
        "patches": int(len(np.unique(labels))),
        "faces": {"quads": int(sides[4]), "triangles": int(sides[3])},
        "corner_valence": {str(v): int(c) for v, c in enumerate(counts) if c and v != 4},
        "regular_corners": int(counts[4]) if len(counts) > 4 else 0,
        "components": int(len(np.unique(comp[used]))) if n_comp else 0,
        "creases": n_creases,
    }
