"""``pde2cad reconstruct``: labelled cloud -> STEP/IGES/report/preview, checked on the files."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

pytest.importorskip("OCP")

from pde2cad.cli import main  # noqa: E402
from pde2cad.occ import measure, read_iges, read_step  # noqa: E402

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def sheet(n: int = 60) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """z = 0.1 sin(x) sin(y) on an n x n grid over [0, 2]^2, labelled by quadrant (2 x 2)."""
    g = np.linspace(0.0, 2.0, n)
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    pts = np.column_stack([x, y, 0.1 * np.sin(x) * np.sin(y)])
    return pts, (x > 1.0).astype(np.int64) + 2 * (y > 1.0)


def write_ply(path: Path, points: NDArray[np.float64], props: dict[str, Any] | None = None,
              binary: bool = True) -> Path:
    """A PLY point cloud with float32 x, y, z and extra float32 vertex properties."""
    props = props or {}
    names = ["x", "y", "z", *props]
    columns = [points[:, 0], points[:, 1], points[:, 2], *props.values()]
    fmt = "binary_little_endian" if binary else "ascii"
    header = f"ply\nformat {fmt} 1.0\nelement vertex {len(points)}\n"
    header += "".join(f"property float {name}\n" for name in names) + "end_header\n"
    if binary:
        rec = np.zeros(len(points), dtype=[(name, "<f4") for name in names])
        for name, col in zip(names, columns, strict=True):
            rec[name] = col
        path.write_bytes(header.encode() + rec.tobytes())
    else:
        body = np.column_stack(columns)
        path.write_text(header + "\n".join(" ".join(f"{v:.9g}" for v in row) for row in body) + "\n")
    return path


def outputs(folder: Path) -> dict[str, Path]:
    return {
        "step": folder / "out.step", "iges": folder / "out.igs",
        "report": folder / "out.json", "preview": folder / "out.png",
    }  # fmt: skip


def all_args(out: dict[str, Path]) -> list[str]:
    return ["-o", str(out["step"]), "--iges", str(out["iges"]), "--report", str(out["report"]),
            "--preview", str(out["preview"])]


def assert_nothing_written(folder: Path) -> None:
    """None of the requested outputs, and no stray temporary file, exists."""
    for path in outputs(folder).values():
        assert not path.exists(), path
    assert not [p.name for p in folder.iterdir() if p.name.startswith(".")]


# --------------------------------------------------------------------------- a full run
@pytest.fixture(scope="module")
def sheet_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """One real run on a labelled PLY with every output requested."""
    folder = tmp_path_factory.mktemp("sheet")
    pts, lab = sheet()
    cloud = write_ply(folder / "sheet.ply", pts, {"scalar_Label": lab.astype(float)})
    out = outputs(folder)
    import io
    from contextlib import redirect_stderr, redirect_stdout

    stdout, stderr = io.StringIO(), io.StringIO()
    with redirect_stdout(stdout), redirect_stderr(stderr):
        code = main(["reconstruct", str(cloud), *all_args(out)])
    diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    return {"code": code, "out": out, "stdout": stdout.getvalue(), "stderr": stderr.getvalue(),
            "diagonal": diagonal, "n_points": len(pts), "folder": folder}


def test_step_is_a_valid_sewn_sheet(sheet_run: dict[str, Any]) -> None:
    assert sheet_run["code"] == 0, sheet_run["stderr"]
    m = measure(read_step(sheet_run["out"]["step"]))
    assert m["valid"] and m["n_faces"] == 4 and m["n_shells"] == 1
    assert m["shared_edges"] == 4 and m["free_edges"] == 8  # 2 x 2 sheet: 2 open edges per side
    assert not m["closed"]
    assert m["max_gap"] <= 1e-7 * sheet_run["diagonal"]
    assert m["max_angle_deg"] < 5.0  # C0, but a smooth sheet has no folds at the seams


def test_report_matches_a_fresh_measure(sheet_run: dict[str, Any]) -> None:
    assert sheet_run["code"] == 0, sheet_run["stderr"]
    report = json.loads(sheet_run["out"]["report"].read_text())
    assert set(report) >= {"input", "settings", "summary", "edges", "patches", "timings", "outputs"}
    s = report["summary"]
    m = measure(read_step(sheet_run["out"]["step"]), samples=s["seam_samples"])
    diagonal = sheet_run["diagonal"]
    assert s["diagonal"] == pytest.approx(diagonal, rel=1e-6)
    for key in ("n_faces", "shared_edges", "free_edges", "valid", "closed"):
        assert s[key] == m[key], key
    assert s["max_gap"] == pytest.approx(m["max_gap"], abs=1e-12 * diagonal)
    assert s["max_gap_rel"] == pytest.approx(s["max_gap"] / diagonal, abs=1e-15)
    assert s["max_angle_deg"] == pytest.approx(m["max_angle_deg"], abs=1e-6)
    assert s["solid"] is False and s["faces_matched"] is True
    # Shared edges by segment label: the quadrants 0 1 / 2 3 meet along four seams.
    assert sorted(tuple(e["labels"]) for e in report["edges"]) == [(0, 1), (0, 2), (1, 3), (2, 3)]
    for e in report["edges"]:
        assert 0.0 <= e["max_gap"] <= 1e-7 * diagonal
        assert e["max_gap_rel"] == pytest.approx(e["max_gap"] / diagonal, abs=1e-15)
        assert 0.0 <= e["max_angle_deg"] <= s["max_angle_deg"]
    assert max(e["max_angle_deg"] for e in report["edges"]) == pytest.approx(s["max_angle_deg"])
    # Per patch: every point accounted for, errors small and consistent with each other.
    patches = report["patches"]
    assert [p["label"] for p in patches] == [0, 1, 2, 3]
    assert sum(p["points"] for p in patches) == sheet_run["n_points"]
    for p in patches:
        # Default --terms auto: M = N chosen per patch by hold-out validation.
        assert p["terms"][0] == p["terms"][1] and 6 <= p["terms"][0] <= 16 and p["sides"] == 4
        assert 0.0 < p["mean"] <= p["rms"] <= p["max"] <= 1e-3 * diagonal
        assert p["mean_rel"] == pytest.approx(p["mean"] / diagonal)
        assert p["max_rel"] == pytest.approx(p["max"] / diagonal)
        # The JSON report asks for the orthogonal errors (one more projection per patch).
        assert 0.0 < p["max_orthogonal"] <= p["max"] + 1e-9 * diagonal
    assert s["max_error_rel"] == pytest.approx(max(p["max_rel"] for p in patches))
    assert report["input"]["points"] == sheet_run["n_points"]
    assert report["input"]["segments"] == 4 and report["input"]["labels_from"] == "scalar_Label"
    assert report["settings"]["terms"] == "auto" and report["settings"]["units"] == "MM"
    assert report["outputs"]["step"] == str(sheet_run["out"]["step"])
    assert all(isinstance(v, float) and v >= 0 for v in report["timings"].values())
    assert report["timings"]["total"] >= report["timings"]["reconstruct"]


def test_report_splits_seams_by_corner(sheet_run: dict[str, Any]) -> None:
    """A 2 x 2 sheet: one interior four-patch corner, four two-patch and four one-patch corners
    on the open boundary; all regular, so the whole seam counts as away from irregular ones."""
    assert sheet_run["code"] == 0, sheet_run["stderr"]
    report = json.loads(sheet_run["out"]["report"].read_text())
    s = report["summary"]
    assert s["corner_valences"] == {"1": 4, "2": 4, "4": 1}
    assert s["irregular_corners"] == 0 and s["corners_matched"] is True
    assert s["corner_match_distance"] <= 1e-6 * sheet_run["diagonal"]
    assert s["max_angle_deg_regular"] == pytest.approx(s["max_angle_deg"])
    assert s["max_angle_deg_near_irregular_corners"] is None and s["c0_fallback"] == []
    centre = next(c["id"] for c in report["corners"] if c["valence"] == 4)
    for e in report["edges"]:  # every seam of the sheet runs from the centre to the rim
        assert centre in e["corners"] and None not in e["corners"]


def test_iges_reads_back_with_the_same_faces(sheet_run: dict[str, Any]) -> None:
    assert sheet_run["code"] == 0, sheet_run["stderr"]
    m = measure(read_iges(sheet_run["out"]["iges"]))
    assert m["n_faces"] == 4 and m["valid"]
    assert m["max_gap"] <= 1e-6 * sheet_run["diagonal"]


def test_preview_is_a_png(sheet_run: dict[str, Any]) -> None:
    from PIL import Image

    assert sheet_run["code"] == 0, sheet_run["stderr"]
    path = sheet_run["out"]["preview"]
    assert path.read_bytes()[:8] == PNG_MAGIC
    with Image.open(path) as img:
        img.verify()
    with Image.open(path) as img:
        width, height = img.size
        pixels = np.asarray(img.convert("RGB"))
    assert width > 400 and height > 300
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50  # patches drawn, not blank


def test_summary_outputs_and_permissions(sheet_run: dict[str, Any]) -> None:
    assert sheet_run["code"] == 0, sheet_run["stderr"]
    text = sheet_run["stdout"]
    assert "4 faces" in text and "open shell" in text and "valid" in text
    assert "max gap" in text and "max normal angle" in text
    for path in sheet_run["out"].values():
        assert str(path) in text
    umask = os.umask(0o022)
    os.umask(umask)
    for path in sheet_run["out"].values():
        assert path.stat().st_mode & 0o777 == 0o666 & ~umask, path  # not mkstemp's 0600
    assert not [p for p in sheet_run["folder"].iterdir() if p.name.startswith(".")]


def test_text_cloud_with_label_file_units_and_schema(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    pts, lab = sheet(40)
    cloud = tmp_path / "sheet.xyz"
    np.savetxt(cloud, pts)
    np.save(tmp_path / "labels.npy", lab)
    step = tmp_path / "out.stp"
    code = main(["reconstruct", str(cloud), "--labels", str(tmp_path / "labels.npy"),
                 "-o", str(step), "--units", "in", "--schema", "AP242", "--terms", "4", "-q"])
    assert code == 0, capsys.readouterr().err
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""  # --quiet
    text = step.read_text(errors="replace")
    assert "AP242" in text.upper() or "AP242_MANAGED_MODEL_BASED_3D_ENGINEERING" in text.upper()
    assert "INCH" in text.upper()
    shape = read_step(step, units="IN")  # read in the declared unit: coordinates unscaled
    m = measure(shape)
    assert m["valid"] and m["n_faces"] == 4 and m["free_edges"] == 8
    diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    assert m["max_gap"] <= 1e-7 * diagonal
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box)
    lo, hi = box.CornerMin(), box.CornerMax()
    assert hi.X() - lo.X() == pytest.approx(2.0, abs=1e-3)  # in inches, as the points were


# --------------------------------------------------------------------------- with a stand-in
@pytest.fixture(scope="module")
def sheet_rec() -> Any:
    from pde2cad.reconstruct import reconstruct

    pts, lab = sheet(40)
    return reconstruct(pts, lab)


def test_options_reach_reconstruct_and_progress_is_shown(
    sheet_rec: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    seen: dict[str, Any] = {}

    def fake(points: Any, labels: Any, **kwargs: Any) -> Any:
        seen.update(kwargs, count=len(points))
        for k in range(4):
            kwargs["progress"]("patches", k + 1, 4)
        return sheet_rec

    monkeypatch.setattr("pde2cad.reconstruct.reconstruct", fake)
    pts, lab = sheet(40)
    cloud = write_ply(tmp_path / "c.ply", pts, {"label": lab.astype(float)}, binary=False)
    code = main(["reconstruct", str(cloud), "-o", str(tmp_path / "o.step"), "--continuity",
                 "c1", "--terms", "8", "--tolerance", "0.01", "--cad-tolerance", "1e-5"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert seen["continuity"] == "c1" and seen["m"] == seen["n"] == 8
    assert seen["tolerance"] == 0.01 and seen["cad_tolerance"] == 1e-5 and seen["count"] == 1600
    assert "patches: 4/4" in captured.err  # not a terminal: one line per finished stage
    assert "labels from label" in captured.err


def test_c1_is_refused_when_reconstruct_cannot_do_it(
    sheet_rec: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    def old(points: Any, labels: Any, *, m: int = 6, n: int = 6, tolerance: Any = None,
            cad_tolerance: Any = None) -> Any:
        return sheet_rec

    monkeypatch.setattr("pde2cad.reconstruct.reconstruct", old)
    pts, lab = sheet(40)
    cloud = write_ply(tmp_path / "c.ply", pts, {"scalar_label": lab.astype(float)})
    out = outputs(tmp_path)
    assert main(["reconstruct", str(cloud), *all_args(out), "--continuity", "c1"]) == 2
    assert "--continuity c0" in capsys.readouterr().err
    assert_nothing_written(tmp_path)
    # Without c1 the old signature works (progress and continuity are not passed).
    assert main(["reconstruct", str(cloud), "-o", str(out["step"]), "-q"]) == 0
    assert measure(read_step(out["step"]))["n_faces"] == 4


def test_a_late_failure_leaves_no_output(
    sheet_rec: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """STEP and IGES are written, then the preview fails: nothing of the run may remain."""
    from pde2cad.errors import ExportError

    def broken_preview(*args: Any, **kwargs: Any) -> None:
        raise ExportError("disk full (simulated)")

    monkeypatch.setattr("pde2cad.reconstruct.reconstruct", lambda p, lab, **kw: sheet_rec)
    monkeypatch.setattr("pde2cad.plots.preview.reconstruction_preview", broken_preview)
    pts, lab = sheet(40)
    cloud = write_ply(tmp_path / "c.ply", pts, {"scalar_Label": lab.astype(float)})
    assert main(["reconstruct", str(cloud), *all_args(outputs(tmp_path))]) == 3
    assert "disk full" in capsys.readouterr().err
    assert_nothing_written(tmp_path)


def test_a_crash_inside_reconstruct_is_a_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def crash(points: Any, labels: Any, **kwargs: Any) -> Any:
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr("pde2cad.reconstruct.reconstruct", crash)
    pts, lab = sheet(20)
    cloud = write_ply(tmp_path / "c.ply", pts, {"scalar_Label": lab.astype(float)})
    assert main(["reconstruct", str(cloud), *all_args(outputs(tmp_path))]) == 1
    err = capsys.readouterr().err
    assert "LinAlgError" in err and "Singular matrix" in err and "Traceback" not in err
    assert_nothing_written(tmp_path)


def test_public_api_reconstruct_stays_callable(sheet_rec: Any) -> None:
    import pde2cad
    import pde2cad.reconstruct  # the submodule rebinds the package attribute
    from pde2cad.reconstruct import Reconstruction

    assert callable(pde2cad.reconstruct)
    assert pde2cad.reconstruct.Reconstruction is Reconstruction
    rec = pde2cad.reconstruct(*sheet(30))
    assert isinstance(rec, Reconstruction) and len(rec.labels) == 4


# --------------------------------------------------------------------------- bad input
def _write(path: Path, data: bytes | str) -> Path:
    if isinstance(data, str):
        path.write_text(data)
    else:
        path.write_bytes(data)
    return path


def _cloud(tmp_path: Path) -> Path:
    pts, lab = sheet(20)
    return write_ply(tmp_path / "c.ply", pts, {"scalar_Label": lab.astype(float)})


@pytest.mark.parametrize(
    "make, extra, code, message",
    [
        (lambda d: d / "missing.ply", [], 2, "does not exist"),
        (lambda d: _write(d / "e.ply", b""), [], 2, "is empty"),
        (lambda d: _write(d / "g.ply", b"\x00garbage" * 50), [], 2, "not a PLY file"),
        (lambda d: _write(d / "t.ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
            b"property float y\nproperty float z\nproperty float label\nend_header\n" + bytes(64)
        ), [], 2, "truncated"),  # fmt: skip
        (lambda d: _write(d / "e.xyz", "x y z\n"), ["--labels", "column4"], 2, "three numbers"),
        # No label property: the automatic layout, which needs more than 400 points.
        (lambda d: write_ply(d / "n.ply", sheet(20)[0], {"intensity": np.ones(400)}), [], 2,
         "automatic layout needs at least 500"),
        (lambda d: write_ply(d / "n.ply", sheet(20)[0], {"scalar_a": np.ones(400),
                                                          "scalar_b": np.ones(400)}), [], 2,
         "scalar_a, scalar_b"),
        (_cloud, ["--labels", "segment"], 2, "no vertex property 'segment'"),
        (lambda d: np.savetxt(d / "c.xyz", sheet(20)[0]) or d / "c.xyz", [], 2,
         "automatic layout needs at least 500"),
        (lambda d: np.save(d / "lab.npy", np.zeros(399)) or _cloud(d), ["--labels", "{d}/lab.npy"],
         2, "have 399 values but the cloud has 400 points"),
        (lambda d: write_ply(d / "f.ply", sheet(20)[0], {"scalar_Label": np.full(400, 0.5)}), [], 2,
         "must be integers"),
    ],
)
def test_bad_input_exits_2_and_writes_nothing(
    make: Any, extra: list[str], code: int, message: str, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    cloud = make(tmp_path)
    extra = [a.format(d=tmp_path) for a in extra]
    assert main(["reconstruct", str(cloud), *all_args(outputs(tmp_path)), *extra]) == code
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert_nothing_written(tmp_path)


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("-o", "out.stl", "-o {d}/out.stl must end in .step or .stp"),
        ("--iges", "out.step", "--iges {d}/out.step must end in .igs or .iges"),
        ("--report", "out.txt", "must end in .json"),
        ("--preview", "out.jpg", "must end in .png or .svg or .pdf"),
    ],
)
def test_bad_suffix_is_refused_before_any_work(
    option: str, value: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["reconstruct", str(_cloud(tmp_path))]
    if option != "-o":
        args += ["-o", str(tmp_path / "out.step")]
    assert main([*args, option, str(tmp_path / value)]) == 2
    assert message.format(d=tmp_path) in capsys.readouterr().err
    assert not (tmp_path / value).exists()
    assert_nothing_written(tmp_path)


def test_output_into_a_missing_folder_exits_3(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    cloud = _cloud(tmp_path)
    out = outputs(tmp_path)
    args = all_args(out)
    args[args.index("--iges") + 1] = str(tmp_path / "no" / "such" / "out.igs")
    assert main(["reconstruct", str(cloud), *args]) == 3
    assert "does not exist; create it first" in capsys.readouterr().err
    assert_nothing_written(tmp_path)


@pytest.mark.parametrize(
    "option, value",
    [("--tolerance", "-1"), ("--tolerance", "nan"), ("--tolerance", "0"),
     ("--cad-tolerance", "inf"), ("--voxel", "-0.1"), ("--terms", "0"), ("--terms", "2.5"), ("--terms", "many"),
     ("--units", "furlong"), ("--continuity", "c2")],
)
def test_nonsense_numbers_are_refused_by_the_parser(
    option: str, value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["reconstruct", str(_cloud(tmp_path)), *all_args(outputs(tmp_path)), option, value])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert option in err and ("must be" in err or "invalid choice" in err or "not a whole" in err)
    assert_nothing_written(tmp_path)


def test_help_lists_reconstruct(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    text = capsys.readouterr().out
    for option in ("--labels", "--continuity", "--terms", "--iges", "--report", "--preview",
                   "--units", "--schema", "--outliers", "--voxel", "--quiet"):
        assert option in text


def _face_samples(shape: Any, count: int = 12) -> NDArray[np.float64]:
    """Points on every face of ``shape`` over a ``count x count`` grid of its UV bounds."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out = []
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        face = TopoDS.Face_s(explorer.Current())
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        surface = BRepAdaptor_Surface(face, True)
        for u in np.linspace(u0, u1, count):
            for v in np.linspace(v0, v1, count):
                p = surface.Value(float(u), float(v))
                out.append((p.X(), p.Y(), p.Z()))
        explorer.Next()
    return np.asarray(out)


def test_sample_cylinder_matches_the_true_surface(tmp_path: Path) -> None:
    """Random samples of an open tube (4 x 2 patches): the STEP faces lie on the cylinder."""
    from pde2cad.samples import cylinder

    cloud = cylinder(8000, seed=0)
    path = write_ply(tmp_path / "tube.ply", cloud.points, {"label": cloud.labels.astype(float)},
                     binary=False)
    out = outputs(tmp_path)
    assert main(["reconstruct", str(path), "-o", str(out["step"]), "--report", str(out["report"]),
                 "-q"]) == 0
    shape = read_step(out["step"])
    m = measure(shape)
    assert m["valid"] and m["n_faces"] == 8 and not m["closed"]
    assert m["shared_edges"] == 12 and m["free_edges"] == 8  # 8 seams along, 4 around; 2 rims
    assert m["max_gap"] <= 1e-7 * cloud.diagonal
    true = cloud.distance(_face_samples(shape))
    assert true.max() <= 1e-2 * cloud.diagonal
    report = json.loads(out["report"].read_text())
    assert {tuple(e["labels"]) for e in report["edges"]} == {
        (0, 1), (2, 3), (4, 5), (6, 7),          # along the axis: the two rows of one column
        (0, 2), (1, 3), (2, 4), (3, 5), (4, 6), (5, 7), (0, 6), (1, 7),  # around
    }


# --------------------------------------------------------------------------- C1 seams by corner
def _c1_run(tmp_path_factory: pytest.TempPathFactory, name: str) -> dict[str, Any]:
    """One ``--continuity c1`` run on a sample shape, with the report and the summary."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from pde2cad import samples

    folder = tmp_path_factory.mktemp(name)
    cloud = getattr(samples, name)(20000)
    path = write_ply(folder / f"{name}.ply", cloud.points, {"label": cloud.labels.astype(float)})
    out = outputs(folder)
    stdout, stderr = io.StringIO(), io.StringIO()
    with redirect_stdout(stdout), redirect_stderr(stderr):
        code = main(["reconstruct", str(path), "-o", str(out["step"]), "--report",
                     str(out["report"]), "--continuity", "c1"])
    assert code == 0, stderr.getvalue()
    return {"report": json.loads(out["report"].read_text()), "stdout": stdout.getvalue(),
            "step": out["step"]}


@pytest.fixture(scope="module")
def sphere6_c1(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return _c1_run(tmp_path_factory, "sphere6")


@pytest.fixture(scope="module")
def torus_c1(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return _c1_run(tmp_path_factory, "torus")


def test_sphere6_reports_its_three_patch_corners_apart(sphere6_c1: dict[str, Any]) -> None:
    report = sphere6_c1["report"]
    s = report["summary"]
    assert s["irregular_corners"] == 8 and s["irregular_valences"] == {"3": 8}
    assert s["corner_valences"] == {"3": 8} and s["corners_matched"] is True
    assert len(report["corners"]) == 8 and not any(c["regular"] for c in report["corners"])
    regular, near = s["max_angle_deg_regular"], s["max_angle_deg_near_irregular_corners"]
    # The kink lives next to the corners where no edge pairing exists; it stays small.
    assert 0.0 <= regular < near < 2.0
    assert max(regular, near) == pytest.approx(s["max_angle_deg"])
    assert s["c0_fallback"] == []
    # Every seam runs between two of the eight corners, and is split the same way.
    for e in report["edges"]:
        assert None not in e["corners"] and e["corners"][0] != e["corners"][1]
        assert 0.1 <= e["near_fraction"] <= 0.5
        assert e["max_angle_deg_regular"] <= regular and e["max_angle_deg_near_irregular"] <= near
    assert {frozenset(e["corners"]) for e in report["edges"]} == {
        frozenset(k) for k in _network_edges(report)
    }
    text = sphere6_c1["stdout"]
    assert "away from 8 three-patch corners" in text and "near them" in text
    assert "max normal angle" in text and "kept C0" not in text


def _network_edges(report: dict[str, Any]) -> set[tuple[int, int]]:
    """Pairs of corners 0..7 that are one cube edge apart (same on the six-patch sphere)."""
    xyz = np.array([c["xyz"] for c in report["corners"]])
    d = np.linalg.norm(xyz[:, None] - xyz[None], axis=2)
    step = np.sort(d[d > 0])[0]
    return {(i, j) for i in range(8) for j in range(i + 1, 8) if d[i, j] < 1.2 * step}


def test_torus_c1_is_smooth_at_every_seam(torus_c1: dict[str, Any]) -> None:
    report = torus_c1["report"]
    s = report["summary"]
    assert s["irregular_corners"] == 0 and s["corner_valences"] == {"4": 16}
    assert s["max_angle_deg_regular"] <= 0.05
    assert s["max_angle_deg_near_irregular_corners"] is None
    assert s["max_angle_deg_regular"] == pytest.approx(s["max_angle_deg"])
    assert s["corners_matched"] is True and s["c0_fallback"] == []
    assert all(e["max_angle_deg_near_irregular"] is None for e in report["edges"])
    text = torus_c1["stdout"]
    assert "every corner regular" in text and "three-patch" not in text
    assert "every corner regular" not in "\n".join(_summary_of(report, "c0"))


def _summary_of(report: dict[str, Any], continuity: str) -> list[str]:
    from pde2cad.report import summary_lines

    return summary_lines({**report, "settings": {**report["settings"], "continuity": continuity}})


def test_summary_names_c0_fallback_patches_and_unmatched_corners() -> None:
    from pde2cad.report import summary_lines

    summary = {
        "n_faces": 9, "n_shells": 1, "solid": False, "closed": False, "valid": True,
        "shared_edges": 12, "free_edges": 12, "max_gap": 0.0, "max_gap_rel": 0.0,
        "max_angle_deg": 0.4, "mean_error_rel": 1e-4, "max_error_rel": 1e-3, "diagonal": 2.0,
        "faces_matched": True, "face_match_distance": 0.0, "c0_fallback": [3, 7],
        "irregular_corners": 3, "irregular_valences": {"3": 2, "5": 1},
        "corner_valences": {"3": 2, "4": 4, "5": 1}, "max_angle_deg_regular": 0.0123,
        "max_angle_deg_near_irregular_corners": 0.4, "corners_matched": False,
        "corner_match_distance": 0.01,
    }  # fmt: skip
    text = "\n".join(summary_lines({"summary": summary}))
    assert "C1: patches 3, 7 kept C0 (3-sided or their C1 fit was worse)" in text
    assert ("seams: max normal angle 0.012 deg away from 2 three-patch and 1 five-patch "
            "corners, 0.4 deg near them") in text
    assert "could not all be matched to network corners" in text
    # An old-style summary (no network information) still prints.
    for key in ("c0_fallback", "irregular_corners", "corners_matched"):
        summary.pop(key)
    text = "\n".join(summary_lines({"summary": summary}))
    assert "max normal angle 0.4 deg" in text and "kept C0" not in text and "away" not in text
    # Sparse patches get a note naming the sparsest (folds near corners start there).
    patches = [{"label": 0, "points": 5000}, {"label": 4, "points": 449}, {"label": 5, "points": 900}]
    text = "\n".join(summary_lines({"summary": summary, "patches": patches}))
    assert "2 of 3 patches have fewer than 1000 points (segment 4: 449)" in text
    assert "fewer than" not in "\n".join(summary_lines({"summary": summary, "patches": patches[:1]}))


def test_layout_line_says_which_creases_a_noisy_cloud_told() -> None:
    """A cloud's crease regions: the summary's layout line gives the crease angle the noise
    let it tell and the noise; a mesh's line has neither."""
    from pde2cad.cli import _layout_line

    layout = {"patches": 6, "faces": {"quads": 0, "triangles": 0}, "corner_valence": {},
              "components": 1, "creases": None, "kind": "crease regions"}
    assert "told" not in _layout_line(layout)
    line = _layout_line({**layout, "crease_angle_told": 45.0, "noise": 0.0052})
    assert "creases of 45 deg or more told (point noise 0.0052)" in line
