"""The whole Chapter 3 pipeline, checked against the exact pixel boundary."""

from __future__ import annotations

import numpy as np
import pytest

import pde2cad
from pde2cad.errors import InputError
from pde2cad.image.evaluate import outline_error


def _disc(r, size, cx=None, cy=None):
    cx = size / 2 if cx is None else cx
    cy = size / 2 if cy is None else cy
    y, x = np.mgrid[0:size, 0:size] + 0.5
    return (x - cx) ** 2 + (y - cy) ** 2 <= r * r


def _angle_deg(u, v):
    return np.degrees(np.arctan2(abs(u[0] * v[1] - u[1] * v[0]), np.dot(u, v)))


def _errors(mask, drawing):
    return outline_error(mask, [lp.curves for lp in drawing.loops])


@pytest.mark.parametrize("tol, most", [(1.0, 4), (0.75, 6)])
def test_disc_within_tolerance_with_few_curves(tol, most):
    mask = _disc(60.3, 150)
    d = pde2cad.vectorize(mask, tol)
    e = _errors(mask, d)
    assert e["max_boundary_to_curve"] <= tol
    assert e["max_curve_to_boundary"] <= tol
    assert d.n_curves <= most
    assert d.loops[0].corners == 0


def test_tolerance_holds_even_below_half_a_pixel():
    # A staircase's vertices sit +-0.5 px around any smooth curve, so below ~0.5 px the fit
    # must fall back to short C0 pieces; the promise still holds.
    mask = _disc(20.3, 50)
    d = pde2cad.vectorize(mask, 0.3, symmetry=False)
    e = _errors(mask, d)
    assert e["max_boundary_to_curve"] <= 0.3
    assert e["max_curve_to_boundary"] <= 0.3


def test_rectangle_is_four_exact_lines_on_pixel_corners():
    mask = np.zeros((30, 40), bool)
    mask[5:20, 8:33] = True
    d = pde2cad.vectorize(mask, 1.0)
    assert d.n_curves == 4
    ends = {tuple(np.round(c[0], 9)) for c in d.loops[0].curves}
    assert ends == {(8.0, 5.0), (33.0, 5.0), (33.0, 20.0), (8.0, 20.0)}  # no half-pixel shift
    assert _errors(mask, d)["max_boundary_to_curve"] < 1e-9


def test_smooth_joins_are_g1_and_corners_stay_sharp():
    # A rounded "D": a half disc (smooth) closed by a straight side (two sharp corners).
    mask = _disc(70, 200, cx=60, cy=100)
    mask[:, :60] = False
    d = pde2cad.vectorize(mask, 1.0, symmetry=False)
    loop = d.loops[0]
    assert loop.corners == 2
    c = loop.curves
    angles = [_angle_deg(a[3] - a[2], b[1] - b[0]) for a, b in zip(c, np.roll(c, -1, axis=0))]
    sharp = [a for a in angles if a > 1e-6]
    assert len(sharp) == 2 and min(sharp) > 60
    assert _errors(mask, d)["max_boundary_to_curve"] <= 1.0


def test_c0_option_keeps_the_thesis_joins():
    mask = _disc(80, 200)
    d = pde2cad.vectorize(mask, 1.0, g1=False, symmetry=False)
    assert _errors(mask, d)["max_boundary_to_curve"] <= 1.0


def test_holes_and_shapes_in_holes_keep_their_nesting():
    mask = _disc(60, 160) & ~_disc(40, 160)
    mask |= _disc(15, 160)
    d = pde2cad.vectorize(mask, 1.0)
    kinds = sorted((lp.depth, lp.is_hole) for lp in d.loops)
    assert kinds == [(0, False), (1, True), (2, False)]
    assert len(d.shapes()) == 2
    assert _errors(mask, d)["max_boundary_to_curve"] <= 1.0


def test_mirror_symmetric_shape_costs_fewer_curves():
    # A heart-like shape, exactly symmetric about x = 100.
    y, x = np.mgrid[0:200, 0:200] + 0.5
    u, v = (x - 100) / 60, (110 - y) / 60
    mask = (u * u + v * v - 1) ** 3 - u * u * v**3 <= 0
    with_sym = pde2cad.vectorize(mask, 1.0)
    without = pde2cad.vectorize(mask, 1.0, symmetry=False)
    assert with_sym.loops[0].symmetry == "mirror"
    assert with_sym.n_fitted_curves <= (without.n_curves + 1) // 2
    assert with_sym.n_curves <= without.n_curves + 1
    # The written outline is mirror-symmetric: curve k mirrors curve K-1-k.
    c = with_sym.loops[0].curves
    mirrored = c[:, :, :].copy()
    mirrored[..., 0] = 200.0 - mirrored[..., 0]
    assert np.abs(mirrored[::-1, ::-1] - c).max() < 1e-9
    assert _errors(mask, with_sym)["max_boundary_to_curve"] <= 1.0


def test_rotation_symmetric_gear_costs_fewer_curves():
    y, x = np.mgrid[0:240, 0:240] + 0.5
    r = np.hypot(x - 120, y - 120)
    th = np.arctan2(y - 120, x - 120)
    mask = r <= 80 + 14 * np.tanh(4 * np.sin(6 * th))
    with_sym = pde2cad.vectorize(mask, 1.0)
    without = pde2cad.vectorize(mask, 1.0, symmetry=False)
    assert with_sym.loops[0].symmetry.startswith("rotation")
    # The fitted part is the cost (Section 3.1); the written outline grows by at most one.
    assert with_sym.n_fitted_curves < without.n_curves / 2
    assert with_sym.n_curves <= without.n_curves + 1
    assert _errors(mask, with_sym)["max_boundary_to_curve"] <= 1.0


def test_one_pixel_shape_is_traced_within_tolerance():
    mask = np.zeros((5, 5), bool)
    mask[2, 3] = True
    assert pde2cad.vectorize(mask, 1.0).specks == 1  # a speck by default (potrace's turdsize)
    d = pde2cad.vectorize(mask, 1.0, min_area=0)
    assert len(d.loops) == 1 and d.n_curves >= 1
    assert _errors(mask, d)["max_boundary_to_curve"] <= 1.0


@pytest.mark.parametrize("tol", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_tolerance_is_refused(tol):
    with pytest.raises(InputError, match="tolerance"):
        pde2cad.vectorize(_disc(10, 30), tol)


def test_empty_image_names_the_fix():
    with pytest.raises(InputError, match="no foreground.*invert"):
        pde2cad.vectorize(np.zeros((20, 20), bool))


def test_report_lists_loops_errors_and_parameterizations():
    mask = _disc(30, 80) & ~_disc(10, 80)
    rep = pde2cad.vectorize(mask, 1.0, dpi=254).report()
    assert rep["loops"] == 2 and rep["shapes"] == 1
    assert rep["curves"] == sum(lp["curves"] for lp in rep["loop_details"])
    assert rep["max_error_px"] <= 1.0
    assert abs(rep["mm_per_px"] - 0.1) < 1e-12
    for lp in rep["loop_details"]:
        assert len(lp["parameterizations"]) == lp["curves"]
        assert set(lp["parameterizations"]) <= {"chord", "centripetal", "uniform", "foley", "line"}


def _font_glyph(font: str, ch: str, size: int = 120) -> np.ndarray:
    """A glyph rendered by PIL from a font matplotlib ships (not drawn for this project)."""
    from pathlib import Path

    matplotlib = pytest.importorskip("matplotlib")
    from PIL import Image, ImageDraw, ImageFont

    path = Path(matplotlib.__file__).parent / "mpl-data" / "fonts" / "ttf" / font
    im = Image.new("L", (2 * size, 2 * size), 255)
    ImageDraw.Draw(im).text((size // 3, size // 6), ch, font=ImageFont.truetype(str(path), size), fill=0)
    return np.asarray(im) < 128


def _assert_exact_mirror(loop) -> None:
    """A reflection maps the outline onto itself read backwards (to 1e-6 px).

    For each cyclic shift of the reversed curve list, the best reflection (orthogonal
    Procrustes with determinant -1) is fitted; the best shift must match exactly.
    """
    c = loop.curves
    p = c.reshape(-1, 2)
    best = np.inf
    for r in range(len(c)):
        q = np.roll(c[::-1, ::-1], r, axis=0).reshape(-1, 2)
        pc, qc = p - p.mean(axis=0), q - q.mean(axis=0)
        u, _, vt = np.linalg.svd(qc.T @ pc)
        rot = u @ np.diag([1.0, -1.0]) @ vt if np.linalg.det(u @ vt) > 0 else u @ vt
        best = min(best, float(np.abs(pc @ rot.T - qc).max()))
    assert best < 1e-6


@pytest.mark.parametrize("font,ch", [("DejaVuSans.ttf", "T"), ("DejaVuSerif.ttf", "T"), ("DejaVuSans.ttf", "O")])
def test_unseen_glyphs_found_mirror_symmetric(font: str, ch: str) -> None:
    # Regression (issue 11): unseen glyphs came out with "0 symmetric loops". The
    # mirror halves of a straight edge crossing the axis merge back into one line.
    mask = _font_glyph(font, ch)
    with_sym = pde2cad.vectorize(mask, 1.0)
    without = pde2cad.vectorize(mask, 1.0, symmetry=False)
    outer = with_sym.loops[0]
    assert outer.symmetry == "mirror"
    assert with_sym.n_fitted_curves < without.n_curves
    assert with_sym.n_curves <= without.n_curves + 1
    _assert_exact_mirror(outer)
    err = _errors(mask, with_sym)
    assert err["max_boundary_to_curve"] <= 1.0
    assert err["max_curve_to_boundary"] <= 1.05


def test_tilted_off_grid_heart_found_mirror_symmetric() -> None:
    # A heart at 63 degrees about an off-grid centre: no pixel-grid mirror exists, the
    # two halves are different staircases.
    y, x = np.mgrid[0:220, 0:220] + 0.5
    c, s = np.cos(1.1), np.sin(1.1)
    dx, dy = x - 99.6, y - 111.2
    u, v = (dx * c + dy * s) / 60.0, -(-dx * s + dy * c) / 60.0
    mask = (u * u + v * v - 1.0) ** 3 - u * u * v**3 <= 0.0
    with_sym = pde2cad.vectorize(mask, 1.0)
    without = pde2cad.vectorize(mask, 1.0, symmetry=False)
    assert with_sym.loops[0].symmetry == "mirror"
    assert with_sym.n_fitted_curves < without.n_curves
    _assert_exact_mirror(with_sym.loops[0])
    err = _errors(mask, with_sym)
    assert err["max_boundary_to_curve"] <= 1.0
    assert err["max_curve_to_boundary"] <= 1.05



def test_symmetric_part_fit_stops_at_its_budget():
    # Regression (issue 11): a part with one piece more than its budget is always
    # rejected, so the part fit gives up there instead of fitting that piece.
    from pde2cad.image.vectorize import _fit_run

    x = np.linspace(0.0, 60.0, 241)
    run = np.stack([x, 6.0 * np.sin(x / 4.0)], axis=1)  # ~2.4 periods of a wave
    args = (run, np.arange(0), 0.5, run[0], run[-1], None, None, True, "optimal")
    free, over = _fit_run(*args)
    assert free is not None and not over
    k = len(free.curves)
    assert k >= 3
    at_budget, over = _fit_run(*args, 1, k)
    assert at_budget is not None and not over and len(at_budget.curves) <= k
    short, over = _fit_run(*args, 1, k - 1)
    assert short is None and over
