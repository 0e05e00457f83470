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
