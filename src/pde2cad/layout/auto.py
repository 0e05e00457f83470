"""Automatic patch layout: a coarse quad mesh of the surface -> one segment label per point.

The reconstruction pipeline (:func:`pde2cad.reconstruct.reconstruct`) needs every point to
carry the label of a 3- or 4-sided region. A coarse quad(-dominant) mesh of the same surface
(from a field-aligned remesher, see :mod:`pde2cad.io.meshes`) is such a layout: each of its
faces is a patch, its vertices of valence != 4 are the corners where 3 or 5 patches meet.
This module turns it into labels, with numpy/scipy only:

1. :func:`quads_of` pairs the remesher's triangles back into quads (it returns each quad as
   two consecutive triangles) and checks that the faces form a manifold;
   :func:`dissolve_doublets` merges the two faces around each valence-2 vertex.
2. :func:`label_points`: every point takes the face nearest to it (faces densely sampled,
   one KD-tree query per point).
3. :func:`clean_labels`: a face that the nearest-face rule splits into several pieces
   (where the coarse mesh cuts a thin part or lies off a strongly curved one) keeps its
   largest piece; the smaller pieces join the neighbour label they touch most, so every
   segment is one connected region as the pipeline requires.
4. :func:`layout_summary`: patches, sides per patch, corner valences, components and the
   creases of the input (:func:`crease_edges`), for the report.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from pde2cad.errors import InputError

#: Samples per face side when faces are sampled for the nearest-face rule: a face's samples
#: lie 1/SAMPLES_PER_SIDE of its side apart, well below a patch's width.
SAMPLES_PER_SIDE = 8
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
    """

    labels: NDArray[np.int64]
    vertices: NDArray[np.float64]
    faces: list[tuple[int, ...]]
    summary: dict[str, object] = field(default_factory=dict)


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


def label_points(
    points: NDArray[np.float64], vertices: NDArray[np.float64], faces: list[tuple[int, ...]]
) -> NDArray[np.int64]:
    """Label of each point: the index of the coarse face whose surface piece holds it.

    1. Each face is split into a fan of triangles, each sampled on a barycentric grid with
       about one step per point spacing (at least ``SAMPLES_PER_SIDE``, at most 4x that).
    2. Each sample moves to its nearest point: the samples then lie on the surface, so a
       point's nearest sample is the face over it even where the coarse face cuts a chord
       through a curved surface (nearest *flat* faces tie around every coarse vertex and
       edge of a convex shape, which scatters the labels there).
    3. One KD-tree query per point gives its nearest sample, whose face is the label.
    """
    tree = cKDTree(points)
    tris, owner = _fan(faces)
    side = np.linalg.norm(vertices[tris[:, 1]] - vertices[tris[:, 0]], axis=1)
    spacing = float(np.median(tree.query(points[:: max(1, len(points) // 2000)], k=2)[0][:, 1]))
    s = int(np.clip(np.ceil(np.median(side) / max(spacing, 1e-300)), SAMPLES_PER_SIDE,
                    4 * SAMPLES_PER_SIDE))
    i, j = np.meshgrid(np.arange(s + 1), np.arange(s + 1))
    keep = i + j <= s
    bary = np.stack([i[keep], j[keep]], axis=1) / s
    weights = np.column_stack([1.0 - bary.sum(axis=1), bary])
    samples = np.einsum("sk,fkd->fsd", weights, vertices[tris]).reshape(-1, 3)
    sample_face = np.repeat(owner, len(weights))
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
    points: NDArray[np.float64], labels: NDArray[np.int64], min_points: int = MIN_PATCH_POINTS
) -> NDArray[np.int64]:
    """Labels where every segment is one connected piece of at least ``min_points`` points.

    1. Connected pieces of each label in the k-NN graph (edges within one label).
    2. Each label keeps its largest piece if that holds ``min_points``; the other pieces
       take the label they share the most graph edges with (repeated until none is left).
    3. Labels are renumbered 0 .. P-1 in order of their smallest old label.
    """
    lab = labels.copy()
    rows, cols = _graph(points)
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


def crease_edges(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64], angle: float = CREASE_ANGLE
) -> NDArray[np.int64]:
    """Edges of a triangle mesh whose two faces' normals differ by more than ``angle`` deg.

    Returns
    -------
    (E, 2) int
        Vertex ids of the crease edges.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    edges, pair = _edge_faces(tri)
    normal = _normals(vertices, tri)
    cos = np.einsum("ij,ij->i", normal[pair[:, 0]], normal[pair[:, 1]])
    return edges[cos < np.cos(np.radians(angle))]


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
