"""Principal curvatures from local quadric fits, on shapes with known curvature."""

from __future__ import annotations

import numpy as np
import pytest

from pde2cad.layout.curvature import curvature_radius_of_points, principal_curvatures


def _sphere(n: int, radius: float, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return radius * p / np.linalg.norm(p, axis=1, keepdims=True)


def _cylinder(n: int, radius: float, length: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 2 * np.pi, n)
    return np.column_stack([radius * np.cos(t), radius * np.sin(t), rng.uniform(0, length, n)])


@pytest.mark.parametrize("radius", [0.01, 1.0, 250.0])
def test_sphere_curvature_is_one_over_the_radius_at_any_scale(radius: float) -> None:
    k = principal_curvatures(_sphere(50_000, radius))
    assert np.allclose(np.abs(k), 1.0 / radius, rtol=0.05)


def test_cylinder_has_one_curved_and_one_straight_direction() -> None:
    k = np.abs(principal_curvatures(_cylinder(60_000, 0.5, 3.0)))
    assert np.median(k[:, 0]) == pytest.approx(2.0, rel=0.03)
    assert np.median(k[:, 1]) < 0.05


def test_radius_ignores_density_and_survives_noise() -> None:
    """The same sphere at 20k and 400k points, and with 0.2 % of D noise: the robust
    radius stays within 25 % of the true 1 (the Poisson-mesh edge estimate read 0.25
    clean and 0.04 noisy)."""
    radii = [curvature_radius_of_points(_sphere(n, 1.0, seed=n)) for n in (20_000, 400_000)]
    assert radii == pytest.approx([1.0, 1.0], rel=0.05)
    noisy = _sphere(100_000, 1.0) + np.random.default_rng(3).normal(
        scale=0.002 * 2 * np.sqrt(3) / np.sqrt(3), size=(100_000, 3))
    assert 0.75 < curvature_radius_of_points(noisy) <= 1.05


def test_crease_neighbourhoods_do_not_size_a_box() -> None:
    """A box's faces are flat: the fits that straddle its edges are left out, so its
    radius is far above its size (no patches spent on creases)."""
    rng = np.random.default_rng(4)
    face = rng.integers(0, 6, 60_000)
    p = rng.uniform(-1, 1, (60_000, 3)) * [1.0, 0.7, 0.5]
    axis, sign = face % 3, np.where(face < 3, -1.0, 1.0)
    p[np.arange(len(p)), axis] = sign * np.array([1.0, 0.7, 0.5])[axis]
    assert curvature_radius_of_points(p) > 5.0
