"""Automatic layout core: quad pairing, nearest-face labels, cleaning, creases, curvature."""

from __future__ import annotations

import numpy as np
import pytest

from pde2cad.layout.auto import (
    GOOD_LAYOUT,
    best_layout,
    clean_labels,
    corner_angles,
    crease_edges,
    crease_regions,
    curvature_radius,
    dissolve_doublets,
    label_points,
    layout_quality,
    layout_summary,
    point_normals,
    point_regions,
    quads_of,
    relax_layout,
    single_patch_regions,
)

# A unit cube: 8 corners, 6 quads, each quad as two consecutive triangles (a, b, c), (a, c, d).
CUBE_V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
CUBE_Q = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
CUBE_T = np.array([t for a, b, c, d in CUBE_Q for t in ((a, b, c), (a, c, d))])


def _sphere(n: int, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_quads_of_pairs_triangles_into_the_cube_faces() -> None:
    faces = quads_of(CUBE_T)
    assert sorted(map(frozenset, faces)) == sorted(map(frozenset, CUBE_Q))
    # Each quad is a cycle: its 4 sides are cube edges (length 2), no diagonal (2 sqrt 2).
    for f in faces:
        sides = [np.linalg.norm(CUBE_V[f[i]] - CUBE_V[f[(i + 1) % 4]]) for i in range(4)]
        assert np.allclose(sides, 2.0)


def _cycle_edges(face: tuple[int, ...]) -> set[frozenset[int]]:
    return {frozenset((face[i], face[(i + 1) % len(face)])) for i in range(len(face))}


def test_dissolve_doublets_restores_the_cube_face() -> None:
    """Cube face (0, 1, 3, 2) split through a valence-2 vertex 8 on its diagonal 0-3."""
    split = [(0, 1, 3, 8), (3, 2, 0, 8)] + CUBE_Q[1:]
    faces = dissolve_doublets(split)
    assert len(faces) == 6
    assert sorted(tuple(sorted(f)) for f in faces) == sorted(tuple(sorted(f)) for f in CUBE_Q)
    # The merged face is a cycle along the cube's edges, not through the removed vertex.
    merged = [f for f in faces if set(f) == {0, 1, 2, 3}][0]
    assert _cycle_edges(merged) == _cycle_edges(CUBE_Q[0])


def test_dissolve_doublets_keeps_an_open_sheet() -> None:
    """Two quads sharing one edge: their outer vertices have valence 1 or 2 but lie on the
    open boundary, so nothing merges."""
    sheet = [(0, 1, 4, 3), (1, 2, 5, 4)]
    assert dissolve_doublets(sheet) == sheet
    assert dissolve_doublets(CUBE_Q) == CUBE_Q


def test_label_points_on_a_sphere_match_the_cube_faces() -> None:
    """Cube-sphere truth: a point belongs to the face of its largest |coordinate|."""
    pts = _sphere(30000)
    verts = CUBE_V / np.sqrt(3.0)  # cube corners on the sphere; faces cut chords
    faces = quads_of(CUBE_T)
    lab = label_points(pts, verts, faces)
    axis = np.abs(pts).argmax(axis=1)
    sign = np.sign(pts[np.arange(len(pts)), axis])
    centre = np.array([np.mean(verts[list(f)], axis=0) for f in faces])
    truth_face = np.array([np.flatnonzero((np.sign(centre[:, a]) == s) &
                                          (np.abs(centre[:, a]) > 0.3))[0]
                           for a, s in zip(axis, sign)])
    # The sphere's normals are radial, so projecting along them is the central projection
    # that defines the truth: wrong labels only within the normals' error (~1e-3 here) of
    # a border.
    srt = np.sort(np.abs(pts), axis=1)
    inner = srt[:, 2] - srt[:, 1] > 0.01
    assert np.mean(lab[inner] == truth_face[inner]) == 1.0
    assert np.mean(lab == truth_face) > 0.999


def test_clean_labels_gives_islands_to_their_surroundings() -> None:
    pts = _sphere(20000, seed=1)
    lab = label_points(pts, CUBE_V / np.sqrt(3.0), quads_of(CUBE_T))
    dirty = lab.copy()
    island = np.linalg.norm(pts - np.array([0.0, 0.0, 1.0]), axis=1) < 0.1  # inside the +z face
    top = np.bincount(lab[island]).argmax()
    dirty[island] = (top + 1) % 6
    clean = clean_labels(pts, dirty)
    assert len(np.unique(clean)) == 6
    # The island went back to the face around it; elsewhere only stray border points moved.
    top_clean = np.bincount(clean[~island][lab[~island] == top]).argmax()
    assert (clean[island] == top_clean).all()
    remap = np.array([np.bincount(clean[lab == k]).argmax() for k in range(6)])
    assert np.mean(remap[lab[~island]] != clean[~island]) < 2e-3


def test_crease_edges_of_a_subdivided_box_lie_on_its_12_edges() -> None:
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box((1.0, 2.0, 3.0)).subdivide().subdivide()
    edges = crease_edges(np.asarray(box.vertices), np.asarray(box.faces), 30.0)
    mid = np.asarray(box.vertices)[edges].mean(axis=1)
    half = np.array([0.5, 1.0, 1.5])
    on_faces = (np.isclose(np.abs(mid), half, atol=1e-9)).sum(axis=1)
    assert len(edges) > 0 and (on_faces == 2).all()
    # Total crease length = the box's edge length sum 4 (1 + 2 + 3).
    length = np.linalg.norm(np.diff(np.asarray(box.vertices)[edges], axis=1), axis=2).sum()
    assert length == pytest.approx(24.0, rel=1e-9)


@pytest.mark.parametrize("radius", [0.5, 2.0, 30.0])
def test_curvature_radius_of_a_sphere(radius: float) -> None:
    trimesh = pytest.importorskip("trimesh")
    s = trimesh.creation.icosphere(4, radius=radius)
    assert curvature_radius(np.asarray(s.vertices), np.asarray(s.faces)) == pytest.approx(
        radius, rel=0.15)


def test_layout_summary_of_the_cube() -> None:
    faces = quads_of(CUBE_T)
    s = layout_summary(faces, np.arange(6), n_creases=12)
    assert s["patches"] == 6 and s["faces"] == {"quads": 6, "triangles": 0}
    assert s["corner_valence"] == {"3": 8} and s["components"] == 1 and s["creases"] == 12


def _cube_sphere(n: int) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """A quad mesh of the unit sphere: each cube face an n x n grid, centrally projected."""
    g = np.linspace(-1.0, 1.0, n + 1)
    verts: list[np.ndarray] = []
    faces: list[tuple[int, ...]] = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            a, b = np.meshgrid(g, g, indexing="ij")
            p = np.zeros((n + 1, n + 1, 3))
            p[..., axis] = sign
            p[..., (axis + 1) % 3] = a
            p[..., (axis + 2) % 3] = b
            base = sum(len(v) for v in verts)
            verts.append(p.reshape(-1, 3))
            idx = base + np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
            for i in range(n):
                for j in range(n):
                    q = (idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1])
                    faces.append(q if sign > 0 else q[::-1])
    v = np.concatenate(verts)
    uniq, inv = np.unique(np.round(v, 9), axis=0, return_inverse=True)
    inv = inv.ravel()
    faces = [tuple(int(inv[k]) for k in f) for f in faces]
    return uniq / np.linalg.norm(uniq, axis=1, keepdims=True), faces


def _bent(v: np.ndarray, faces: list[tuple[int, ...]], amount: float) -> np.ndarray:
    """The cube-sphere with its (1, 1, 1) corner (3-valent) moved ``amount`` of the way to
    the far corner of one of its faces, on the sphere: that face's angle there nears 180."""
    corner = int(np.argmax(v @ np.array([1.0, 1.0, 1.0])))
    nb = [f for f in faces if corner in f]
    far = [k for k in nb[0] if k != corner and k not in nb[1] and k not in nb[2]][0]
    bent = v.copy()
    bent[corner] += amount * (v[far] - v[corner])
    bent[corner] /= np.linalg.norm(bent[corner])
    return bent


def test_corner_angles_of_the_cube_and_a_bent_corner() -> None:
    ang, val = corner_angles(CUBE_V, CUBE_Q)
    # In the tangent plane of a cube corner (normal along the diagonal) its three 90-deg
    # face angles read 120 each; every vertex 3-valent.
    assert np.allclose(ang, 120.0) and (val == 3).all()
    v, faces = _cube_sphere(3)
    assert layout_quality(v, faces) < 125.0  # cube-sphere corners: 120 at the cube's corners
    # A cube corner pushed towards one face's far corner: a T, angle ~180.
    bent = _bent(v, faces, 0.8)
    assert layout_quality(bent, faces) > 160.0
    # Winding does not matter: half the faces turned round read the same.
    mixed = [f[::-1] if k % 2 else f for k, f in enumerate(faces)]
    turned, kept = corner_angles(bent, mixed)[0], corner_angles(bent, faces)[0]
    assert np.allclose(np.sort(turned), np.sort(kept))


def test_relax_layout_straightens_a_bent_corner_on_the_sphere() -> None:
    """The bent cube-sphere corner relaxes back below GOOD_LAYOUT, on the sphere, with the
    sphere's points (not the mesh) as the surface."""
    v, faces = _cube_sphere(3)
    bent = _bent(v, faces, 0.8)
    pts = _sphere(40000, seed=3)
    relaxed = relax_layout(pts, bent, faces)
    assert layout_quality(relaxed, faces) <= GOOD_LAYOUT
    # Every vertex stays on the sphere (tangent planes of points ~0.01 apart).
    assert np.abs(np.linalg.norm(relaxed, axis=1) - 1.0).max() < 2e-3


def test_relax_layout_keeps_an_open_boundary() -> None:
    """A half cube-sphere (z > 0 faces): its rim vertices do not move."""
    v, faces = _cube_sphere(2)
    top = [f for f in faces if (v[list(f), 2] > -1e-9).all()]
    pts = _sphere(40000, seed=4)
    pts = pts[pts[:, 2] > 0]
    relaxed = relax_layout(pts, v, top)
    used = np.unique(np.concatenate([np.asarray(f) for f in top]))
    rim = used[np.abs(v[used, 2]) < 1e-9]
    assert len(rim) > 0 and np.allclose(relaxed[rim], v[rim])


def test_best_layout_prefers_the_unbent_mesh() -> None:
    """Of a bent and a clean cube-sphere, the clean one wins; the search stops there."""
    v, faces = _cube_sphere(3)
    bent = _bent(v, faces, 0.95)
    calls = []
    meshes = [(bent, faces), (v, faces), (bent, faces)]

    def remesh(i: int) -> tuple[np.ndarray, list[tuple[int, ...]]]:
        calls.append(i)
        return meshes[i]

    pts = _sphere(30000, seed=5)
    verts, _, quality = best_layout(pts, remesh, tries=3, relax=False)
    assert calls == [0, 1] and quality <= GOOD_LAYOUT
    assert np.allclose(verts, v)


def test_point_normals_of_a_noisy_sphere() -> None:
    pts = _sphere(20000, seed=6)
    noisy = pts + np.random.default_rng(7).normal(scale=2e-3, size=pts.shape)
    n = point_normals(noisy)
    cos = np.abs(np.einsum("ij,ij->i", n, pts))
    assert np.degrees(np.arccos(np.median(cos))) < 5.0


def _box_face(points: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Which of a centred box's 6 faces each point lies on (axis * 2 + side)."""
    rel = np.abs(points) / half
    axis = rel.argmax(axis=1)
    side = (points[np.arange(len(points)), axis] > 0).astype(int)
    return axis * 2 + side


def test_crease_regions_of_a_box_are_its_faces() -> None:
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box((1.0, 2.0, 3.0)).subdivide()
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    region = crease_regions(v, f, 30.0)
    truth = _box_face(v[f].mean(axis=1), np.array([0.5, 1.0, 1.5]))
    assert region.max() + 1 == 6
    # One region per box face: the map region -> face is a bijection.
    pairs = np.unique(np.column_stack([region, truth]), axis=0)
    assert len(pairs) == 6 and len(np.unique(pairs[:, 1])) == 6


def test_single_patch_regions_are_flat_disks() -> None:
    """A box: 6 flat disks. A cylinder: its caps are, its side (an annulus) is not. A
    sphere (one closed region) is not."""
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    assert single_patch_regions(v, f, crease_regions(v, f)).all()
    cyl = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=48)
    v, f = np.asarray(cyl.vertices), np.asarray(cyl.faces)
    region = crease_regions(v, f)
    ok = single_patch_regions(v, f, region)
    assert region.max() + 1 == 3
    cap = np.array([np.abs(np.einsum("ij,j->i", _tri_normals(v, f[region == r]), [0, 0, 1.0])).min()
                    > 0.99 for r in range(3)])
    assert (ok == cap).all() and cap.sum() == 2
    ball = trimesh.creation.icosphere(3)
    v, f = np.asarray(ball.vertices), np.asarray(ball.faces)
    assert not single_patch_regions(v, f, crease_regions(v, f)).any()


def _tri_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_point_regions_and_region_bounded_labels_on_a_box() -> None:
    """Points on a 12-triangle box take their face's region (its long triangles sampled
    finely); labels cleaned with those regions never span a crease."""
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    pts = np.asarray(trimesh.sample.sample_surface(box, 30000, seed=3)[0])
    region = point_regions(pts, v, f, crease_regions(v, f))
    truth = _box_face(pts, np.array([0.5, 1.0, 1.5]))
    owner = {r: np.bincount(truth[region == r]).argmax() for r in np.unique(region)}
    wrong = np.array([owner[r] for r in region]) != truth
    assert len(owner) == 6 and len(set(owner.values())) == 6
    # The points lie in their triangles: only points on a crease itself may go either way.
    dist_to_crease = np.sort(np.abs(np.abs(pts) - [0.5, 1.0, 1.5]), axis=1)[:, 1]
    assert wrong.mean() < 2e-4 and (dist_to_crease[wrong] < 1e-9).all()
    # Labels cutting across the box (halves along x) become one label per (half, face).
    lab = (pts[:, 0] > 0.1).astype(np.int64)
    clean = clean_labels(pts, lab, regions=region)
    for k in np.unique(clean):
        faces_of_k = np.bincount(truth[clean == k], minlength=6)
        assert faces_of_k.max() >= 0.99 * faces_of_k.sum()
    assert len(np.unique(clean)) == 10  # the 4 faces along x halve, the 2 ends do not
