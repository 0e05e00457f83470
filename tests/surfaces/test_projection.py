"""Tests of closest-point parameterization on a base patch (Section 5.2.3)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad.errors import InputError
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import BicubicCoons, BilinearCoons, three_sided
from pde2cad.surfaces.deformation import Deformation, DeformedPatch
from pde2cad.surfaces.projection import closest_points, project_points

RNG = np.random.default_rng(5223)


def _curved_patch(spacing: str = "uniform") -> BilinearCoons:
    """A saddle-like patch over about [0, 3]^2 with a 2-piece bottom side: C1 at the joint
    with uniform breaks, only C0 (a crease across the patch) with length breaks."""
    bottom = PiecewiseBezier.from_chain(
        np.array(
            [
                [[0, 0, 0], [0.6, -0.3, 0.6], [1.1, 0.1, 0.7], [1.5, 0.0, 0.4]],
                [[1.5, 0.0, 0.4], [1.9, -0.1, 0.1], [2.5, 0.2, -0.4], [3, 0, 0]],
            ],
            dtype=float,
        ),
        spacing=spacing,  # type: ignore[arg-type]
    )
    top = np.array([[0, 3, 0.4], [1, 3.3, 1.0], [2, 2.8, 0.2], [3, 3, 0.3]])
    left = np.array([[0, 0, 0], [-0.3, 1, 0.8], [0.2, 2, -0.5], [0, 3, 0.4]])
    right = np.array([[3, 0, 0], [3.2, 1, -0.6], [2.9, 2, 0.9], [3, 3, 0.3]])
    return BilinearCoons(bottom, right, top, left)


def _offset_samples(
    patch: object, n: int, offset: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Interior (u, v), points pushed along the unit normal by up to ``offset``, offsets."""
    uv = RNG.uniform(0.005, 0.995, (n, 2))
    s, su, sv = patch.jet(uv[:, 0], uv[:, 1])[:3]  # type: ignore[attr-defined]
    normal = np.cross(su, sv)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    h = RNG.uniform(-offset, offset, n)
    return uv, s + h[:, None] * normal, h


def test_recovers_known_parameters_on_a_curved_patch() -> None:
    patch = _curved_patch()
    uv, points, h = _offset_samples(patch, 20000, 0.02)
    params, dist, outside = project_points(patch, points)
    np.testing.assert_allclose(params, uv, rtol=0, atol=1e-8)
    np.testing.assert_allclose(dist, np.abs(h), rtol=0, atol=1e-10)
    assert not outside.any()


@pytest.mark.parametrize("offset", [0.0, 0.05])
def test_closest_points_are_the_surface_at_the_parameters(offset: float) -> None:
    """The closest points come from the last Newton iterate (the last step taken to first
    order, without an evaluation): they must still be S(u, v) to 1e-13 of the patch size
    (|S_uu| step^2 / 2 for steps below 1e-7), on and off the surface, with the same
    parameters as project_points."""
    patch = _curved_patch()
    _, points, _ = _offset_samples(patch, 20000, offset)
    points = np.vstack([points, points[:500] + [0.0, 0.0, 0.4], RNG.uniform(-1, 4, (500, 3))])
    params, dist, outside, closest = closest_points(patch, points)
    tiny = 1e-13 * float(np.linalg.norm(np.ptp(patch.evaluate(RNG.random(999), RNG.random(999)), axis=0)))
    np.testing.assert_allclose(closest, patch.evaluate(params[:, 0], params[:, 1]), rtol=0, atol=tiny)
    np.testing.assert_allclose(dist, np.linalg.norm(points - closest, axis=1), rtol=0, atol=tiny)
    plain = project_points(patch, points)
    for a, b in zip(plain, (params, dist, outside), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_crease_gives_a_local_closest_point() -> None:
    # Where a chain is only C0 the patch has a crease; on its concave side a point can have
    # two local closest points, one per facet. Either is returned, never a worse point.
    patch = _curved_patch("length")
    crease = patch.bottom.breaks[1]
    uv, points, h = _offset_samples(patch, 20000, 0.02)
    params, dist, _ = project_points(patch, points)
    assert np.all(dist <= np.abs(h) + 1e-9)
    near = np.abs(uv[:, 0] - crease) < 1e-4
    np.testing.assert_allclose(params[~near], uv[~near], rtol=0, atol=1e-8)


def test_recovers_parameters_on_a_bicubic_and_a_deformed_patch() -> None:
    base = _curved_patch()
    ribbons = RNG.normal(scale=0.5, size=(4, 4, 3)) + [0.0, 3.0, 0.0]
    bicubic = BicubicCoons(base.bottom, base.right, base.top, base.left, *ribbons)
    deformed = DeformedPatch(base, Deformation(RNG.normal(scale=0.03, size=(4, 4, 3)), "c1"))
    for patch in (bicubic, deformed):
        uv, points, h = _offset_samples(patch, 5000, 0.01)
        params, dist, outside = project_points(patch, points)
        np.testing.assert_allclose(params, uv, rtol=0, atol=1e-8)
        np.testing.assert_allclose(dist, np.abs(h), rtol=0, atol=1e-10)
        assert not outside.any()


def test_flags_points_beyond_the_sides() -> None:
    patch = _curved_patch()
    # The sides extrapolate smoothly, so S(1.1, v) lies beyond the right side.
    beyond = np.array([[1.1, 0.5], [0.4, -0.08], [-0.05, 1.05], [0.3, 1.2]])
    inside = np.array([[0.9999, 0.5], [0.5, 0.0], [0.0, 0.3], [0.2, 0.7]])
    uv = np.vstack([beyond, inside])
    points = patch.evaluate(uv[:, 0], uv[:, 1])
    params, dist, outside = project_points(patch, points)
    np.testing.assert_array_equal(outside, [True] * 4 + [False] * 4)
    np.testing.assert_allclose(params[4:], inside, atol=1e-10)
    assert params[0, 0] == 1.0 and params[1, 1] == 0.0 and tuple(params[2]) == (0.0, 1.0)
    assert np.all(dist[:4] > 0.05) and np.all(dist[4:] < 1e-12)


def test_three_sided_patch_near_its_apex() -> None:
    a, b, apex = np.array([0.0, 0, 0]), np.array([2.0, 0, 0]), np.array([1.0, 2.0, 0.5])
    patch = three_sided(
        np.array([a, [0.7, -0.3, 0.2], [1.4, 0.2, -0.2], b]),
        np.array([b, [2.2, 0.8, 0.0], [1.6, 1.6, 0.6], apex]),
        np.array([apex, [0.5, 1.5, 0.7], [-0.2, 0.8, 0.0], a]),
    )
    uv = np.column_stack([RNG.random(3000), RNG.uniform(0.95, 0.999, 3000)])
    points = patch.evaluate(uv[:, 0], uv[:, 1])
    params, dist, outside = project_points(patch, points)
    assert dist.max() < 1e-10 and not outside.any()
    np.testing.assert_allclose(params, uv, atol=1e-6)  # u is ill-conditioned near the apex


def test_surface_without_jet_uses_the_three_methods() -> None:
    class Plain:
        """Only evaluate / derivatives / second_derivatives, the documented minimum."""

        def __init__(self, patch: BilinearCoons) -> None:
            self.evaluate, self.derivatives = patch.evaluate, patch.derivatives
            self.second_derivatives = patch.second_derivatives

    patch = _curved_patch()
    uv, points, _ = _offset_samples(patch, 500, 0.01)
    params, _, _ = project_points(Plain(patch), points, workers=1)
    np.testing.assert_allclose(params, uv, atol=1e-8)


def test_rejects_bad_input() -> None:
    patch = _curved_patch()
    points = RNG.random((10, 3))
    points[4, 1] = np.nan
    with pytest.raises(InputError, match=r"NaN or inf.*row 4"):
        project_points(patch, points)
    with pytest.raises(InputError, match="dimension 2"):
        project_points(patch, RNG.random((10, 2)))
    with pytest.raises(InputError, match=r"shape \(N, D\)"):
        project_points(patch, RNG.random(10))
    with pytest.raises(InputError, match="lacks second_derivatives"):
        project_points(
            object.__new__(type("Half", (), {"evaluate": 0, "derivatives": 0})), RNG.random((3, 3))
        )


def test_empty_input() -> None:
    params, dist, outside = project_points(_curved_patch(), np.empty((0, 3)))
    assert params.shape == (0, 2) and dist.shape == (0,) and outside.shape == (0,)


@pytest.mark.slow
def test_a_million_points() -> None:
    patch = _curved_patch()
    uv, points, h = _offset_samples(patch, 1_000_000, 0.02)
    params, dist, outside = project_points(patch, points)
    np.testing.assert_allclose(params, uv, rtol=0, atol=1e-8)
    np.testing.assert_allclose(dist, np.abs(h), rtol=0, atol=1e-10)
    assert not outside.any()


def test_result_does_not_depend_on_chunks_or_threads() -> None:
    """Chunks are balanced over the threads; every point's answer is its own."""
    patch = _curved_patch("length")
    _, points, _ = _offset_samples(patch, 20000, 0.3)
    single = project_points(patch, points, workers=1, chunk=10**6)
    for workers, chunk in ((2, 50_000), (2, 777), (3, 4096)):
        split = project_points(patch, points, workers=workers, chunk=chunk)
        for a, b in zip(single, split, strict=True):
            np.testing.assert_array_equal(a, b)
