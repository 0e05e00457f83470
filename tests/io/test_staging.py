"""OutputSet and check_paths: all outputs or none, earlier files kept, names that fit."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from pde2cad.errors import ExportError, InputError
from pde2cad.io.staging import TEMP_MARK, OutputSet, check_paths


def test_commit_writes_every_output(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        with OutputSet() as out:
            out.path(tmp_path / "a.svg").write_text("A")
            out.path(tmp_path / "b.dxf").write_text("B")
            out.commit()
    finally:
        os.umask(old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.svg", "b.dxf"]
    assert (tmp_path / "a.svg").read_text() == "A" and (tmp_path / "b.dxf").read_text() == "B"
    assert (tmp_path / "a.svg").stat().st_mode & 0o777 == 0o644


def test_failed_rename_restores_earlier_files_exactly(tmp_path: Path) -> None:
    first, second, third = tmp_path / "a.step", tmp_path / "b.igs", tmp_path / "c.json"
    first.write_text("earlier run")
    os.chmod(first, 0o640)
    before = first.stat()
    out = OutputSet()
    out.path(first).write_text("new A")
    out.path(third).write_text("new C")
    out.path(second).write_text("new B")
    second.mkdir()  # the rename onto b.igs now fails (a folder is in the way)
    with pytest.raises(ExportError, match="b.igs.*no output of this run was written"):
        out.commit()
    after = first.stat()
    assert first.read_text() == "earlier run"
    assert (after.st_ino, after.st_mode, after.st_mtime_ns) == (before.st_ino, before.st_mode,
                                                                before.st_mtime_ns)
    assert not third.exists()  # new in this run: removed again
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.step", "b.igs"]


def test_exception_in_block_discards(tmp_path: Path) -> None:
    (tmp_path / "a.svg").write_text("old")
    with pytest.raises(RuntimeError):
        with OutputSet() as out:
            out.path(tmp_path / "a.svg").write_text("half")
            raise RuntimeError("boom")
    assert [p.name for p in tmp_path.iterdir()] == ["a.svg"]
    assert (tmp_path / "a.svg").read_text() == "old"


@pytest.mark.parametrize("length", [250, 255])
def test_long_names_fit_the_name_limit(tmp_path: Path, length: int) -> None:
    target = tmp_path / ("n" * (length - 4) + ".dxf")
    with OutputSet() as out:
        tmp = out.path(target)
        assert len(tmp.name.encode()) <= 255 and tmp.name.endswith(".dxf")
        tmp.write_text("x")
    assert target.read_text() == "x"
    with OutputSet() as out:  # multi-byte names are cut on character boundaries
        out.path(tmp_path / ("é" * 120 + ".svg")).write_text("y")
    assert (tmp_path / ("é" * 120 + ".svg")).read_text() == "y"


def test_folder_errors_are_export_errors(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="does not exist"):
        OutputSet().path(tmp_path / "missing" / "a.svg")
    (tmp_path / "d.svg").mkdir()
    with pytest.raises(ExportError, match="is a folder"):
        OutputSet().path(tmp_path / "d.svg")


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path: Path) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    dead_pid = int(dead.stdout)
    target = tmp_path / "out.svg"
    probe = OutputSet()
    name = probe.path(target).name
    probe.discard()
    live_pid = os.getppid()
    stale = tmp_path / name.replace(f"{TEMP_MARK}{os.getpid()}-", f"{TEMP_MARK}{dead_pid}-")
    alive = tmp_path / name.replace(f"{TEMP_MARK}{os.getpid()}-", f"{TEMP_MARK}{live_pid}-")
    other = tmp_path / name.replace("out", "other").replace(f"{TEMP_MARK}{os.getpid()}-", f"{TEMP_MARK}{dead_pid}-")
    for p in (stale, alive, other):
        p.write_text("left by kill -9")
    with OutputSet() as out:
        out.path(target).write_text("ok")
    assert not stale.exists()  # dead process, same target
    assert alive.exists() and other.exists()  # a live run's file, another target's file
    assert target.read_text() == "ok"


def test_check_paths(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    img = tmp_path / "x.svg"
    img.write_text("an image named .svg")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match="would overwrite the input"):
        check_paths([img], [Path("x.svg")])  # relative vs absolute
    os.link(img, tmp_path / "hard.svg")
    with pytest.raises(InputError, match="would overwrite the input"):
        check_paths([img], [tmp_path / "hard.svg"])
    (tmp_path / "soft.svg").symlink_to(img)
    with pytest.raises(InputError, match="would overwrite the input"):
        check_paths([img], [tmp_path / "soft.svg"])
    with pytest.raises(InputError, match="are the same file"):
        check_paths([img], [tmp_path / "a.svg", None, tmp_path / "sub" / ".." / "a.svg"])
    check_paths([img], [tmp_path / "a.svg", tmp_path / "a.dxf", None])
