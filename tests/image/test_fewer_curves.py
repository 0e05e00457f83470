"""Curve counts against potrace and the symmetric distance on shapes this project did not
draw (issue 11 items 1 and 5): glyphs of fonts matplotlib ships (Computer Modern sans,
STIX italic), native and upscaled 4x, and a level set of matplotlib's sample height map."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

import pde2cad
from pde2cad.image.evaluate import outline_error, run_potrace

matplotlib = pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL")
needs_potrace = pytest.mark.skipif(shutil.which("potrace") is None, reason="potrace (Debian package) not installed")

_FONTS = Path(matplotlib.__file__).parent / "mpl-data" / "fonts" / "ttf"


def _glyph(font: str, ch: str, size: int = 64, scale: int = 1) -> np.ndarray:
    from PIL import Image, ImageDraw, ImageFont

    f = ImageFont.truetype(str(_FONTS / font), size)
    im = Image.new("L", (2 * size, 2 * size), 255)
    ImageDraw.Draw(im).text((size // 3, size // 6), ch, font=f, fill=0)
    mask = np.asarray(im) < 128
    return np.kron(mask, np.ones((scale, scale), bool)) if scale > 1 else mask


def _level_set() -> np.ndarray:
    z = np.load(Path(matplotlib.__file__).parent / "mpl-data" / "sample_data" / "topobathy.npz")["topo"]
    return z > np.quantile(z, 0.4)


def _despeckled(mask: np.ndarray, area: int = 2) -> np.ndarray:
    """The mask without what vectorize drops by default, by the benchmark's independent
    scipy.ndimage code (shapes and holes of at most ``area`` pixels)."""
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "vectorize_vs_potrace.py"
    spec = importlib.util.spec_from_file_location("vectorize_vs_potrace", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.despeckled(mask, area)


def _join_angles(curves: np.ndarray) -> np.ndarray:
    """Turn (degrees) at each join of a closed chain, from the curves' end tangents."""
    out = curves[:, 3] - curves[:, 2]
    inn = np.roll(curves, -1, axis=0)
    inn = inn[:, 1] - inn[:, 0]
    cos = (out * inn).sum(1) / np.maximum(np.linalg.norm(out, axis=1) * np.linalg.norm(inn, axis=1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


CASES = {
    "cmss10": [_glyph("cmss10.ttf", ch) for ch in "BGakmy5&"],
    "stix_italic": [_glyph("STIXGeneralItalic.ttf", ch) for ch in "Rbfhw3?"],
    "cmr10_4x": [_glyph("cmr10.ttf", ch, scale=4) for ch in "Sgj"],
}


@needs_potrace
@pytest.mark.parametrize("name", sorted(CASES))
def test_half_of_potrace_segments_and_symmetric_distance_within_tolerance(name):
    ours = theirs = 0
    for mask in CASES[name]:
        d = pde2cad.vectorize(mask, 1.0, symmetry=False)
        curves = [lp.curves for lp in d.loops]
        ours += sum(len(c) for c in curves)
        theirs += run_potrace(mask)["segments"]
        err = outline_error(_despeckled(mask), curves)
        # Both ways: pixel boundary -> curves and curves -> pixel boundary (+ sampling slack).
        assert err["max_boundary_to_curve"] <= 1.0
        assert err["max_curve_to_boundary"] <= 1.05
    assert ours <= 0.5 * theirs, (name, ours, theirs)


def test_every_kink_between_curves_is_a_declared_corner():
    # G1 is kept where the outline is smooth: a join that turns is counted as a corner.
    for mask in CASES["cmr10_4x"] + CASES["stix_italic"]:
        for lp in pde2cad.vectorize(mask, 1.0, symmetry=False).loops:
            if len(lp.curves) > 1:
                turns = _join_angles(np.asarray(lp.curves))
                assert np.count_nonzero(turns > 2.5) <= lp.corners


@pytest.mark.xfail(reason="issue 11 item 1 not met yet: 103 curves vs 87 for a plain C0 least-squares fit"
                   " on this level set (G1 joins at smooth points still cost pieces here)", strict=False)
def test_level_set_loops_cost_no_more_than_a_plain_c0_fit():
    from pde2cad.curves.piecewise import fit_chain
    from pde2cad.image.contours import trace_loops

    from pde2cad.image.vectorize import despeckle

    mask = _level_set()
    d = pde2cad.vectorize(mask, 1.0, symmetry=False)
    plain = 0
    for c in despeckle(trace_loops(mask), 2)[0]:
        ring = np.vstack([c.points, c.points[:1]])
        plain += len(fit_chain(ring, 1.0, g1=False, edge_midpoints=True).curves)
    assert d.n_curves <= plain
    err = outline_error(mask, [lp.curves for lp in d.loops])
    assert max(err["max_boundary_to_curve"], err["max_curve_to_boundary"]) <= 1.0
