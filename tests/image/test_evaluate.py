"""Tests of the independent error measure and the potrace runner (pde2cad.image.evaluate)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from pde2cad.image.evaluate import (
    boundary_edges,
    boundary_samples,
    outline_error,
    parse_svg_paths,
    run_potrace,
)

needs_potrace = pytest.mark.skipif(shutil.which("potrace") is None, reason="potrace not installed")


def rect_mask(
    h: int = 30, w: int = 40, rows: tuple[int, int] = (5, 25), cols: tuple[int, int] = (8, 30)
) -> np.ndarray:
    m = np.zeros((h, w), dtype=bool)
    m[rows[0] : rows[1], cols[0] : cols[1]] = True
    return m


def line_cubic(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.array([p, (2 * p + q) / 3, (p + 2 * q) / 3, q])


def rect_curves(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    pts = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)
    return np.array([line_cubic(pts[i], pts[(i + 1) % 4]) for i in range(4)])


def disc_mask(n: int = 120, r: float = 40.0) -> np.ndarray:
    yy, xx = np.mgrid[0:n, 0:n] + 0.5
    return (xx - n / 2) ** 2 + (yy - n / 2) ** 2 < r * r


# ------------------------------------------------------------------ boundary samples


@pytest.mark.parametrize("step", [0.25, 0.1, 0.5])
def test_boundary_samples_rectangle(step: float) -> None:
    m = rect_mask()
    pts = boundary_samples(m, step=step)
    perimeter = 2 * (20 + 22)
    assert len(pts) == round(perimeter / step)
    x, y = pts[:, 0], pts[:, 1]
    on_vertical = np.isclose(x, 8) | np.isclose(x, 30)
    on_horizontal = np.isclose(y, 5) | np.isclose(y, 25)
    assert np.all((on_vertical & (y >= 5) & (y <= 25)) | (on_horizontal & (x >= 8) & (x <= 30)))
    # every pixel corner of the rectangle is sampled
    for corner in [(8, 5), (30, 5), (30, 25), (8, 25)]:
        assert np.any(np.all(np.isclose(pts, corner), axis=1))


def test_boundary_includes_image_border_and_holes() -> None:
    m = np.ones((4, 5), dtype=bool)  # touches the border everywhere
    m[1:3, 2] = False  # a 1x2 hole
    edges = boundary_edges(m)
    assert len(edges) == 2 * (4 + 5) + 2 * (1 + 2)
    assert len(boundary_samples(m, step=0.25)) == 4 * len(edges)
    assert len(boundary_samples(np.zeros((5, 5), bool))) == 0


def test_boundary_diagonal_touch() -> None:
    m = np.array([[1, 0], [0, 1]], dtype=bool)
    assert len(boundary_edges(m)) == 8
    # the shared corner (1, 1) appears once
    pts = boundary_samples(m, step=0.5)
    assert np.sum(np.all(pts == [1.0, 1.0], axis=1)) == 1


# ------------------------------------------------------------------ outline error


def test_outline_error_exact_rectangle() -> None:
    m = rect_mask()
    e = outline_error(m, [rect_curves(8, 5, 30, 25)])
    assert e["max_boundary_to_curve"] < 1e-9
    assert e["mean_boundary_to_curve"] < 1e-9
    assert e["max_curve_to_boundary"] < 1e-9


def test_outline_error_shifted_rectangle() -> None:
    m = rect_mask()
    e = outline_error(m, [rect_curves(8.5, 5, 30.5, 25)])  # shifted half a pixel in x
    assert e["max_boundary_to_curve"] == pytest.approx(0.5, abs=1e-6)
    assert e["max_curve_to_boundary"] == pytest.approx(0.5, abs=1e-6)
    # vertical sides are 0.5 away, horizontal sides 0 except for a 0.5 px stub at one end
    assert 0.2 < e["mean_boundary_to_curve"] < 0.3
    e = outline_error(m, [rect_curves(8.5, 5.5, 30.5, 25.5)])  # diagonal shift
    assert e["max_boundary_to_curve"] == pytest.approx(np.sqrt(0.5), abs=1e-6)
    assert e["mean_boundary_to_curve"] == pytest.approx(0.5, abs=0.02)


def test_outline_error_circle_is_accurate() -> None:
    """A circle of radius r through a smooth path: compare with the analytic distance."""
    m = disc_mask(120, 40.0)
    c, r = 60.0, 40.3
    k = 0.5522847498 * r  # 4-arc cubic circle, radial error < 3e-4 * r
    arcs = []
    for a in np.arange(4) * np.pi / 2:
        u = np.array([np.cos(a), np.sin(a)])
        v = np.array([np.cos(a + np.pi / 2), np.sin(a + np.pi / 2)])
        arcs.append([c + r * u, c + r * u + k * v, c + r * v + k * u, c + r * v])
    arcs = np.array(arcs)
    e = outline_error(m, arcs)
    pts = boundary_samples(m, step=0.05)
    exact = np.abs(np.linalg.norm(pts - c, axis=1) - r).max()
    assert e["max_boundary_to_curve"] == pytest.approx(exact, abs=0.012 + 1e-3)


def test_outline_error_empty_inputs() -> None:
    m = rect_mask()
    assert outline_error(m, [])["max_boundary_to_curve"] == float("inf")
    assert outline_error(np.zeros((5, 5), bool), [])["max_boundary_to_curve"] == 0.0


# ------------------------------------------------------------------ SVG parsing


def test_parse_relative_path() -> None:
    d = "M10 20 l10 0 c0 5 -5 10 -10 10 h-5 v-5 z m30 0 L 40 30 30 30 Z"
    curves, n = parse_svg_paths(d)
    assert len(curves) == 2
    a, b = curves
    np.testing.assert_allclose(a[0], line_cubic(np.array([10, 20.0]), np.array([20, 20.0])))
    np.testing.assert_allclose(a[1], [[20, 20], [20, 25], [15, 30], [10, 30]])
    np.testing.assert_allclose(a[2][[0, 3]], [[10, 30], [5, 30]])  # h-5
    np.testing.assert_allclose(a[3][[0, 3]], [[5, 30], [5, 25]])  # v-5
    np.testing.assert_allclose(a[4][[0, 3]], [[5, 25], [10, 20]])  # z closes with a line
    # after z the current point is the subpath start (10, 20); m30 0 -> (40, 20)
    np.testing.assert_allclose(b[0][[0, 3]], [[40, 20], [40, 30]])
    np.testing.assert_allclose(b[1][[0, 3]], [[40, 30], [30, 30]])
    np.testing.assert_allclose(b[2][[0, 3]], [[30, 30], [40, 20]])
    # l, c, h, v, closing z line + L, implicit L, closing Z line
    assert n == 5 + 3


def test_parse_potrace_like_svg_with_transform() -> None:
    svg = """<?xml version="1.0" standalone="no"?>
<svg version="1.0" xmlns="http://www.w3.org/2000/svg" width="6pt" height="5pt" viewBox="0 0 6 5">
<g transform="translate(0.000000,5.000000) scale(0.100000,-0.100000)" fill="#000000">
<path d="M10 30 c0 -5 7 -10 15 -10 8 0 15 5 15 10 0 6 -7 10 -15 10 -8 0 -15
-4 -15 -10z"/>
</g>
</svg>"""
    curves, n = parse_svg_paths(svg)
    assert n == 4  # four curvetos (implicit repetition), z closes exactly
    c = curves[0]
    assert c.shape == (4, 4, 2)
    np.testing.assert_allclose(c[0, 0], [1.0, 2.0])  # (10, 30) -> x 1, y 5 - 3
    np.testing.assert_allclose(c[0, 3], [2.5, 3.0])  # (25, 20) -> bottom of the ellipse
    np.testing.assert_allclose(c[-1, 3], c[0, 0])
    assert np.all((c[..., 1] >= 1.0) & (c[..., 1] <= 3.0))


# ------------------------------------------------------------------ potrace


@pytest.mark.potrace
@needs_potrace
def test_potrace_rectangle_lands_on_pixel_corners() -> None:
    m = rect_mask(30, 40, (5, 25), (8, 30))
    m[12:18, 15:20] = False
    res = run_potrace(m, repeats=1)
    pts = np.concatenate([c.reshape(-1, 2) for c in res["curves"]])
    # the outer rectangle is traced as lines through its exact corners
    for corner in [(8, 5), (30, 5), (30, 25), (8, 25)]:
        assert np.any(np.all(np.isclose(pts, corner), axis=1)), corner
    e = outline_error(m, res["curves"])
    assert e["max_boundary_to_curve"] <= 1.0
    assert res["segments"] > 0 and res["time_s"] > 0
    assert (res["width"], res["height"]) == (40, 30)


@pytest.mark.potrace
@needs_potrace
def test_potrace_disc_within_one_pixel() -> None:
    m = disc_mask(120, 40.0)
    res = run_potrace(m, repeats=1)
    e = outline_error(m, res["curves"])
    assert e["max_boundary_to_curve"] <= 1.0
    assert e["max_curve_to_boundary"] <= 1.0
    assert e["mean_boundary_to_curve"] < 0.35
    # the convention is the best alignment: half a pixel off in x or y is clearly worse
    for shift in ([0.5, 0.0], [0.0, 0.5], [-0.5, 0.0], [0.0, -0.5]):
        e2 = outline_error(m, [c + shift for c in res["curves"]])
        assert e2["max_boundary_to_curve"] > 1.0
        assert e2["mean_boundary_to_curve"] > e["mean_boundary_to_curve"] + 0.05
    ends = np.concatenate([c[:, 0] for c in res["curves"]])  # on-curve points
    np.testing.assert_allclose(ends.min(axis=0), [20.0, 20.0], atol=1.0)
    np.testing.assert_allclose(ends.max(axis=0), [100.0, 100.0], atol=1.0)
