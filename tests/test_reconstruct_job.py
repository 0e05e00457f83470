"""The reconstruct job as a library call: path clashes refused before any work, all-or-nothing
outputs that never lose an earlier run's files, header options reaching the writers."""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("OCP")

import pde2cad.reconstruct  # noqa: E402,F401 - the submodule, for dotted-path patching
from pde2cad.cli import main  # noqa: E402
from pde2cad.errors import ExportError  # noqa: E402
from pde2cad.occ import measure, read_iges, read_step  # noqa: E402
from pde2cad.reconstruct_job import ReconstructJob, Staging, run_reconstruct  # noqa: E402


def sheet(n: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """z = 0.1 sin(x) sin(y) on an n x n grid over [0, 2]^2, labelled by quadrant (2 x 2)."""
    g = np.linspace(0.0, 2.0, n)
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    return np.column_stack([x, y, 0.1 * np.sin(x) * np.sin(y)]), (x > 1.0) + 2 * (y > 1.0)


@pytest.fixture()
def cloud(tmp_path: Path) -> Path:
    """A text cloud with its labels in a separate ``labels.txt``."""
    pts, lab = sheet()
    np.savetxt(tmp_path / "c.xyz", pts)
    np.savetxt(tmp_path / "labels.txt", lab, fmt="%d")
    return tmp_path / "c.xyz"


def _no_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    def fail(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("reconstruct ran although the paths clash")

    monkeypatch.setattr("pde2cad.reconstruct.reconstruct", fail)


@pytest.mark.parametrize("target, victim", [("out.step", "c.xyz"), ("r.json", "labels.txt")])
def test_a_link_to_an_input_is_refused_before_any_work(
    cloud: Path, target: str, victim: str, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """An output that is (a symbolic link to) the cloud or the label file: exit 2, the input
    unchanged, no fit run."""
    folder = cloud.parent
    (folder / target).symlink_to(folder / victim)
    before = (folder / victim).read_bytes()
    _no_fit(monkeypatch)
    args = ["reconstruct", str(cloud), "--labels", str(folder / "labels.txt"), "-q"]
    args += ["-o", str(folder / target)] if target.endswith(".step") else \
        ["-o", str(folder / "o.step"), "--report", str(folder / target)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "would overwrite the input" in err and victim in err
    assert (folder / victim).read_bytes() == before
    assert not (folder / "o.step").exists()


def test_two_outputs_that_are_one_file_are_refused(
    cloud: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = cloud.parent
    (folder / "a.step").write_text("earlier")
    os.link(folder / "a.step", folder / "a.igs")  # one file, two names
    _no_fit(monkeypatch)
    assert main(["reconstruct", str(cloud), "--labels", str(folder / "labels.txt"),
                 "-o", str(folder / "a.step"), "--iges", str(folder / "a.igs")]) == 2
    assert "-o and --iges name the same file" in capsys.readouterr().err
    assert (folder / "a.step").read_text() == "earlier"


def test_a_folder_as_output_is_refused(cloud: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (cloud.parent / "dir.step").mkdir()
    assert main(["reconstruct", str(cloud), "--labels", str(cloud.parent / "labels.txt"),
                 "-o", str(cloud.parent / "dir.step")]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_a_failed_commit_keeps_the_earlier_run(
    cloud: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Run 1 writes STEP + IGES. Run 2 fails while renaming its IGES into place (disk full):
    exit 3 naming the IGES, and both files of run 1 are still there, byte for byte."""
    folder = cloud.parent
    step, iges = folder / "o.step", folder / "o.igs"
    args = ["reconstruct", str(cloud), "--labels", str(folder / "labels.txt"), "-o", str(step),
            "--iges", str(iges), "-q"]
    assert main(args) == 0
    earlier = {p: p.read_bytes() for p in (step, iges)}
    real_replace = os.replace

    def full_disk(src: Any, dst: Any) -> None:
        if Path(dst) == iges:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", full_disk)
    assert main([*args, "--terms", "4"]) == 3
    err = capsys.readouterr().err
    assert f"cannot write {iges}" in err and "No space left" in err and str(step) not in err
    monkeypatch.undo()
    for path, data in earlier.items():
        assert path.read_bytes() == data, path
    assert sorted(p.name for p in folder.iterdir()) == ["c.xyz", "labels.txt", "o.igs", "o.step"]


def test_a_failed_commit_of_a_first_run_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    staging = Staging()
    targets = [tmp_path / "a.step", tmp_path / "b.igs"]
    for t in targets:
        staging.path(t).write_text(t.name)
    real_replace = os.replace

    def fail_second(src: Any, dst: Any) -> None:
        if Path(dst) == targets[1]:
            raise OSError(errno.EIO, "I/O error")
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", fail_second)
    with pytest.raises(ExportError, match="b.igs"):
        staging.commit()
    assert list(tmp_path.iterdir()) == []


def test_a_250_character_output_name_is_written(tmp_path: Path) -> None:
    target = tmp_path / ("x" * 245 + ".step")
    staging = Staging()
    tmp = staging.path(target)
    assert len(tmp.name) <= 255
    tmp.write_text("data")
    staging.commit()
    assert target.read_text() == "data" and len(list(tmp_path.iterdir())) == 1


def test_header_options_reach_the_files(cloud: Path) -> None:
    """--name/--author/--organization land in the STEP and IGES headers; without --name the
    product is named after the target file, never after the staging file."""
    folder = cloud.parent
    job = ReconstructJob(cloud=cloud, labels=str(folder / "labels.txt"), output=folder / "o.step",
                         iges=folder / "o.igs", name="bracket-7", author="A. Smith",
                         organization="Works Ltd")
    result = run_reconstruct(job)
    step = result.outputs["output"].read_text()
    iges = result.outputs["iges"].read_text()
    for text in ("bracket-7", "A. Smith", "Works Ltd"):
        assert text in step and text in iges
    assert "PRODUCT('bracket-7'" in step and "segment_" in step
    assert measure(read_step(result.outputs["output"]))["n_faces"] == 4
    assert measure(read_iges(result.outputs["iges"]))["n_faces"] == 4
    run_reconstruct(ReconstructJob(cloud=cloud, labels=str(folder / "labels.txt"),
                                   output=folder / "pump_cover.step"))
    text = (folder / "pump_cover.step").read_text()
    assert "PRODUCT('pump_cover'" in text and "pde2cad" in text and ".tmp" not in text


def test_job_result_matches_the_files(cloud: Path) -> None:
    folder = cloud.parent
    result = run_reconstruct(ReconstructJob(cloud=cloud, labels=str(folder / "labels.txt"),
                                            output=folder / "o.step", report=folder / "r.json"))
    s = result.report["summary"]
    m = measure(read_step(folder / "o.step"), samples=s["seam_samples"])
    assert (s["n_faces"], s["shared_edges"], s["free_edges"]) == (4, 4, 8)
    assert s["max_gap"] == pytest.approx(m["max_gap"], abs=1e-12)
    assert s["max_gap"] <= 1e-7 * result.reconstruction.diagonal
    assert result.timings["total"] >= result.timings["reconstruct"] > 0
    assert set(result.outputs) == {"output", "report"}


def test_cli_header_flags_reach_the_job(cloud: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """The CLI only parses: its --name/--author/--organization become the job's fields."""
    import pde2cad.reconstruct_job as job_module

    jobs: list[ReconstructJob] = []
    real = job_module.run_reconstruct

    def spy(job: ReconstructJob, **kwargs: Any) -> Any:
        jobs.append(job)
        return real(job, **kwargs)

    monkeypatch.setattr(job_module, "run_reconstruct", spy)
    folder = cloud.parent
    assert main(["reconstruct", str(cloud), "--labels", str(folder / "labels.txt"), "-o",
                 str(folder / "o.step"), "--name", "bracket-7", "--author", "A. Smith",
                 "--organization", "Works Ltd", "--continuity", "c1", "--terms", "5"]) == 0
    (job,) = jobs
    assert (job.name, job.author, job.organization) == ("bracket-7", "A. Smith", "Works Ltd")
    assert (job.continuity, job.terms, Path(job.output)) == ("c1", 5, folder / "o.step")
    out = capsys.readouterr().out
    assert "4 faces" in out and str(folder / "o.step") in out
    assert measure(read_step(folder / "o.step"))["n_faces"] == 4


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (Linux)")
def test_a_full_stdout_is_exit_3_not_a_traceback(cloud: Path) -> None:
    import subprocess
    import sys

    folder = cloud.parent
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            [sys.executable, "-m", "pde2cad.cli", "reconstruct", str(cloud), "--labels",
             str(folder / "labels.txt"), "-o", str(folder / "o.step")],
            stdout=full, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")},
        )
    assert proc.returncode == 3, proc.stderr
    assert "summary could not be printed" in proc.stderr and "Traceback" not in proc.stderr
    assert measure(read_step(folder / "o.step"))["n_faces"] == 4
