"""Creases told from faceting (issue 10): coarse smooth meshes have none, CAD edges stay."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad.layout.auto import _edge_faces, _normals, crease_edges, crease_regions
from pde2cad.layout.creases import background_bend, dihedral_angles

trimesh = pytest.importorskip("trimesh")

BUNNY = Path("/work/data/npm/bunny.off")


def _arrays(mesh) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def _bent_regions(v: np.ndarray, f: np.ndarray, angle: float = 30.0) -> tuple[int, int]:
    """The plain dihedral rule (before issue 10): edges bent over ``angle``, and the regions
    they cut the mesh into."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _, pair = _edge_faces(f)
    theta = dihedral_angles(_normals(v, f), pair)
    smooth = pair[theta <= angle]
    g = coo_matrix((np.ones(len(smooth)), (smooth[:, 0], smooth[:, 1])), shape=(len(f),) * 2)
    return int((theta > angle).sum()), int(connected_components(g, directed=False)[0])


def _ellipsoid_hull(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 1:1:3 ellipsoid as the hull of ``n`` random points: coarse, irregular faceting."""
    p = np.random.default_rng(seed).normal(size=(n, 3))
    p = p / np.linalg.norm(p, axis=1, keepdims=True) * [1.0, 1.0, 3.0]
    return _arrays(trimesh.convex.convex_hull(p))


def _blob() -> tuple[np.ndarray, np.ndarray]:
    """An icosphere(2) (162 vertices) with smooth radial bumps of 20 %."""
    v, f = _arrays(trimesh.creation.icosphere(2))
    r = 1 + 0.2 * np.sin(9 * v[:, 0]) * np.cos(6 * v[:, 1]) * np.sin(3 * v[:, 2] + 1)
    return v * r[:, None], f


@pytest.mark.parametrize("case", ["ellipsoid_60", "ellipsoid_80", "capsule", "blob"])
def test_faceting_of_a_coarse_smooth_mesh_is_no_crease(case: str) -> None:
    """Smooth shapes meshed so coarsely that 20-150 edges bend by over 30 deg and the plain
    dihedral rule cut them into 2-21 regions: no crease edge, one region."""
    if case.startswith("ellipsoid"):
        v, f = _ellipsoid_hull(int(case.split("_")[1]), seed=0)
    elif case == "capsule":
        v, f = _arrays(trimesh.creation.capsule(height=2.0, radius=0.5, count=[8, 8]))
    else:
        v, f = _blob()
    bent, _ = _bent_regions(v, f)
    assert bent >= 20
    assert len(crease_edges(v, f, 30.0)) == 0
    assert crease_regions(v, f, 30.0).max() == 0


def test_blob_was_cut_into_regions_by_the_plain_rule() -> None:
    """The bumpy blob above: the plain rule gave 21 regions (the regression of issue 10)."""
    assert _bent_regions(*_blob())[1] >= 10


def _box_variant(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A (1, 2, 3) box: its 12 triangles, subdivided 3 times, the same
    with vertex noise of 1 % of the edge length, and split to edges <= 0.1 (uneven
    triangles, 0.03-0.1) with noise of 10 % of the shortest (the plain dihedral rule finds
    407 creases and 7 regions there); and the vertices before the noise, and its level."""
    rng = np.random.default_rng(4)
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    if name == "12":
        v, f = _arrays(box)
        noise = 0.0
    elif name.startswith("subdivided"):
        v, f = _arrays(box.subdivide().subdivide().subdivide())
        noise = 1.25e-3 if name.endswith("noisy") else 0.0
    else:
        vv, ff = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, max_edge=0.1)
        v, f = np.asarray(vv, dtype=float), np.asarray(ff, dtype=np.int64)
        noise = 3e-3
    return (v + rng.normal(0.0, noise, v.shape) if noise else v), f, v, noise


@pytest.mark.parametrize("name", ["12", "subdivided", "subdivided_noisy", "split_noisy"])
def test_box_keeps_its_12_edges_and_6_faces(name: str) -> None:
    """The box turned at random: every mesh edge on a box edge is a crease, no other; their
    dihedral is 90 deg (median within 1 deg with noise); the regions are the 6 faces, one
    to one."""
    local, f, clean, noise = _box_variant(name)
    rotation = trimesh.transformations.random_rotation_matrix(
        np.random.default_rng(4).random(3))[:3, :3]
    v = local @ rotation.T  # turned at random, checked in the box's frame
    half = np.array([0.5, 1.0, 1.5])
    edges = crease_edges(v, f, 30.0)
    mid = local[edges].mean(axis=1)
    on_faces = np.isclose(np.abs(mid), half, atol=6 * noise + 1e-9).sum(axis=1)
    assert len(edges) and (on_faces == 2).all()
    length = np.linalg.norm(np.diff(local[edges], axis=1), axis=2).sum()
    assert length == pytest.approx(24.0, rel=1e-9 if not noise else 2e-2)
    all_edges, pair = _edge_faces(f)
    theta = dihedral_angles(_normals(v, f), pair)
    kept = theta[np.isin(all_edges @ [len(v), 1], edges @ [len(v), 1])]
    if noise:
        assert abs(np.median(kept) - 90.0) < 1.0 and np.abs(kept - 90.0).max() < 35.0
    else:
        assert np.abs(kept - 90.0).max() < 1e-6
    region = crease_regions(v, f, 30.0)
    truth = _box_face(clean[f].mean(axis=1), half)
    pairs = np.unique(np.column_stack([region, truth]), axis=0)
    assert region.max() + 1 == 6 and len(pairs) == 6 and len(np.unique(pairs[:, 1])) == 6


def _box_face(points: np.ndarray, half: np.ndarray) -> np.ndarray:
    rel = np.abs(points) / half
    axis = rel.argmax(axis=1)
    return axis * 2 + (points[np.arange(len(points)), axis] > 0).astype(int)


def _lens(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Two unit-sphere caps meeting at a 24-gon rim in z = 0 (dihedral ~100 deg): the hull
    of ``n`` random points per cap and the rim's; the caps' faceting bends 10-30 deg."""
    rng = np.random.default_rng(seed)
    d, pts = 0.7, []
    for s in (1.0, -1.0):
        p = rng.normal(size=(4 * n, 3))
        p = p / np.linalg.norm(p, axis=1, keepdims=True)
        p = p[s * p[:, 2] > d + 0.05][:n]
        p[:, 2] -= s * d
        pts.append(p)
    t = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    r = np.sqrt(1 - d * d)
    pts.append(np.column_stack([r * np.cos(t), r * np.sin(t), 0 * t]))
    return _arrays(trimesh.convex.convex_hull(np.concatenate(pts)))


@pytest.mark.parametrize("n", [30, 120])
def test_crease_between_faceted_curved_faces_is_kept(n: int) -> None:
    """A lens: its rim (24 edges in z = 0) is the only crease and splits it in 2 caps."""
    v, f = _lens(n, seed=1)
    edges = crease_edges(v, f, 30.0)
    assert len(edges) == 24 and np.abs(v[edges][:, :, 2]).max() < 1e-12
    region = crease_regions(v, f, 30.0)
    side = v[f].mean(axis=1)[:, 2] > 0
    assert region.max() == 1 and (region == region[np.argmax(side)]).tolist() == side.tolist()


@pytest.mark.parametrize(("angle", "regions"), [(30.0, 12), (40.0, 3)])
def test_crease_angle_stays_the_users_threshold(angle: float, regions: int) -> None:
    """A 10-sided cylinder (walls 36 deg apart, flat between): a decagonal prism at a 30 deg
    crease angle (10 walls and 2 caps), a cylinder at 40 (side and caps)."""
    v, f = _arrays(trimesh.creation.cylinder(radius=1.0, height=2.0, sections=10))
    assert crease_regions(v, f, angle).max() + 1 == regions


def test_background_bend_leaves_the_creases_out() -> None:
    """A 12-triangle box: every edge is a crease or a face diagonal; the creases' background
    is the diagonals' 0 deg (not the creases' 90)."""
    v, f = _arrays(trimesh.creation.box((1.0, 2.0, 3.0)))
    _, pair = _edge_faces(f)
    theta = dihedral_angles(_normals(v, f), pair)
    bent = theta > 30.0
    assert bent.sum() == 12 and np.allclose(background_bend(theta, pair, bent, len(f)), 0.0)


@pytest.mark.skipif(not BUNNY.is_file(), reason="the npm bunny is not at /work/data/npm")
def test_coarse_bunny_has_no_crease_bounded_faces() -> None:
    """The npm Stanford bunny (1.8k vertices): the plain rule found 357 crease edges and
    26 regions (35 crease edges left around a region of the layout's size); now only the
    rims of specks of a few triangles, which the layout's smallest region (1/80 of the
    area, a quarter of a patch of 20) absorbs."""
    from pde2cad.io.meshes import read_surface

    s = read_surface(BUNNY, sample_points=2000)
    v, f = s.vertices, s.triangles
    assert v is not None and f is not None
    assert _bent_regions(v, f)[0] > 300
    assert len(crease_edges(v, f, 30.0)) < 0.01 * len(_edge_faces(f)[0])
    area = float(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                axis=1).sum() / 2)
    assert crease_regions(v, f, 30.0, min_area=area / 80).max() == 0


def _cube_cloud(n: int, seed: int = 0) -> np.ndarray:
    """Uniform samples on the surface of the unit cube."""
    rng = np.random.default_rng(seed)
    face = rng.integers(0, 6, n)
    uv = rng.random((n, 2))
    pts = np.empty((n, 3))
    axis, side = face // 2, (face % 2).astype(float)
    for a in range(3):
        rows = axis == a
        others = [b for b in range(3) if b != a]
        pts[rows, a] = side[rows]
        pts[np.ix_(rows, others)] = uv[rows]
    return pts


def test_crease_variation_matches_sampled_creases() -> None:
    """The two-plane model of a crease's surface variation against sampled creases (30, 60
    and 90 deg between the normals; points on both half-planes, the query on the line)."""
    from scipy.spatial import cKDTree

    from pde2cad.layout.creases import CLOUD_NEIGHBOURS, crease_variation

    rng = np.random.default_rng(1)
    for angle in (30.0, 60.0, 90.0):
        half = np.radians(angle) / 2
        s, x = rng.uniform(-1, 1, 40000), rng.uniform(-1, 1, 40000)
        pts = np.column_stack([x, s * np.cos(half), np.abs(s) * np.sin(half)])
        _, idx = cKDTree(pts).query(np.zeros((1, 3)), k=CLOUD_NEIGHBOURS[0])
        hood = pts[idx[0]] - pts[idx[0]].mean(axis=0)
        w = np.linalg.eigvalsh(hood.T @ hood)
        assert w[0] / w.sum() == pytest.approx(crease_variation(angle), rel=0.35)


def _face_purity(pts: NDArray[np.float64], regions: NDArray[np.int64], margin: float) -> None:
    """Every region of a unit cube's cloud is one face: pure beyond ``margin`` of the edges."""
    face = np.argmin(np.minimum(pts, 1 - pts), axis=1) * 2 + (pts.max(axis=1) > 1 - 1e-9)
    inner = np.min(np.sort(np.minimum(pts, 1 - pts), axis=1)[:, 1:], axis=1) > margin
    assert regions.max() == 5
    for r in range(6):
        own = face[(regions == r) & inner]
        assert len(own) and np.all(own == np.bincount(own).argmax())


def test_cloud_regions_of_a_cube_are_its_six_faces() -> None:
    """A cube's clean samples fall into its 6 faces, each point on its own face but for a
    band one spacing wide at the edges; a sphere has no creases. Noise of half the point
    spacing hides 30-deg creases: the right-angled edges are still told, at a larger crease
    angle and over more neighbours (noise subtracted from the variation); noise of a whole
    spacing hides them (None, not a guess)."""
    from pde2cad.layout.creases import cloud_regions

    pts = _cube_cloud(30000)
    spacing = np.sqrt(6.0 / 30000)
    found = cloud_regions(pts, 30.0, 240)
    assert found is not None and found.angle == 30.0 and found.noise < 1e-3 * spacing
    _face_purity(pts, found.labels, 1.5 * spacing)
    rng = np.random.default_rng(2)
    ball = rng.normal(size=(20000, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    assert cloud_regions(ball, 30.0, 240) is None
    noisy = pts + rng.normal(0.0, 0.5 * spacing, pts.shape)
    found = cloud_regions(noisy, 30.0, 240)
    assert found is not None and 30.0 < found.angle < 90.0
    assert found.noise == pytest.approx(0.5 * spacing, rel=0.1)
    # A face's points within its neighbourhood's reach of an edge (sqrt(k / pi) spacings)
    # may go to the next face: beyond it every region is one face.
    _face_purity(pts, found.labels, np.sqrt(found.neighbours / np.pi) * spacing)
    assert cloud_regions(pts + rng.normal(0.0, spacing, pts.shape), 30.0, 240) is None


def test_surface_noise_reads_the_noise_not_the_curvature() -> None:
    """The quadric residual reads a noisy sphere's noise to 10 % and a clean, sparse torus's
    curvature as almost none (a plane residual would read its sag); the crease-edge quadrics
    take 40 neighbours on clean clouds and more, up to 160, on noisy ones."""
    from scipy.spatial import cKDTree

    from pde2cad import samples
    from pde2cad.layout.creases import surface_noise
    from pde2cad.layout.edges import MLS_NEIGHBOURS, SHEET_MOST, _sheet_neighbours

    rng = np.random.default_rng(4)
    ball = rng.normal(size=(20000, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    noisy = ball + rng.normal(0.0, 0.01, ball.shape)
    assert surface_noise(noisy, cKDTree(noisy)) == pytest.approx(0.01, rel=0.1)
    torus = samples.torus(8000, seed=1).points
    diagonal = float(np.linalg.norm(np.ptp(torus, axis=0)))
    assert surface_noise(torus, cKDTree(torus)) < 1e-4 * diagonal
    spacing = float(np.median(cKDTree(ball).query(ball, k=2)[0][:, 1]))
    assert _sheet_neighbours(ball, cKDTree(ball), spacing) == MLS_NEIGHBOURS
    assert _sheet_neighbours(noisy, cKDTree(noisy), spacing) == SHEET_MOST


def _holed_plate(n: int, seed: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Uniform samples of a 4 x 4 x 0.5 plate with three through holes of radius 0.2 (about
    8 point spacings at 50k points), and each point's face: 0 top, 1 bottom, 2-5 the
    sides, 6-8 the hole walls."""
    rng = np.random.default_rng(seed)
    centres = np.array([[-1.0, -1.0], [1.0, -0.5], [0.0, 1.2]])
    r, h = 0.2, 0.5
    flat = 16 - 3 * np.pi * r * r
    areas = np.array([flat, flat, *(4 * [4 * h]), *(3 * [2 * np.pi * r * h])])
    face = rng.choice(9, size=n, p=areas / areas.sum())
    pts = np.empty((n, 3))
    for f in range(9):
        m = np.flatnonzero(face == f)
        z = rng.uniform(-h / 2, h / 2, len(m))
        if f < 2:  # top, bottom: rejection sampling outside the holes
            xy = rng.uniform(-2, 2, (4 * len(m), 2))
            xy = xy[(np.linalg.norm(xy[:, None] - centres[None], axis=2) > r).all(axis=1)][: len(m)]
            pts[m] = np.column_stack([xy, np.full(len(m), h / 2 if f == 0 else -h / 2)])
        elif f < 6:
            t, side = rng.uniform(-2, 2, len(m)), np.full(len(m), 2.0 if f % 2 else -2.0)
            pts[m] = np.column_stack([t, side, z] if f < 4 else [side, t, z])
        else:
            a = rng.uniform(0, 2 * np.pi, len(m))
            pts[m] = np.column_stack([centres[f - 6] + r * np.column_stack([np.cos(a), np.sin(a)]), z])
    return pts, face


def test_cloud_regions_keep_the_walls_of_small_holes() -> None:
    """A bolt hole 8 point spacings round sags across a crease's neighbourhood like a
    crease, and its wall read as one band with the edges round it (before: the plate's 6
    faces without its 3 hole walls; a clean flange lost its 3 bolt-hole walls the same
    way). The quadric through the neighbours takes the sag but not a kink: each hole wall
    is a region of its own, and each region one face."""
    from pde2cad.layout.creases import cloud_regions

    pts, face = _holed_plate(50_000, 3)
    found = cloud_regions(pts, 30.0, 240)
    assert found is not None and found.labels.max() + 1 == 9
    own = [np.bincount(face[found.labels == region], minlength=9) for region in range(9)]
    assert all(counts.max() > 0.97 * counts.sum() for counts in own)
    assert sorted(int(counts.argmax()) for counts in own) == list(range(9))
