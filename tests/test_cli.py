"""The pde2cad command line: outputs, summary, exit codes, no partial files."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ezdxf
import numpy as np
import pytest
from PIL import Image

from pde2cad.cli import main


@pytest.fixture
def ring_png(tmp_path):
    y, x = np.mgrid[0:120, 0:120] + 0.5
    r = np.hypot(x - 60, y - 60)
    img = np.where((r <= 50) & (r >= 25), 0, 255).astype(np.uint8)
    path = tmp_path / "ring.png"
    Image.fromarray(img).save(path)
    return path


def test_vectorize_writes_svg_dxf_and_report(ring_png, tmp_path, capsys):
    svg, dxf, rep = tmp_path / "r.svg", tmp_path / "r.dxf", tmp_path / "r.json"
    code = main(["vectorize", str(ring_png), "-o", str(svg), "-o", str(dxf), "--report", str(rep), "--dpi", "254"])
    assert code == 0
    out = capsys.readouterr().out
    assert "1 shapes, 2 loops" in out and "max error" in out
    report = json.loads(rep.read_text())
    assert report["loops"] == 2 and report["max_error_px"] <= 1.0
    doc = ezdxf.readfile(dxf)
    assert doc.header["$INSUNITS"] == 4
    assert len(doc.modelspace().query("SPLINE")) == 2
    assert svg.read_text().count("<path") == 1


def test_default_output_is_beside_the_image(ring_png):
    assert main(["vectorize", str(ring_png)]) == 0
    assert ring_png.with_suffix(".svg").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["vectorize", "/no/such/file.png"], "no such file"),
        (["vectorize", "{ring}", "--tolerance", "0"], "must be a number > 0"),
        (["vectorize", "{ring}", "-o", "{tmp}/out.pdf"], "must end in .svg or .dxf"),
        (["vectorize", "{text}"], "not an image"),
        (["vectorize", "{blank}"], "no foreground"),
    ],
)
def test_bad_input_exits_non_zero_with_a_message_and_no_file(args, message, ring_png, tmp_path):
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    blank = tmp_path / "blank.png"
    Image.fromarray(np.full((20, 20), 255, np.uint8)).save(blank)
    args = [a.format(ring=ring_png, tmp=tmp_path, text=text, blank=blank) for a in args]
    proc = subprocess.run([sys.executable, "-m", "pde2cad.cli", *args, "-o", str(tmp_path / "x.svg")]
                          if "-o" not in args else [sys.executable, "-m", "pde2cad.cli", *args],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "x.svg").exists() and not (tmp_path / "out.pdf").exists()


def test_unwritable_output_exits_3(ring_png, tmp_path, capsys):
    code = main(["vectorize", str(ring_png), "-o", str(tmp_path / "missing" / "x.svg")])
    assert code == 3
    assert "does not exist" in capsys.readouterr().err


def test_version_and_help():
    proc = subprocess.run([sys.executable, "-m", "pde2cad.cli", "--version"], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stdout.startswith("pde2cad ")
    proc = subprocess.run([sys.executable, "-m", "pde2cad.cli", "--help"], capture_output=True, text=True)
    assert "vectorize" in proc.stdout


def test_arcs_dxf_stays_within_the_tolerance_of_the_pixel_boundary(ring_png, tmp_path):
    from pde2cad.image.evaluate import boundary_samples
    from pde2cad.image.raster import read_image

    dxf = tmp_path / "r.dxf"
    assert main(["vectorize", str(ring_png), "-o", str(dxf), "--dxf-curves", "arcs"]) == 0
    doc = ezdxf.readfile(dxf)
    assert doc.audit().has_errors is False
    height = read_image(ring_png).shape[0]
    pts = []
    for pl in doc.modelspace().query("LWPOLYLINE"):
        for v in pl.virtual_entities():
            if v.dxftype() == "ARC":
                pts.extend((p.x, height - p.y) for p in v.flattening(0.001))
            else:
                for f in np.linspace(0.0, 1.0, 64):
                    p = v.dxf.start + (v.dxf.end - v.dxf.start) * f
                    pts.append((p.x, height - p.y))
    pts = np.asarray(pts)
    boundary = boundary_samples(read_image(ring_png), step=0.1)
    from scipy.spatial import cKDTree

    d_boundary_to_arcs = cKDTree(pts).query(boundary)[0].max()
    d_arcs_to_boundary = cKDTree(boundary).query(pts)[0].max()
    assert d_boundary_to_arcs <= 1.0 + 0.01  # flattening at 1e-3, sample spacing 0.1
    assert d_arcs_to_boundary <= 1.0 + 0.06


# --------------------------------------------------------------------------- no lost data
def cli(*args, **kwargs) -> subprocess.CompletedProcess:  # noqa: ANN002, ANN003
    return subprocess.run([sys.executable, "-m", "pde2cad.cli", *map(str, args)],
                          capture_output=True, text=True, **kwargs)


def litter(folder) -> list[str]:  # noqa: ANN001
    return sorted(p.name for p in folder.iterdir() if ".pde2cad-" in p.name)


@pytest.fixture
def svg_named_image(ring_png, tmp_path):
    """A PNG image whose name ends in .svg (what a user may well have)."""
    path = tmp_path / "x.svg"
    path.write_bytes(ring_png.read_bytes())
    return path


@pytest.mark.parametrize(
    "extra",
    [[], ["-o", "{img}"], ["-o", "{tmp}/a.svg", "--report", "{img}"],
     ["-o", "{tmp}/a.svg", "--report", "{tmp}/a.svg"], ["-o", "{tmp}/a.dxf", "-o", "{tmp}/./a.dxf"]],
)
def test_outputs_that_would_overwrite_an_input_or_each_other_are_refused(svg_named_image, tmp_path,
                                                                           extra):
    before = svg_named_image.read_bytes()
    proc = cli("vectorize", svg_named_image, *[a.format(img=svg_named_image, tmp=tmp_path) for a in extra])
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "overwrite the input" in proc.stderr or "same file" in proc.stderr
    assert svg_named_image.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ring.png", "x.svg"]


def test_second_output_unwritable_writes_neither(ring_png, tmp_path):
    (tmp_path / "a.svg").write_text("earlier")
    proc = cli("vectorize", ring_png, "-o", tmp_path / "a.svg", "-o", tmp_path / "nope" / "b.dxf")
    assert proc.returncode == 3 and "does not exist" in proc.stderr and "Traceback" not in proc.stderr
    assert (tmp_path / "a.svg").read_text() == "earlier"
    assert litter(tmp_path) == []


def _as_nobody() -> list[str]:
    """Run as an unprivileged user when root (root ignores folder permissions)."""
    return ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"] if os.geteuid() == 0 else []


@pytest.fixture
def open_dir():
    """A folder an unprivileged user can reach (pytest's tmp_path is 0700 when root)."""
    path = Path(tempfile.mkdtemp(prefix="pde2cad-cli-"))
    path.chmod(0o777)
    yield path
    for p in path.rglob("*"):
        p.chmod(0o777)
    shutil.rmtree(path)


def test_report_into_read_only_folder_exits_3_and_leaves_no_svg(ring_png, open_dir):
    img = open_dir / "ring.png"
    img.write_bytes(ring_png.read_bytes())
    img.chmod(0o644)
    ro = open_dir / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    src = str(Path(__file__).resolve().parents[1] / "src")
    proc = subprocess.run([*_as_nobody(), sys.executable, "-m", "pde2cad.cli", "vectorize", str(img),
                           "-o", str(open_dir / "r.svg"), "--report", str(ro / "r.json")],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": src})
    assert proc.returncode == 3, proc.stderr
    assert "Traceback" not in proc.stderr and "r.json" in proc.stderr
    assert not (open_dir / "r.svg").exists() and litter(open_dir) == [] and list(ro.iterdir()) == []


def test_full_disk_while_writing_exits_3_with_nothing_written(ring_png, tmp_path):
    import resource

    def small_files() -> None:  # writes past 2 kB fail with EFBIG, as on a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (2048, 2048))

    proc = cli("vectorize", ring_png, "-o", tmp_path / "r.svg", "-o", tmp_path / "r.dxf",
               preexec_fn=small_files)
    assert proc.returncode == 3, proc.stderr
    assert "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ring.png"]


def test_stdout_on_a_full_device_exits_3_without_traceback(ring_png, tmp_path):
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "pde2cad.cli", "vectorize", str(ring_png), "-o",
                               str(tmp_path / "r.svg")], stdout=full, stderr=subprocess.PIPE, text=True)
    assert proc.returncode == 3
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr
    assert "summary could not be printed" in proc.stderr
    assert (tmp_path / "r.svg").read_text().count("<path") == 1  # the outputs are written


def test_closed_stdout_pipe_exits_0(ring_png, tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "pde2cad.cli", "vectorize", str(ring_png), "-o",
                             str(tmp_path / "r.svg")], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # like `| head -0`
    err = proc.stderr.read().decode()
    assert proc.wait() == 0 and "Traceback" not in err and "Exception ignored" not in err


@pytest.fixture
def slow_image(tmp_path):
    """Two 7-point stars that take the vectorizer a few seconds (one alone got too fast for
    the signal tests to catch the run)."""
    size = 300
    r = np.where(np.arange(14) % 2 == 0, 0.45, 0.18) * size
    from PIL import ImageDraw

    img = Image.new("L", (2 * size, size), 255)
    for k in range(2):
        a = -0.3 + 0.37 * k + np.arange(14) * np.pi / 7
        ImageDraw.Draw(img).polygon([(size / 2 + k * size + x, size / 2 + y) for x, y in
                                     zip(r * np.cos(a), r * np.sin(a))], fill=0)
    path = tmp_path / "star.png"
    img.save(path)
    return path


def _start_and_wait_for_temps(slow_image, folder) -> subprocess.Popen:  # noqa: ANN001
    proc = subprocess.Popen([sys.executable, "-m", "pde2cad.cli", "vectorize", str(slow_image),
                             "-o", str(folder / "s.svg"), "-o", str(folder / "s.dxf"),
                             "--report", str(folder / "s.json")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            # Ctrl-C as in a terminal: a background job (nohup, `cmd &` in a
                            # script) starts its children with SIGINT ignored, and Python then
                            # installs no KeyboardInterrupt handler (the run ended with 0).
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while len(litter(folder)) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    assert proc.poll() is None, "the run ended before it could be stopped"
    return proc


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_and_sigint_remove_the_temporary_files(slow_image, tmp_path, sig):
    (tmp_path / "s.svg").write_text("earlier")
    proc = _start_and_wait_for_temps(slow_image, tmp_path)
    proc.send_signal(sig)
    code = proc.wait(timeout=60)
    err = proc.stderr.read().decode()
    assert code == (-signal.SIGTERM if sig == signal.SIGTERM else 130), err
    assert "Traceback" not in err
    assert litter(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ring.png", "s.svg", "star.png"] or \
        sorted(p.name for p in tmp_path.iterdir()) == ["s.svg", "star.png"]
    assert (tmp_path / "s.svg").read_text() == "earlier"


def test_kill_9_leftovers_are_removed_by_the_next_run(slow_image, tmp_path):
    proc = _start_and_wait_for_temps(slow_image, tmp_path)
    proc.kill()
    proc.wait(timeout=60)
    left = litter(tmp_path)
    assert len(left) == 3 and all(f"-{proc.pid}-" in name for name in left)
    assert not any((tmp_path / n).exists() for n in ("s.svg", "s.dxf", "s.json"))
    again = cli("vectorize", slow_image, "-o", tmp_path / "s.svg", "-o", tmp_path / "s.dxf",
                "--report", tmp_path / "s.json")
    assert again.returncode == 0, again.stderr
    assert litter(tmp_path) == []
    assert json.loads((tmp_path / "s.json").read_text())["loops"] == 2


def test_dxf_version_and_offset_flags(ring_png, tmp_path):
    out = tmp_path / "r12.dxf"
    proc = cli("vectorize", ring_png, "-o", out, "--dxf-version", "r12", "--offset", "0.5", "--dpi", "254")
    assert proc.returncode == 0, proc.stderr
    doc = ezdxf.readfile(out)
    assert doc.dxfversion == "AC1009" and not doc.audit().has_errors
    assert {e.dxftype() for e in doc.modelspace()} == {"POLYLINE"}
    proc = cli("vectorize", ring_png, "-o", tmp_path / "r.svg", "--offset", "0.5")
    assert proc.returncode == 2 and "DXF output only" in proc.stderr
