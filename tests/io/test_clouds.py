"""Point cloud reading: every format reads back exactly; labels from PLY, files, columns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

o3d = pytest.importorskip("open3d")

from pde2cad.errors import InputError  # noqa: E402
from pde2cad.io.clouds import preprocess, read_cloud, read_ply_property  # noqa: E402

RNG = np.random.default_rng(7)
PTS = RNG.uniform(-5.0, 5.0, size=(200, 3))
LAB = RNG.integers(0, 6, size=200)


_FORMATS = {"<": "binary_little_endian", ">": "binary_big_endian", "": "ascii"}


def write_ply(path: Path, pts: NDArray[np.float64], lab: NDArray[np.int64], order: str) -> None:
    """A CloudCompare-like PLY: double x y z, uchar colour, float scalar_Label.

    ``order`` is "<" or ">" for binary little/big endian, "" for ascii.
    """
    binary = bool(order)
    header = (
        "ply\nformat {} 1.0\ncomment written by a test\nelement vertex {}\n"
        "property double x\nproperty double y\nproperty double z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "property float scalar_Label\nend_header\n"
    ).format(_FORMATS[order], len(pts))
    rgb = np.full((len(pts), 3), 128, dtype=np.uint8)
    if binary:
        o = order
        rec = np.zeros(len(pts), dtype=[("x", o + "f8"), ("y", o + "f8"), ("z", o + "f8"),
                                        ("r", "u1"), ("g", "u1"), ("b", "u1"),
                                        ("L", o + "f4")])  # fmt: skip
        rec["x"], rec["y"], rec["z"] = pts.T
        rec["r"], rec["g"], rec["b"] = rgb.T
        rec["L"] = lab.astype(np.float32)
        path.write_bytes(header.encode() + rec.tobytes())
    else:
        lines = [
            f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g} 128 128 128 {float(v):.6f}"
            for p, v in zip(pts, lab)
        ]
        path.write_text(header + "\n".join(lines) + "\n")


@pytest.mark.parametrize("order", ["", "<", ">"])
def test_ply_with_scalar_label(tmp_path: Path, order: str) -> None:
    path = tmp_path / "cloud.ply"
    write_ply(path, PTS, LAB, order)
    points, labels = read_cloud(path, labels="scalar_Label")
    np.testing.assert_array_equal(points, PTS)
    assert labels is not None and labels.dtype == np.int64
    np.testing.assert_array_equal(labels, LAB)
    np.testing.assert_array_equal(read_ply_property(path, "red"), 128.0)
    with pytest.raises(InputError, match="no vertex property 'label'.*scalar_Label"):
        read_cloud(path, labels="label")


def test_big_endian_ply_reads_as_little_endian(tmp_path: Path) -> None:
    write_ply(tmp_path / "le.ply", PTS, LAB, "<")
    write_ply(tmp_path / "be.ply", PTS, LAB, ">")
    assert (tmp_path / "le.ply").read_bytes() != (tmp_path / "be.ply").read_bytes()
    le, be = read_cloud(tmp_path / "le.ply"), read_cloud(tmp_path / "be.ply")
    np.testing.assert_array_equal(be[0], le[0])
    np.testing.assert_array_equal(be[0], PTS)


@pytest.mark.parametrize("count", ["abc", "-3", "1.5"])
def test_bad_element_count_names_the_line(tmp_path: Path, count: str) -> None:
    path = tmp_path / "bad.ply"
    write_ply(path, PTS, LAB, "")
    path.write_text(path.read_text().replace(f"element vertex {len(PTS)}", f"element vertex {count}"))
    with pytest.raises(InputError, match=f"header line 4 'element vertex {count}'"):
        read_cloud(path, labels="scalar_Label")


def test_pcd_and_label_file(tmp_path: Path) -> None:
    path = tmp_path / "cloud.pcd"
    o3d.io.write_point_cloud(str(path), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(PTS)))
    np.save(tmp_path / "lab.npy", LAB)
    np.savetxt(tmp_path / "lab.txt", LAB.astype(float), fmt="%.1f")
    for lab_file in (tmp_path / "lab.npy", str(tmp_path / "lab.txt")):
        points, labels = read_cloud(path, labels=lab_file)
        np.testing.assert_allclose(points, PTS, rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(labels, LAB)
    np.save(tmp_path / "short.npy", LAB[:-3])
    with pytest.raises(InputError, match="197 values but the cloud has 200 points"):
        read_cloud(path, labels=tmp_path / "short.npy")


def test_xyz_pts_txt(tmp_path: Path) -> None:
    body = "\n".join(f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g} {v}" for p, v in zip(PTS, LAB))
    (tmp_path / "a.xyz").write_text(body + "\n")
    (tmp_path / "a.pts").write_text(f"{len(PTS)}\n" + body + "\n")
    (tmp_path / "a.txt").write_text("//X Y Z Label\n" + body.replace(" ", ",") + "\n")
    for name in ("a.xyz", "a.pts", "a.txt"):
        points, labels = read_cloud(tmp_path / name)
        np.testing.assert_array_equal(points, PTS)
        assert labels is None
        _, labels = read_cloud(tmp_path / name, labels="column4")
        np.testing.assert_array_equal(labels, LAB)


def test_npy(tmp_path: Path) -> None:
    np.save(tmp_path / "p3.npy", PTS)
    np.save(tmp_path / "p4.npy", np.column_stack([PTS, LAB + 0.0, np.ones(len(PTS))]))
    points, labels = read_cloud(tmp_path / "p3.npy")
    np.testing.assert_array_equal(points, PTS)
    assert labels is None
    points, labels = read_cloud(tmp_path / "p4.npy", labels="column4")
    np.testing.assert_array_equal(points, PTS)
    np.testing.assert_array_equal(labels, LAB)
    with pytest.raises(InputError, match="only 3 columns"):
        read_cloud(tmp_path / "p3.npy", labels="column4")


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply"])
def test_mesh_is_sampled(tmp_path: Path, suffix: str) -> None:
    mesh = o3d.geometry.TriangleMesh.create_box(2.0, 3.0, 4.0)
    mesh.compute_vertex_normals()  # STL needs normals
    path = tmp_path / f"box{suffix}"
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    points, labels = read_cloud(path, sample_points=5000)
    assert points.shape == (5000, 3) and labels is None
    np.testing.assert_allclose(points.min(axis=0), 0.0, atol=0.05)
    np.testing.assert_allclose(points.max(axis=0), [2.0, 3.0, 4.0], atol=0.05)
    # Every sample lies on a face of the box (one coordinate at 0 or at the size).
    on_face = (np.abs(points) < 1e-6) | (np.abs(points - [2.0, 3.0, 4.0]) < 1e-6)
    assert on_face.any(axis=1).all()
    with pytest.raises(InputError, match="is a mesh"):
        read_cloud(path, labels="label")


def test_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        read_cloud(tmp_path / "missing.ply")
    (tmp_path / "a.las").write_text("x")
    with pytest.raises(InputError, match="unknown point cloud format '.las'.*PLY/PCD/NPY/XYZ/PTS/TXT"):
        read_cloud(tmp_path / "a.las")
    (tmp_path / "empty.xyz").write_text("")
    with pytest.raises(InputError, match="no line starting with three numbers"):
        read_cloud(tmp_path / "empty.xyz")
    (tmp_path / "nan.xyz").write_text("0 0 0\nnan 1 2\n1 inf 2\n3 3 3\n")
    with pytest.raises(InputError, match="NaN or inf coordinates in 2 of 4 rows"):
        read_cloud(tmp_path / "nan.xyz")
    (tmp_path / "bad.npy").write_bytes(b"not numpy")
    with pytest.raises(InputError, match="cannot read"):
        read_cloud(tmp_path / "bad.npy")
    (tmp_path / "garbage.ply").write_bytes(b"nothing here")
    with pytest.raises(InputError):
        read_cloud(tmp_path / "garbage.ply")
    np.save(tmp_path / "nanlab.npy", np.column_stack([PTS[:3], [1.0, np.nan, 2.0]]))
    with pytest.raises(InputError, match="1 NaN/inf values"):
        read_cloud(tmp_path / "nanlab.npy", labels="column4")
    np.save(tmp_path / "fraclab.npy", np.column_stack([PTS[:3], [1.0, 2.5, 2.0]]))
    with pytest.raises(InputError, match="must be integers; point 1 has 2.5"):
        read_cloud(tmp_path / "fraclab.npy", labels="column4")


def test_preprocess_outliers_and_voxels() -> None:
    grid = np.stack(np.meshgrid(np.arange(40), np.arange(40), indexing="ij"), -1).reshape(-1, 2)
    pts = np.column_stack([grid * 0.1, np.zeros(len(grid))])
    lab = (grid[:, 0] >= 20).astype(np.int64)
    far = np.array([[50.0, 50.0, 50.0], [-40.0, 10.0, 30.0]])
    p, l = preprocess(np.vstack([pts, far]), np.r_[lab, 0, 1], outlier_nb=10)
    assert len(p) == len(pts)
    np.testing.assert_array_equal(l, lab)
    # Voxels of 0.2 hold 2x2 grid points each; the label border at x = 2.0 is a voxel border.
    p, l = preprocess(pts, lab, outlier_nb=None, voxel=0.2 + 1e-9)
    assert len(p) == 400 and l is not None
    np.testing.assert_array_equal(l, (p[:, 0] > 1.99).astype(np.int64))
    # A mixed voxel keeps the majority label and the centroid of that label's points only.
    mixed = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]])
    p, l = preprocess(mixed, [3, 5, 5], outlier_nb=None, voxel=1.0)
    np.testing.assert_array_equal(l, [5])
    np.testing.assert_allclose(p, [[0.15, 0.0, 0.0]])
    p, l = preprocess(mixed, None, outlier_nb=None, voxel=1.0)
    assert l is None
    np.testing.assert_allclose(p, [[0.1, 0.0, 0.0]])
