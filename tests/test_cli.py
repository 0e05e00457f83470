"""The pde2cad command line: outputs, summary, exit codes, no partial files."""

from __future__ import annotations

import json
import subprocess
import sys

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
