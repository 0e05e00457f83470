"""Open rims on the true rim (issue 13.3): the rim estimator and single-patch fits.

Shapes (none of them the project's samples):

* a flat half-plane sheet, rim at y = 0, spacing 1, clean and with noise of 0.3 and 0.7
  spacings on every coordinate: the rim estimate must be unbiased;
* a 100 x 60 flag ``z = 4 sin(2 pi x / 140 + 0.5) cos(2 pi y / 180) + 0.02 x``, 10k and 50k
  uniformly random points, clean or with 0.2 % of the diagonal of noise, also rotated, scaled
  and shifted: the mean distance from the TRUE surface over the whole rectangle, rim
  included, and the distance of the fitted sides to the true rim lines;
* a tilted flat rectangle: straight rims must come out as straight lines.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.patch import Patch, fit_patch
from pde2cad.surfaces.projection import project_points
from pde2cad.surfaces.region import extract_boundary
from pde2cad.surfaces.rim import fit_rim_spline, locate_rim, sample_spacing

WIDTH, HEIGHT = 100.0, 60.0


def _flag(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    z = 4.0 * np.sin(2 * np.pi * x / 140 + 0.5) * np.cos(2 * np.pi * y / 180) + 0.02 * x
    return np.stack([x, y, z], axis=-1)


def _flag_cloud(count: int, noise: float = 0.0, seed: int = 0) -> tuple[NDArray[np.float64], float]:
    rng = np.random.default_rng(seed)
    points = _flag(rng.random(count) * WIDTH, rng.random(count) * HEIGHT)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    return points + noise * diagonal * rng.standard_normal(points.shape), diagonal


def _rim_distance(curves: tuple[PiecewiseBezier, ...]) -> NDArray[np.float64]:
    """In-plane distance of samples of the sides to the nearest true rim line."""
    q = np.vstack([c.evaluate(np.linspace(0.0, 1.0, 400)) for c in curves])
    return np.minimum.reduce(
        [np.abs(q[:, 0]), np.abs(q[:, 0] - WIDTH), np.abs(q[:, 1]), np.abs(q[:, 1] - HEIGHT)]
    )


def _truth_to_patch(patch: Patch, frame: tuple[NDArray[np.float64], float] | None = None) -> float:
    """Mean distance from a 201 x 201 grid of the TRUE flag over the whole rectangle to the
    patch (closest point within its parameter square), in the flag's units. ``frame``:
    (rotation, scale, shift) the patch was fitted in."""
    gx, gy = np.meshgrid(np.linspace(0, WIDTH, 201), np.linspace(0, HEIGHT, 201), indexing="ij")
    truth = _flag(gx.ravel(), gy.ravel())
    scale = 1.0
    if frame is not None:
        rotation, scale, shift = frame
        truth = truth @ rotation.T * scale + shift
    _, dist, _ = project_points(patch, truth)
    return float(dist.mean() / scale)


# --------------------------------------------------------------------------- the estimator
@pytest.mark.parametrize("noise", [0.0, 0.3, 0.7])
def test_rim_offset_is_unbiased_on_a_random_sheet(noise: float) -> None:
    rng = np.random.default_rng(11)
    count = 60_000
    points = np.c_[rng.random(count) * 600.0, rng.random(count) * 100.0 - 100.0, np.zeros(count)]
    points += noise * rng.standard_normal(points.shape)
    reference = np.array([[0.0, -0.6, 0.0], [200.0, -0.6, 0.0], [400.0, -0.6, 0.0], [600.0, -0.6, 0.0]])
    est = locate_rim(points, PiecewiseBezier.from_cubic(reference), sample_spacing(points))
    assert est is not None and len(est.points) > 80
    # Measured (spacings): mean +0.00 / -0.01 / -0.04, station std 0.08 / 0.16 / 0.28.
    assert abs(float(est.points[:, 1].mean())) < 0.08
    assert float(est.points[:, 1].std()) < 0.15 + 0.3 * noise
    if noise:
        assert float(np.median(est.noise)) == pytest.approx(noise, rel=0.15)
    # Heights from the windows' quadrics, extrapolated to the rim: the plane z = 0 to a
    # fraction of the noise (measured: mean 0.34 / 0.3 sigma, max 1.3 / 0.8 sigma).
    assert np.abs(est.points[:, 2]).mean() < 0.02 + 0.45 * noise
    assert np.abs(est.points[:, 2]).max() < 0.05 + 1.6 * noise


def test_rim_estimate_does_not_depend_on_scale_or_position() -> None:
    points, _ = _flag_cloud(20_000)
    rotation = np.linalg.qr(np.random.default_rng(5).standard_normal((3, 3)))[0]
    scale, shift = 1e-3, np.array([1e4, -3e3, 5e2])
    moved = points @ rotation.T * scale + shift
    a, b = extract_boundary(points, rims=True), extract_boundary(moved, rims=True)
    # The same loop of sides (corner 0 depends on the PCA frame's orientation, so compare
    # the sampled boundaries as point sets). Measured: mean 0.015 spacings, max 0.11 (where
    # the side fitter splits a side into pieces differently: a discrete choice).
    t = np.linspace(0.0, 1.0, 500)
    here = np.vstack([s.evaluate(t) for s in a.sides])
    back = ((np.vstack([s.evaluate(t) for s in b.sides]) - shift) / scale) @ rotation
    spacing = sample_spacing(points)
    for dist in (cKDTree(here).query(back)[0], cKDTree(back).query(here)[0]):
        assert dist.mean() < 0.05 * spacing and dist.max() < 0.25 * spacing


# --------------------------------------------------------------------------- the flag
@pytest.mark.parametrize("count", [10_000, 50_000])
def test_flag_patch_reaches_its_rim(count: int) -> None:
    points, diagonal = _flag_cloud(count)
    spacing = sample_spacing(points)
    patch = fit_patch(points, m="auto", n="auto", boundary=extract_boundary(points, rims=True))
    # Issue 13.3: <= 1e-4 D (2.1e-4 with sides on the boundary loop; measured here 1.6e-5 at
    # 10k, 8.6e-6 at 50k; 9.3e-5 and 4.8e-5 with the loop sides).
    assert _truth_to_patch(patch) <= 3e-5 * diagonal
    rim = _rim_distance(patch.sides)
    # Measured: mean 0.06 / 0.05 spacings, max 0.5 / 0.2 (loop sides: 0.4 / 0.5 mean).
    assert rim.mean() <= 0.15 * spacing and rim.max() <= 1.0 * spacing
    loop = extract_boundary(points, rims=False)
    assert _rim_distance(loop.sides).mean() > 3.0 * rim.mean()


@pytest.mark.parametrize("seed", [0, 1])
def test_noisy_flag_rim_is_on_the_true_rim(seed: int) -> None:
    points, diagonal = _flag_cloud(50_000, noise=0.002, seed=seed)
    rim_sides = extract_boundary(points, rims=True)
    loop_sides = extract_boundary(points, rims=False)
    rim = _rim_distance(rim_sides.sides)
    # Measured (seeds 0 / 1): mean 4.6e-4 / 2.0e-4 D (loop sides 5.5e-4 / 4.6e-4).
    assert rim.mean() <= 0.9 * _rim_distance(loop_sides.sides).mean()
    assert rim.mean() <= 6e-4 * diagonal and rim.max() <= 2.5e-3 * diagonal
    # Mean distance from the true surface: measured 1.06e-4 / 2.04e-4 D (loop sides 1.18e-4 /
    # 1.22e-4): the rim sides' corner heights are extrapolated from noisy quadrics, which on
    # seed 1 costs more than the rim gains (open in issue 13.3).
    fitted = _truth_to_patch(fit_patch(points, m="auto", n="auto", boundary=rim_sides))
    assert fitted <= 2.5e-4 * diagonal


def test_rotated_shifted_flag_fits_as_well() -> None:
    points, diagonal = _flag_cloud(20_000, seed=2)
    rotation = np.linalg.qr(np.random.default_rng(9).standard_normal((3, 3)))[0]
    scale, shift = 250.0, np.array([-4e5, 2e5, 7e4])
    moved_points = points @ rotation.T * scale + shift
    patch = fit_patch(moved_points, m="auto", n="auto",
                      boundary=extract_boundary(moved_points, rims=True))
    plain = fit_patch(points, m="auto", n="auto", boundary=extract_boundary(points, rims=True))
    moved = _truth_to_patch(patch, (rotation, scale, shift))
    assert moved <= 3e-5 * diagonal
    assert moved == pytest.approx(_truth_to_patch(plain), rel=0.05)


# --------------------------------------------------------------------------- straight, planar
def test_straight_rims_become_lines() -> None:
    rng = np.random.default_rng(4)
    xy = rng.random((20_000, 2)) * [80.0, 50.0]
    rotation = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    plate = np.c_[xy, np.zeros(len(xy))] @ rotation.T + [3.0, -7.0, 11.0]
    rb = extract_boundary(plate, rims=True)
    spacing = sample_spacing(plate)
    lines = 0
    for side in rb.sides:
        ctrl = side.ctrl.reshape(-1, 3)
        chord = (ctrl[-1] - ctrl[0]) / np.linalg.norm(ctrl[-1] - ctrl[0])
        rel = ctrl - ctrl[0]
        lines += side.n_curves == 1 and bool(
            np.linalg.norm(rel - np.outer(rel @ chord, chord), axis=1).max() < 1e-9 * 100.0
        )
    # Measured: 3 of the 4 sides are exact lines; the 4th has two stations 0.4 spacings off
    # (an unusually wide gap at the rim) and stays a chain within its tolerance.
    assert lines >= 3
    local = (np.vstack([s.evaluate(np.linspace(0, 1, 200)) for s in rb.sides]) - [3.0, -7.0, 11.0]) @ rotation
    edge = np.minimum.reduce([np.abs(local[:, 0]), np.abs(local[:, 0] - 80.0),
                              np.abs(local[:, 1]), np.abs(local[:, 1] - 50.0)])
    assert edge.mean() < 0.1 * spacing and edge.max() < 0.5 * spacing


# --------------------------------------------------------------------------- held-out waves
def _wave_cloud(count: int, warp: bool, seed: int = 3) -> NDArray[np.float64]:
    """A wave sheet over [0, 1]^2 (not a project sample), uniformly random or 10x denser at
    x = 0.01 than at x = 1 (x = u^2)."""
    uv = np.random.default_rng(seed).random((2, count))
    x = uv[0] ** 2 if warp else uv[0]
    return np.stack([x, uv[1], 0.15 * np.sin(4 * x) * np.cos(3 * uv[1])], axis=-1)


@pytest.mark.parametrize("warp", [False, True])
def test_rim_sides_beat_loop_sides_on_a_wave(warp: bool) -> None:
    """The rim sides were opt-in because on waves they made the fit 4x (uniform) and 20x
    (non-uniform) worse: G1 joints drew creases through the patch, and on the sparse side
    of the non-uniform cloud windows sized by the mean spacing held too few points. Mean
    distance from the TRUE wave over the whole square, M = N = 10."""
    points = _wave_cloud(50_000, warp)
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    g = np.linspace(0.0, 1.0, 151)
    gx, gy = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    truth = np.stack([gx, gy, 0.15 * np.sin(4 * gx) * np.cos(3 * gy)], axis=-1)
    errors = {}
    for rims in (False, True):
        patch = fit_patch(points, m=10, n=10, boundary=extract_boundary(points, rims=rims))
        errors[rims] = float(project_points(patch, truth)[1].mean()) / diagonal
    # Measured (uniform / non-uniform): rims 5.1e-5 / 5.9e-5 D, loop sides 1.2e-4 / 1.2e-4.
    assert errors[True] <= 0.7 * errors[False]
    assert errors[True] <= 8e-5


def test_rim_spline_is_c2_and_follows_the_rim() -> None:
    """Rim sides are C2 splines in one parameter (no speed jump at a joint), through the
    corners exactly, as close to smooth rim points as their shape needs."""
    t = np.linspace(0.0, 1.0, 60)
    run = np.stack([t, 0.1 * np.sin(5 * t), 0.2 * np.cos(3 * t)], axis=1)
    side, error = fit_rim_spline(run, run[0], run[-1])
    assert side.n_curves >= 2 and error < 1e-4
    np.testing.assert_array_equal(side.start, run[0])
    np.testing.assert_array_equal(side.end, run[-1])
    joints = side.breaks[1:-1]
    for order in (1, 2):
        left = side.derivative(joints - 1e-9, order)
        right = side.derivative(joints, order)
        np.testing.assert_allclose(left, right, rtol=0, atol=1e-5)
    # Noisy rim points (sigma 2e-3 on a straight-ish rim): few pieces, not the noise.
    noisy = run + 2e-3 * np.random.default_rng(1).standard_normal(run.shape)
    assert fit_rim_spline(noisy, noisy[0], noisy[-1])[0].n_curves <= 3
