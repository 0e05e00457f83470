"""The kernel-neutral stage :func:`pde2cad.fit_surfaces`: no CAD kernel, same geometry as the
OCP path, input checked at the door."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from pde2cad import samples
from pde2cad.errors import InputError
from pde2cad.reconstruct import fit_surfaces

HEAVY = ("OCP", "FreeCAD", "Part", "ezdxf", "open3d", "matplotlib", "cadquery", "build123d")


def test_fit_surfaces_loads_no_cad_kernel() -> None:
    """Import and run the whole kernel-neutral stage in a fresh process: no OCP (or other
    heavy module) may get loaded, and the surfaces must interpolate the shared corners."""
    code = (
        "import sys\n"
        "import numpy as np\n"
        "import pde2cad\n"
        "from pde2cad import samples\n"
        "cloud = samples.sheet(6000, seed=1)\n"
        "model = pde2cad.fit_surfaces(cloud.points, cloud.labels, continuity='c1')\n"
        "assert len(model.surfaces) == 4 and model.labels == [0, 1, 2, 3]\n"
        "assert model.sew_tolerance > 0\n"
        f"bad = [m for m in {HEAVY!r} if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def _corner_of(surface, u: float, v: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    return np.asarray(surface.evaluate(np.array([u]), np.array([v]))).reshape(3)


def test_surfaces_meet_at_the_network_corners() -> None:
    """Every surface's four parameter corners are network corners (to 1e-9 D): the model
    alone, without a kernel, already describes a closed-up net of patches."""
    cloud = samples.torus(20000)
    model = fit_surfaces(cloud.points, cloud.labels)
    assert len(model.surfaces) == 16 and len(model.corners) == 16
    assert set(model.edges) == set(model.edge_errors) and len(model.edges) == 32
    for label, s in model.surfaces.items():
        u0, u1 = float(s.knots_u[0]), float(s.knots_u[-1])
        v0, v1 = float(s.knots_v[0]), float(s.knots_v[-1])
        for u, v in ((u0, v0), (u1, v0), (u1, v1), (u0, v1)):
            d = np.linalg.norm(model.corners - _corner_of(s, u, v), axis=1).min()
            assert d <= 1e-9 * model.diagonal, label
    assert cloud.distance(model.corners).max() <= 2e-4 * cloud.diagonal


@pytest.mark.parametrize(
    "points, labels, message",
    [
        ("abc", [0], "array of numbers"),
        (None, [0], "array of numbers"),
        ([[0, 0, 0], [1, 1]], [0, 0], "points must be"),
        ([["a", "b", "c"]], [0], "array of numbers"),
        (np.zeros((4, 2)), np.zeros(4), "(N, 3)"),
        (np.zeros((0, 3)), np.zeros(0), "(N, 3)"),
        (np.array([[0, 0, np.nan], [1, 1, 1]]), [0, 0], "NaN/inf"),
        (np.zeros((3, 3)), None, "one integer per point, got None"),
        (np.zeros((3, 3)), "abc", "one integer per point"),
        (np.zeros((3, 3)), [[0], [1, 2], [3]], "labels"),
        (np.zeros((3, 3)), [0, 1], "have 2 values but the cloud has 3 points"),
        (np.zeros((3, 3)), [0.2, 0.7, 1.0], "must be integers"),
    ],
)
def test_wrong_types_are_input_errors(points: object, labels: object, message: str) -> None:
    with pytest.raises(InputError) as info:
        fit_surfaces(points, labels)  # type: ignore[arg-type]
    assert message in str(info.value)


def test_float_labels_that_are_whole_numbers_are_taken() -> None:
    cloud = samples.sheet(6000, seed=1)
    model = fit_surfaces(cloud.points, cloud.labels.astype(float) + 10.0)
    assert model.labels == [10, 11, 12, 13]


@pytest.mark.parametrize(
    "options, message",
    [
        ({"m": None, "n": None}, 'm must be a whole number >= 1 or "auto", got None'),
        ({"m": 2.5, "n": 2.5}, "got 2.5"),
        ({"m": 4, "n": True}, "n must be"),
        ({"continuity": None}, "continuity must be 'c0' or 'c1'"),
        ({"tolerance": "0.1"}, "tolerance must be a positive number, got '0.1'"),
        ({"cad_tolerance": float("nan")}, "cad_tolerance must be a positive number"),
    ],
)
def test_wrong_options_are_input_errors(options: dict[str, object], message: str) -> None:
    cloud = samples.sheet(2000, seed=1)
    with pytest.raises(InputError) as info:
        fit_surfaces(cloud.points, cloud.labels, **options)  # type: ignore[arg-type]
    assert message in str(info.value)


@pytest.mark.parametrize(
    "make, continuity",
    [(lambda: samples.teapot(20000, parts=("body", "bottom")), "c1"),
     (lambda: samples.sphere6(20000), "c1"), (lambda: samples.torus(20000), "c0")],
)
def test_patches_mapped_back_evaluate_like_the_fitted_ones(make: Any, continuity: str) -> None:
    """Each patch handed back (bilinear or bicubic base, 3- or 4-sided) is the fitted patch
    moved to the caller's frame: the same points at the same parameters, errors scaled."""
    cloud = make()
    shift = np.array([2e5, -1e5, 3e4])
    model = fit_surfaces(cloud.points * 50.0 + shift, cloud.labels, continuity=continuity)
    frame = model.frame
    assert frame is not None and frame.scale == pytest.approx(50.0 * cloud.diagonal)
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 1, 9)))
    for label, patch in model.patches.items():
        local = patch.local
        world = frame.point(local.evaluate(u, v))
        np.testing.assert_allclose(patch.evaluate(u, v), world, rtol=0, atol=1e-9 * frame.scale)
        surface = model.surfaces[label]
        on_surface = np.asarray(surface.evaluate(u, v))
        # The B-spline is within the CAD tolerance (1e-4 D) of the patch it came from.
        assert np.abs(on_surface - world).max() <= 2e-4 * frame.scale
        assert patch.fit_errors["max"] == pytest.approx(local.fit_errors["max"] * frame.scale)
        np.testing.assert_array_equal(patch.points, cloud.points[cloud.labels == label] * 50.0
                                      + shift)


def test_layout_is_handed_back_in_the_callers_units() -> None:
    cloud = samples.sheet(6000, seed=1)
    model = fit_surfaces(cloud.points * 1e3 + 5e5, cloud.labels)
    lay = model.layout
    assert lay.tree is None
    for border in lay.borders.values():  # border points lie on the moved sheet
        assert np.abs(cloud.distance((border - 5e5) / 1e3)).max() <= 2e-2 * cloud.diagonal
    assert np.abs(cloud.distance((lay.corners - 5e5) / 1e3)).max() <= 2e-2 * cloud.diagonal
    # Point spacing of 6000 points over a 2 x 2 sheet (x 1e3): about 2000 / sqrt(6000).
    assert 0.2 * 2e3 / np.sqrt(6000) < lay.spacing < 5 * 2e3 / np.sqrt(6000)
    assert lay.radius > lay.spacing


def test_an_unreachable_tolerance_says_which_units_its_figures_are_in() -> None:
    from pde2cad.errors import FitError

    cloud = samples.sheet(4000, noise=0.01)
    with pytest.raises(FitError) as info:
        fit_surfaces(cloud.points * 10.0, cloud.labels, tolerance=1e-4)
    text = str(info.value)
    diagonal = 10.0 * float(np.linalg.norm(np.ptp(cloud.points, axis=0)))
    assert "not reached" in text and f"diagonal, {diagonal:.6g} in its units" in text
    # 1e-4 model units is 1e-4 / diagonal of the working frame's unit diagonal
    assert f"tolerance {1e-4 / diagonal:.3g}" in text
