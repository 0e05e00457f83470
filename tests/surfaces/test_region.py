"""Tests of region boundary extraction (thesis Sections 5.2.1-5.2.2, Fig. 5.2)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.surfaces import region
from pde2cad.surfaces.coons import BilinearCoons, three_sided
from pde2cad.surfaces.region import (
    RegionBoundary,
    boundary_loop,
    corner_curvature,
    detect_region_corners,
    extract_boundary,
)

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


def _height(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.2 * np.sin(xy[:, 0]) * np.cos(xy[:, 1])


def _lift(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.c_[xy, _height(xy)]


def _square_cloud(seed: int = 7, n: int = 5000) -> NDArray[np.float64]:
    """Unordered samples of a curved 4-sided patch over [0, 2]^2 (no boundary sampling)."""
    return _lift(np.random.default_rng(seed).random((n, 2)) * 2.0)


def _side_samples(rb: RegionBoundary) -> NDArray[np.float64]:
    return np.vstack([s.evaluate(np.linspace(0.0, 1.0, 4001)) for s in rb.sides])


def _edge_distance(rb: RegionBoundary, a, b, t: NDArray[np.float64]) -> float:
    """Largest distance from samples of the true edge a -> b (at ``t``) to the sides."""
    xy = a + (b - a) * t[:, None]
    return float(cKDTree(_side_samples(rb)).query(_lift(xy))[0].max())


@pytest.fixture(scope="module")
def square() -> tuple[NDArray[np.float64], RegionBoundary]:
    points = _square_cloud()
    return points, extract_boundary(points)


# --------------------------------------------------------------------------- the 4-sided patch
def test_square_corners_from_unordered_cloud(square) -> None:
    points, rb = square
    diag = np.sqrt(8.0)
    assert len(rb.corners) == 4 and len(rb.sides) == 4
    dist, which = cKDTree(rb.corner_points).query(_lift(SQUARE))
    assert sorted(which.tolist()) == [0, 1, 2, 3]
    assert dist.max() < 0.02 * diag


def test_square_sides_follow_true_edges(square) -> None:
    _, rb = square
    diag = np.sqrt(8.0)
    for a, b in zip(SQUARE, np.roll(SQUARE, -1, axis=0)):
        # Away from the corners the side is within 1 % of the diagonal of the true edge (the
        # outermost samples lie ~half a spacing inside it); the ends follow the corners (2 %).
        assert _edge_distance(rb, a, b, np.linspace(0.1, 0.9, 200)) < 0.01 * diag
        assert _edge_distance(rb, a, b, np.linspace(0.0, 1.0, 200)) < 0.02 * diag
    assert np.all(rb.side_errors <= rb.tolerance * (1 + 1e-9))


def test_square_result_contract(square) -> None:
    points, rb = square
    origin, axes = rb.frame
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.cross(axes[0], axes[1]), axes[2], atol=1e-12)
    np.testing.assert_array_equal(rb.loop, points[rb.loop_index])
    assert rb.corners[0] == 0 and np.all(np.diff(rb.corners) > 0)
    # Counter-clockwise in the projection.
    uv = (rb.loop - origin) @ axes[:2].T
    area = 0.5 * np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1])
    assert area > 0
    # Corner 0 is the one with the smallest u + v.
    corner_uv = (rb.corner_points - origin) @ axes[:2].T
    assert corner_uv.sum(axis=1).argmin() == 0
    # Head-to-tail with bit-identical shared corners.
    for k in range(4):
        np.testing.assert_array_equal(rb.sides[k].end, rb.sides[(k + 1) % 4].start)


def test_square_sides_build_bilinear_coons(square) -> None:
    _, rb = square
    origin, axes = rb.frame
    patch = BilinearCoons.from_loop(*rb.sides)
    np.testing.assert_array_equal(patch.evaluate(0.0, 0.0), rb.sides[0].start)
    su, sv = patch.derivatives(0.5, 0.5)
    assert np.cross(su, sv) @ axes[2] > 0  # the patch normal is the frame normal
    # The patch spans the region and lies near the true surface (a bilinear Coons patch of
    # the four sides does not reproduce the interior bump exactly: that is the deformation's job).
    u, v = np.meshgrid(np.linspace(0, 1, 21), np.linspace(0, 1, 21))
    grid = patch.evaluate(u, v).reshape(-1, 3)
    np.testing.assert_allclose(grid[:, :2].min(axis=0), [0.0, 0.0], atol=0.05)
    np.testing.assert_allclose(grid[:, :2].max(axis=0), [2.0, 2.0], atol=0.05)
    assert np.abs(grid[:, 2] - _height(grid[:, :2])).max() < 0.1


def test_grid_samples_are_fitted_exactly() -> None:
    g = np.linspace(0.0, 2.0, 41)
    xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    rb = extract_boundary(_lift(xy))
    dist = cKDTree(rb.corner_points).query(_lift(SQUARE))[0]
    assert dist.max() < 1e-9  # a sample sits at each tip: kept as is
    assert np.all(rb.side_errors <= rb.tolerance * (1 + 1e-9))
    assert rb.tolerance < 1e-3
    for a, b in zip(SQUARE, np.roll(SQUARE, -1, axis=0)):
        assert _edge_distance(rb, a, b, np.linspace(0.0, 1.0, 200)) < 1e-3


def test_noisy_cloud_still_gives_four_corners() -> None:
    # Thesis Sec. 5.4.5 noise levels: 0.5 % of the bounding-box diagonal on every coordinate.
    rng = np.random.default_rng(3)
    points = _lift(rng.random((10_000, 2)) * 2.0)
    diag = np.sqrt(8.0)
    points += rng.normal(scale=0.005 * diag, size=points.shape)
    rb = extract_boundary(points)
    assert len(rb.corners) == 4
    assert cKDTree(rb.corner_points).query(_lift(SQUARE))[0].max() < 0.03 * diag


# --------------------------------------------------------------------------- other shapes
def _triangle_cloud(seed: int = 1) -> NDArray[np.float64]:
    xy = np.random.default_rng(seed).random((8000, 2))
    xy = xy[xy.sum(axis=1) <= 1.0] * 2.0
    return np.c_[xy, 0.1 * xy[:, 0] ** 2]


def test_triangular_region_gives_three_corners() -> None:
    points = _triangle_cloud()
    rb = extract_boundary(points)
    assert len(rb.corners) == 3
    tips = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.4], [0.0, 2.0, 0.0]])
    assert cKDTree(rb.corner_points).query(tips)[0].max() < 0.02 * np.sqrt(8.0)
    patch = three_sided(*rb.sides)
    np.testing.assert_allclose(patch.evaluate(0.3, 1.0), rb.sides[2].start, atol=1e-12)


def _disc_cloud(seed: int = 2) -> NDArray[np.float64]:
    xy = np.random.default_rng(seed).random((6000, 2)) * 2.0 - 1.0
    xy = xy[(xy**2).sum(axis=1) <= 1.0]
    return np.c_[xy, 0.1 * xy[:, 0] ** 2]


def test_disc_has_no_corners() -> None:
    with pytest.raises(InputError, match="corners"):
        extract_boundary(_disc_cloud())


def test_disc_with_given_corners() -> None:
    points = _disc_cloud()
    angles = np.radians([225.0, 315.0, 45.0, 135.0])
    given = np.c_[np.cos(angles), np.sin(angles), 0.1 * np.cos(angles) ** 2]
    rb = extract_boundary(points, corners=given)
    # Coordinates are used exactly; the first given corner is corner 0, and the order is
    # reversed after it if it runs clockwise in the projection frame.
    origin, axes = rb.frame
    uv = (given - origin) @ axes[:2].T
    ccw = np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1]) > 0
    expected = given if ccw else given[[0, 3, 2, 1]]
    np.testing.assert_array_equal(rb.corner_points, expected)
    BilinearCoons.from_loop(*rb.sides)


def _l_cloud(seed: int = 0) -> NDArray[np.float64]:
    xy = np.random.default_rng(seed).random((6000, 2)) * 2.0
    xy = xy[~((xy[:, 0] > 1.0) & (xy[:, 1] > 1.0))]
    return np.c_[xy, 0.05 * xy[:, 0]]


def test_l_shape_notch_is_followed() -> None:
    points = _l_cloud()
    # The alpha shape follows the notch: 5 convex corners and the concave one.
    with pytest.raises(InputError, match=r"6 corners \(1 concave\)"):
        extract_boundary(points)
    # count=4 keeps 4 of the 5 convex corners; the notch then lies inside a side.
    rb = extract_boundary(points, count=4)
    convex = np.array([[0, 0], [2, 0], [2, 1], [1, 2], [0, 2]], dtype=float)
    dist = cKDTree(convex).query(rb.corner_points[:, :2])[0]
    assert len(rb.corners) == 4 and dist.max() < 0.05
    notch = np.array([1.0, 1.0])
    assert np.linalg.norm(rb.loop[:, :2] - notch, axis=1).min() < 0.1


# --------------------------------------------------------------------------- given corners
def test_given_corner_indices_are_honoured_and_reordered() -> None:
    points = _square_cloud(seed=11, n=3000)
    tips = cKDTree(points).query(_lift(SQUARE))[1]  # sample nearest to each true corner
    rb = extract_boundary(points, corners=tips)
    # The first given corner is corner 0; the others follow counter-clockwise.
    np.testing.assert_array_equal(rb.corner_points[0], points[tips[0]])
    assert {tuple(p) for p in rb.corner_points} == {tuple(p) for p in points[tips]}
    reversed_order = extract_boundary(points, corners=tips[[0, 3, 2, 1]])
    np.testing.assert_array_equal(reversed_order.corner_points, rb.corner_points)
    np.testing.assert_array_equal(reversed_order.loop_index, rb.loop_index)


def test_given_corners_must_follow_the_loop() -> None:
    points = _square_cloud(seed=11, n=3000)
    tips = cKDTree(points).query(_lift(SQUARE))[1]
    with pytest.raises(InputError, match="not in order"):
        extract_boundary(points, corners=tips[[0, 2, 1, 3]])
    with pytest.raises(InputError, match="3 or 4"):
        extract_boundary(points, corners=tips[:2])
    with pytest.raises(InputError, match="count=3"):
        extract_boundary(points, corners=tips, count=3)


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("points", "match"),
    [
        (np.c_[np.linspace(0, 1, 50), np.linspace(0, 2, 50), np.linspace(0, 3, 50)], "collinear"),
        (np.random.default_rng(0).random((9, 3)), "at least 10"),
        (np.r_[np.random.default_rng(0).random((40, 3)), [[np.nan, 0.0, 0.0]]], "NaN"),
        (np.random.default_rng(0).random((40, 2)), r"shape \(N, 3\)"),
    ],
)
def test_bad_points_raise(points: NDArray[np.float64], match: str) -> None:
    with pytest.raises(InputError, match=match):
        extract_boundary(points)


def test_region_in_two_pieces_raises() -> None:
    rng = np.random.default_rng(5)
    xy = np.r_[rng.random((2000, 2)), rng.random((2000, 2)) + [3.0, 0.0]]
    with pytest.raises(InputError, match="2 pieces"):
        boundary_loop(xy)
    with pytest.raises(InputError, match="height field"):
        extract_boundary(np.c_[xy, np.zeros(len(xy))])


def test_tiny_alpha_raises() -> None:
    xy = np.random.default_rng(5).random((500, 2))
    with pytest.raises(InputError, match="alpha"):
        boundary_loop(xy, alpha=1e-6)


# --------------------------------------------------------------------------- building blocks
def test_boundary_loop_is_ccw_and_on_the_edge() -> None:
    xy = np.random.default_rng(4).random((4000, 2)) * 2.0
    loop = boundary_loop(xy)
    ring = xy[loop]
    area = 0.5 * np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])
    assert area > 0.97 * 4.0
    depth = np.minimum(ring, 2.0 - ring).min(axis=1)
    assert depth.max() < 0.1
    assert len(np.unique(loop)) == len(loop)


def test_band_path_matches_full_triangulation(monkeypatch: pytest.MonkeyPatch) -> None:
    xy = np.random.default_rng(6).random((30_000, 2)) * [3.0, 1.0]
    full = boundary_loop(xy)
    monkeypatch.setattr(region, "BAND_POINTS", 10_000)
    monkeypatch.setattr(region, "COARSE_POINTS", 5_000)
    band = boundary_loop(xy)
    start = int(np.flatnonzero(band == full[0])[0])
    np.testing.assert_array_equal(np.roll(band, -start), full)


def test_corner_curvature_is_inverse_radius_and_signed() -> None:
    t = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    circle = 3.0 * np.c_[np.cos(t), np.sin(t)]
    np.testing.assert_allclose(corner_curvature(circle, 5), 1.0 / 3.0, rtol=1e-12)
    np.testing.assert_allclose(corner_curvature(circle[::-1], 5), -1.0 / 3.0, rtol=1e-12)
    lifted = np.c_[circle, np.full(len(circle), 7.0)]
    np.testing.assert_allclose(corner_curvature(lifted, 5), 1.0 / 3.0, rtol=1e-12)
    # Square corner with arms of length h: k = 4 (h^2 / 2) / (h h h sqrt 2) = sqrt(2) / h.
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 1.0]])
    assert corner_curvature(corner, 1)[1] == pytest.approx(np.sqrt(2.0))


def test_detect_region_corners_on_a_clean_polygon() -> None:
    s = np.linspace(0.0, 1.0, 50, endpoint=False)[:, None]
    loop = np.vstack([a + (b - a) * s for a, b in zip(SQUARE, np.roll(SQUARE, -1, axis=0))])
    np.testing.assert_array_equal(detect_region_corners(loop), [0, 50, 100, 150])
    np.testing.assert_array_equal(detect_region_corners(loop[::-1]), [49, 99, 149, 199])
    with pytest.raises(InputError, match="count"):
        detect_region_corners(loop, count=5)
