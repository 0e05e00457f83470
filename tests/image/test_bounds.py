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
