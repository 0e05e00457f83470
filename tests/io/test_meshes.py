"""Mesh / unlabelled-cloud input and the automatic layout end to end (trimesh, Instant Meshes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pde2cad.errors import InputError

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("pyinstantmeshes")

from pde2cad.io.meshes import read_surface  # noqa: E402


def _off(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    lines = ["OFF", f"{len(vertices)} {len(faces)} 0"]
    lines += [" ".join(map(str, v)) for v in vertices]
    lines += ["3 " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_read_surface_keeps_mesh_faces_and_samples_on_them(tmp_path: Path) -> None:
    sphere = trimesh.creation.icosphere(3, radius=2.0)
    path = tmp_path / "s.stl"
    sphere.export(path)
    s = read_surface(path, sample_points=5000)
    assert s.source == "mesh" and len(s.triangles) == len(sphere.faces)
    # STL stores each triangle's corners: trimesh merges them back to the shared vertices.
    assert len(s.vertices) == len(sphere.vertices)
    r = np.linalg.norm(s.points, axis=1)
    assert len(s.points) == 5000 and r.max() <= 2.0 + 1e-9 and r.min() > 2.0 * 0.98
    # Each point knows the triangle it was sampled on (its crease region, with no search):
    # it lies inside that triangle (barycentric coordinates in [0, 1], off its plane ~0).
    a, b, c = (s.vertices[s.triangles[s.point_triangles, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    area2 = np.einsum("ij,ij->i", normal, normal)
    off = np.abs(np.einsum("ij,ij->i", s.points - a, normal)) / np.sqrt(area2)
    w_b = np.einsum("ij,ij->i", np.cross(s.points - a, c - a), normal) / area2
    w_c = np.einsum("ij,ij->i", np.cross(b - a, s.points - a), normal) / area2
    assert off.max() < 1e-12 and w_b.min() > -1e-9 and w_c.min() > -1e-9 and (w_b + w_c).max() < 1 + 1e-9


def test_read_surface_reads_an_unlabelled_cloud(tmp_path: Path) -> None:
    p = np.random.default_rng(0).normal(size=(2000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    path = tmp_path / "c.xyz"
    np.savetxt(path, np.column_stack([p, p]))  # x y z nx ny nz
    s = read_surface(path)
    assert s.source == "cloud" and s.triangles is None
    assert np.allclose(s.points, p)


@pytest.mark.parametrize("case", ["no_faces", "nan", "nonmanifold", "ten_points", "line"])
def test_bad_input_is_a_clear_error(tmp_path: Path, case: str) -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    if case == "no_faces":
        path, match = _off(tmp_path / "a.off", v, np.zeros((0, 3), int)), "no faces|no triangles"
    elif case == "nan":
        v[1, 0] = np.nan
        path, match = _off(tmp_path / "a.off", v, np.array([[0, 1, 2], [0, 2, 3]])), "NaN"
    elif case == "nonmanifold":
        # Three triangles on the edge 0-1.
        path, match = _off(tmp_path / "a.off", v, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])), \
            "non-manifold"
    elif case == "ten_points":
        path = tmp_path / "a.xyz"
        np.savetxt(path, np.random.default_rng(1).random((10, 3)))
        match = "10 points"
    else:
        path = tmp_path / "a.xyz"
        np.savetxt(path, np.outer(np.linspace(0, 1, 2000), [1.0, 2.0, 3.0]))
        match = "line"
    with pytest.raises(InputError, match=match):
        read_surface(path)


def test_cli_sphere_mesh_to_a_closed_solid(tmp_path: Path) -> None:
    """An icosphere OFF, no labels: a valid solid, gaps far below 1e-7 D, fit within the
    issue's bounds; the labels written can be read back one per sampled point."""
    pytest.importorskip("OCP")
    from pde2cad.cli import main

    mesh = _off(tmp_path / "ball.off", trimesh.creation.icosphere(4).vertices * 10.0,
                trimesh.creation.icosphere(4).faces)
    out, report, labels = tmp_path / "ball.step", tmp_path / "r.json", tmp_path / "l.npy"
    code = main(["reconstruct", str(mesh), "-o", str(out), "--report", str(report),
                 "--labels-out", str(labels), "--patches", "24", "-q"])
    assert code == 0
    import json

    r = json.loads(report.read_text())
    s = r["summary"]
    assert s["valid"] and s["closed"] and s["solid"] and s["free_edges"] == 0
    assert s["max_gap_rel"] < 1e-7
    assert s["mean_error_rel"] < 2e-3
    assert r["layout"]["patches"] == s["n_faces"] >= 12
    lab = np.load(labels)
    assert lab.shape[1] == 4 and len(np.unique(lab[:, 3])) == s["n_faces"]
    # Sampled points lie on the sphere of radius 10 (chordal mesh: within 1 %).
    assert np.abs(np.linalg.norm(lab[:, :3], axis=1) - 10.0).max() < 0.1


def _sharp_case(name: str):  # type: ignore[no-untyped-def]
    """trimesh's own primitives with sharp edges: a (1, 2, 3) box turned at random, and a
    hexagonal prism (its caps have 6 corners, so the pipeline splits them)."""
    if name == "box":
        m = trimesh.creation.box((1.0, 2.0, 3.0))
        m.apply_transform(trimesh.transformations.random_rotation_matrix(
            np.random.default_rng(3).random(3)))
        return m, {90.0}
    # 0: the seams where the pipeline cut a cap, inside a flat face.
    return trimesh.creation.cylinder(radius=0.8, height=1.1, sections=6), {90.0, 60.0, 0.0}


@pytest.mark.parametrize("name", ["box", "prism"])
def test_creases_become_sharp_borders(tmp_path: Path, name: str) -> None:
    """No labels, a mesh with sharp edges: every flat face between creases is a patch (or
    the pipeline's pieces of one), the solid closes with gaps <= 1e-7 D, and every crease
    keeps its dihedral (median along each edge within 1.5 deg, nowhere off by 8)."""
    pytest.importorskip("OCP")
    from pde2cad.io.meshes import reconstruct_auto
    from pde2cad.occ.continuity import measure

    mesh, dihedrals = _sharp_case(name)
    path = _off(tmp_path / "part.off", np.asarray(mesh.vertices), np.asarray(mesh.faces))
    surface = read_surface(path, sample_points=50_000)
    rec, layout = reconstruct_auto(surface, continuity="c1")
    diagonal = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    m = measure(rec.shape, 20, profile=True)
    assert m["valid"] and m["closed"] and m["free_edges"] == 0
    assert m["max_gap"] <= 1e-7 * diagonal
    assert layout.summary["patches"] == (6 if name == "box" else 8)
    sharp = 0
    for edge in m["edges"]:
        angles = np.asarray(edge["profile"]["angles_deg"])
        truth = min(dihedrals, key=lambda d: abs(d - np.median(angles)))
        assert abs(np.median(angles) - truth) < 1.5
        assert np.abs(angles - truth).max() < 8.0
        sharp += truth > 0
    assert sharp >= (12 if name == "box" else 18)  # every edge of the solid, maybe in pieces
    # Fit: points to faces, and faces back to the true surface.
    dist = np.concatenate([np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points,
                                          axis=1) for p in rec.patches.values()])
    # Not asserted: the share of points off by 1 % D (0.2-1.5 %, by layout). A lobe narrower
    # than a patch side is covered by one face that folds at its tip (the remesher sizes
    # its faces evenly); that needs curvature-adaptive sizing, still to come.
    assert dist.mean() <= 2e-3 * diagonal
    g = np.linspace(0.0, 1.0, 30)
    uu, vv = (a.ravel() for a in np.meshgrid(g, g))
    faces = np.concatenate([p.evaluate(uu, vv) for p in rec.patches.values()])
    from scipy.spatial import cKDTree

    # The true surface as 300k samples (~1e-3 D apart: an upper bound of the distance).
    reference = trimesh.sample.sample_surface(mesh, 300_000, seed=7)[0]
    back = cKDTree(reference).query(faces)[0]
    assert np.percentile(back, 95) <= 5e-3 * diagonal


def test_refined_mesh_splits_long_cad_triangles() -> None:
    """trimesh's 12-triangle box, refined for ~12 patches: same surface (area, bounds), no
    edge longer than a patch side / REMESH_EDGES_PER_SIDE, so the remesher finds a layout."""
    from pde2cad.io.meshes import REMESH_EDGES_PER_SIDE, _refined

    box = trimesh.creation.box((1.0, 2.0, 3.0))
    v, f = _refined(np.asarray(box.vertices), np.asarray(box.faces, dtype=np.int64), 12)
    fine = trimesh.Trimesh(v, f, process=False)
    assert fine.area == pytest.approx(box.area, rel=1e-12)
    assert np.allclose(fine.bounds, box.bounds)
    edges = np.linalg.norm(v[fine.edges[:, 0]] - v[fine.edges[:, 1]], axis=1)
    assert edges.max() <= np.sqrt(box.area / 12) / REMESH_EDGES_PER_SIDE + 1e-12


@pytest.mark.parametrize("case", ["no_faces", "nan", "nonmanifold", "ten_points", "line"])
def test_bad_input_via_the_cli_exits_2_and_writes_nothing(
    tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The bad inputs above through ``pde2cad reconstruct`` with every output asked for:
    exit 2, the problem named, no file of any output left behind."""
    pytest.importorskip("OCP")
    from pde2cad.cli import main

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    if case == "no_faces":
        path, match = _off(tmp_path / "a.off", v, np.zeros((0, 3), int)), "no faces"
    elif case == "nonmanifold":
        path = _off(tmp_path / "a.off", v, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))
        match = "non-manifold"
    else:
        path = tmp_path / "a.xyz"
        pts = {"nan": np.random.default_rng(1).random((2000, 3)),
               "ten_points": np.random.default_rng(1).random((10, 3)),
               "line": np.outer(np.linspace(0, 1, 2000), [1.0, 2.0, 3.0])}[case]
        if case == "nan":
            pts[17, 1] = np.nan
        np.savetxt(path, pts)
        match = {"nan": "NaN", "ten_points": "10 points", "line": "line"}[case]
    before = set(tmp_path.iterdir())
    out = tmp_path / "out"
    code = main(["reconstruct", str(path), "-o", f"{out}.step", "--iges", f"{out}.igs",
                 "--report", f"{out}.json", "--preview", f"{out}.png",
                 "--labels-out", f"{out}_labels.npy", "--layout", "auto", "-q"])
    assert code == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert set(tmp_path.iterdir()) == before


def test_labels_out_rerun_reproduces_the_layout(tmp_path: Path) -> None:
    """A raw sphere scan (XYZ with normal columns, 0.2 % noise) without labels; the labels
    written by --labels-out, passed back with --labels, give the same patches and the same
    fit (the labelled pipeline on the same labels). (With density 4x higher on one half,
    all three layouts were rejected: see the issue 10 report.)"""
    pytest.importorskip("OCP")
    import json

    from pde2cad.cli import main

    rng = np.random.default_rng(5)
    p = rng.normal(size=(30_000, 3))
    p = 30.0 * p / np.linalg.norm(p, axis=1, keepdims=True)
    noisy = p + rng.normal(scale=0.002 * 60 * np.sqrt(3) / np.sqrt(3), size=p.shape)
    cloud = tmp_path / "scan.xyz"
    np.savetxt(cloud, np.column_stack([noisy, p / 30.0]))
    labels = tmp_path / "labels.txt"
    first, second = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["reconstruct", str(cloud), "-o", str(tmp_path / "a.step"), "--report",
                 str(first), "--labels-out", str(labels), "-q"]) == 0
    assert main(["reconstruct", str(cloud), "-o", str(tmp_path / "b.step"), "--report",
                 str(second), "--labels", str(labels), "-q"]) == 0
    a, b = (json.loads(f.read_text())["summary"] for f in (first, second))
    lab = np.loadtxt(labels)
    assert lab.shape == (len(p),) and len(np.unique(lab)) == a["n_faces"] == b["n_faces"]
    for s in (a, b):
        assert s["valid"] and s["solid"] and s["max_gap_rel"] < 1e-7
        # 0.2 % of D noise: the faces stay within the noise of the true sphere.
        assert s["mean_error_rel"] < 2e-3
    assert b["mean_error_rel"] == pytest.approx(a["mean_error_rel"], rel=0.05)


def test_a_body_with_thin_lobes_gets_a_layout_from_its_coarse_corners(tmp_path: Path) -> None:
    """Regression: a bumpy ellipsoid with two thin lobes (ears): the corners inferred from
    projected labels read bent borders as corners (5-cornered segments, split pieces too
    small) or lost a side; with the coarse mesh's own corners every layout is fitted to a
    closed solid within the issue's mean distance bound."""
    pytest.importorskip("OCP")
    from pde2cad.io.meshes import reconstruct_auto
    from pde2cad.occ.continuity import measure

    sphere = trimesh.creation.icosphere(5)
    v = np.asarray(sphere.vertices)
    r = 1 + 0.12 * np.sin(3 * v[:, 0]) * np.cos(2 * v[:, 1])
    for ear in (np.array([0.35, 0.2, 0.92]), np.array([-0.35, 0.2, 0.92])):
        r += 0.9 * np.exp(-np.sum((v - ear / np.linalg.norm(ear)) ** 2, axis=1) / 0.03)
    verts = v * r[:, None] * [1.3, 1.0, 0.9]
    path = _off(tmp_path / "lobes.off", verts, np.asarray(sphere.faces))
    surface = read_surface(path, sample_points=40_000)
    rec, layout = reconstruct_auto(surface, continuity="c0")
    assert layout.corners is not None and not rec.splits.pieces
    diagonal = float(np.linalg.norm(np.ptp(verts, axis=0)))
    m = measure(rec.shape, 10)
    assert m["valid"] and m["closed"] and m["free_edges"] == 0
    assert m["max_gap"] <= 1e-7 * diagonal
    dist = np.concatenate([np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points,
                                          axis=1) for p in rec.patches.values()])
    # Not asserted: the share of points off by 1 % D (0.2-1.5 %, by layout). A lobe narrower
    # than a patch side is covered by one face that folds at its tip (the remesher sizes
    # its faces evenly); that needs curvature-adaptive sizing, still to come.
    assert dist.mean() <= 2e-3 * diagonal


def test_the_guide_mesh_and_the_coarse_quads_repeat_exactly() -> None:
    """The same noisy cloud twice: the guide Poisson mesh and Instant Meshes' coarse quads
    come out bit for bit the same (threaded, both changed from run to run, and a layout
    written by --labels-out could not be refitted with --labels), and the next variant is
    another layout."""
    from pde2cad.io.meshes import quad_remesh, surface_mesh

    rng = np.random.default_rng(11)
    p = rng.normal(size=(20_000, 3)) * [1.0, 0.7, 0.5]
    p /= np.linalg.norm(p / [1.0, 0.7, 0.5], axis=1, keepdims=True)
    p += rng.normal(scale=0.002 * 2.0, size=p.shape)
    meshes = [surface_mesh(p) for _ in range(2)]
    assert np.array_equal(meshes[0][0], meshes[1][0])
    assert np.array_equal(meshes[0][1], meshes[1][1])
    quads = [quad_remesh(*meshes[0], 24) for _ in range(2)]
    assert np.array_equal(quads[0][0], quads[1][0]) and quads[0][1] == quads[1][1]
    other = quad_remesh(*meshes[0], 24, variant=1)
    assert len(other[0]) != len(quads[0][0]) or not np.allclose(other[0], quads[0][0])
