"""Despeckling, time and size bounds, and the batch command line (issue 11)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from pde2cad.cli import main
from pde2cad.errors import FitError, InputError
from pde2cad.image.evaluate import outline_error
from pde2cad.image.vectorize import MAX_EDGES, vectorize


def _disc(n: int = 120, r: float = 40.0) -> np.ndarray:
    y, x = np.mgrid[0:n, 0:n] + 0.5
    return np.hypot(x - n / 2, y - n / 2) <= r


def test_salt_and_pepper_specks_are_dropped_and_counted():
    rng = np.random.default_rng(3)
    clean = _disc()
    noisy = clean.copy()
    flip = rng.random(clean.shape) < 0.004  # isolated single pixels, both colours
    noisy ^= flip
    ref = vectorize(clean, symmetry=False)
    got = vectorize(noisy, symmetry=False)
    kept = vectorize(noisy, symmetry=False, min_area=0)
    assert got.specks >= 0.9 * flip.sum() - 5  # nearly every flipped pixel is a speck
    assert got.n_curves <= ref.n_curves + 2  # the disc costs what it costs without noise
    assert kept.specks == 0 and kept.n_curves > 5 * got.n_curves
    # Despeckling must not cost accuracy on the remaining boundary (measured on the mask).
    assert outline_error(clean, [lp.curves for lp in got.loops])["max_boundary_to_curve"] <= 1.5


def test_one_pixel_checkerboard_becomes_one_square():
    board = (np.indices((256, 256)).sum(0) % 2).astype(bool)
    d = vectorize(board)
    assert len(d.loops) == 1 and d.specks > 30000  # the 1-px holes are filled
    assert d.n_curves <= 8


def test_max_seconds_stops_with_a_clear_error():
    board = (np.indices((512, 512)).sum(0) % 2).astype(bool)
    with pytest.raises(FitError, match="max-seconds"):
        vectorize(board, min_area=0, max_seconds=0.5)


def test_noise_beyond_the_edge_limit_is_refused_before_tracing():
    side = int(np.sqrt(MAX_EDGES)) + 200
    noise = np.random.default_rng(0).random((side, side), dtype=np.float32) < 0.5
    with pytest.raises(InputError, match="boundary edges"):
        vectorize(noise)


def test_batch_writes_every_image_and_one_line_each(tmp_path, capsys):
    paths = []
    for i, r in enumerate((30.0, 40.0, 50.0)):
        p = tmp_path / f"disc{i}.png"
        Image.fromarray(np.where(_disc(r=r), 0, 255).astype(np.uint8)).save(p)
        paths.append(str(p))
    bad = tmp_path / "blank.png"
    Image.fromarray(np.full((20, 20), 255, np.uint8)).save(bad)
    out = tmp_path / "out"
    out.mkdir()
    code = main(["vectorize", *paths, str(bad), "--out-dir", str(out), "--format", "svg,dxf", "--jobs", "2"])
    text = capsys.readouterr().out.splitlines()
    assert code == 2  # the blank image is bad input; the others are still written
    assert sorted(f.name for f in out.iterdir()) == sorted(
        [f"disc{i}.{e}" for i in range(3) for e in ("svg", "dxf")]
    )
    assert len(text) == 5 and "blank.png: error" in text[3] and text[-1].startswith("vectorize: 4 images, 1 failed")


def test_batch_needs_an_out_dir(tmp_path):
    assert main(["vectorize", "a.png", "b.png"]) == 2


def test_batch_refuses_to_overwrite_an_input(tmp_path):
    """An image named x.svg in the output folder would be replaced by its own SVG: refused
    before any work, the image untouched."""
    img = tmp_path / "disc.svg"  # a PNG under an .svg name
    Image.fromarray(np.where(_disc(r=20.0), 0, 255).astype(np.uint8)).save(img, format="PNG")
    other = tmp_path / "other.png"
    Image.fromarray(np.where(_disc(r=25.0), 0, 255).astype(np.uint8)).save(other)
    before = img.read_bytes()
    assert main(["vectorize", str(img), str(other), "--out-dir", str(tmp_path)]) == 2
    assert img.read_bytes() == before and not (tmp_path / "other.svg").exists()


def test_batch_writes_the_dxf_version_and_kerf_asked_for(tmp_path):
    """--dxf-version and --offset reach every image of a batch, as for one image: R12
    polylines of lines and arcs, the disc grown by the offset."""
    import ezdxf

    paths = []
    for i, r in enumerate((30.0, 40.0)):
        p = tmp_path / f"disc{i}.png"
        Image.fromarray(np.where(_disc(r=r), 0, 255).astype(np.uint8)).save(p)
        paths.append(str(p))
    out = tmp_path / "out"
    out.mkdir()
    assert main(["vectorize", *paths, "--out-dir", str(out), "--format", "dxf",
                 "--dxf-version", "R12", "--offset", "2", "--jobs", "1"]) == 0
    for i, r in enumerate((30.0, 40.0)):
        doc = ezdxf.readfile(out / f"disc{i}.dxf")
        assert doc.dxfversion == "AC1009"
        msp = doc.modelspace()
        assert not msp.query("SPLINE") and len(msp.query("POLYLINE")) == 1
        pts = np.array([(v.dxf.location.x, v.dxf.location.y) for v in msp.query("POLYLINE")[0].vertices])
        # Vertices (arc ends) need not be evenly spread: the centre by a circle fit
        # (Kasa), not their centroid.
        A = np.c_[2 * pts, np.ones(len(pts))]
        cx, cy, _ = np.linalg.lstsq(A, (pts**2).sum(axis=1), rcond=None)[0]
        radius = np.linalg.norm(pts - [cx, cy], axis=1)
        assert abs(radius.mean() - (r + 2.0)) < 1.0  # grown by the kerf (1 px tolerance)
        assert np.ptp(radius) < 2.0
