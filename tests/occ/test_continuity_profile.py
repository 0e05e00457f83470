"""``measure(..., profile=True)``: the per-sample angle (and gap) profile of every shared edge."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.typing import NDArray

pytest.importorskip("OCP")

from pde2cad.occ import make_face, measure, read_step, sew, write_step  # noqa: E402

pytestmark = pytest.mark.occ


def _bezier(poles: NDArray[np.float64]) -> SimpleNamespace:
    nu, nv = poles.shape[:2]
    return SimpleNamespace(poles=poles, knots_u=np.r_[np.zeros(nu), np.ones(nu)],
                           knots_v=np.r_[np.zeros(nv), np.ones(nv)], degree_u=nu - 1,
                           degree_v=nv - 1)  # fmt: skip


def _quad(p00, p10, p01, p11) -> SimpleNamespace:  # noqa: ANN001 - test helper
    return _bezier(np.array([[p00, p01], [p10, p11]], dtype=float))


def _paraboloid_halves(tilt: float = 0.0) -> list:
    """z = x^2 + 0.3 y^2 over [0, 1]^2 split at x = 0.5 (exactly C1); ``tilt`` rotates the
    second half's interior about the shared line x = 0.5 (a kink growing along it)."""
    lin = np.arange(4) / 3.0
    sq = np.array([0.0, 0.0, 1.0 / 3.0, 1.0])
    x, y = np.meshgrid(lin, lin, indexing="ij")
    poles = np.stack([x, y, sq[:, None] + 0.3 * sq[None, :]], axis=-1)
    rows, left, right = [poles], [poles[0]], [poles[-1]]
    while len(rows[-1]) > 1:
        nxt = 0.5 * (rows[-1][:-1] + rows[-1][1:])
        rows.append(nxt)
        left.append(nxt[0])
        right.append(nxt[-1])
    a, b = np.array(left), np.array(right[::-1])
    # Tilt proportional to y: no kink at y = 0, the largest at y = 1.
    b[1:, :, 2] += tilt * (b[1:, :, 0] - 0.5) * b[1:, :, 1]
    return [make_face(_bezier(a)), make_face(_bezier(b))]


def test_profile_is_off_by_default() -> None:
    shape, _ = sew(_paraboloid_halves(), 1e-6)
    m = measure(shape)
    assert m["shared_edges"] == 1 and "profile" not in m["edges"][0]


def test_profile_of_a_c1_pair_lies_on_the_seam(tmp_path: Path) -> None:
    shape, _ = sew(_paraboloid_halves(), 1e-6)
    m = measure(read_step(write_step(shape, tmp_path / "pair.step")), samples=15, profile=True)
    (edge,) = m["edges"]
    prof = edge["profile"]
    points, angles, gaps = prof["points"], prof["angles_deg"], prof["gaps"]
    assert points.shape == (15, 3) and angles.shape == (15,) and gaps.shape == (15,)
    # The seam is x = 0.5, z = 0.25 + 0.3 y^2, y from 0 to 1 (either direction).
    assert np.allclose(points[:, 0], 0.5, atol=1e-9)
    assert np.allclose(points[:, 2], 0.25 + 0.3 * points[:, 1] ** 2, atol=1e-9)
    assert sorted([points[0, 1], points[-1, 1]]) == pytest.approx([0.0, 1.0], abs=1e-9)
    assert np.all(angles < 1e-6) and np.all(gaps < 1e-7)
    assert edge["max_angle_deg"] == pytest.approx(angles.max())
    assert edge["max_gap"] == pytest.approx(gaps.max())


def test_profile_follows_a_growing_kink() -> None:
    shape, _ = sew(_paraboloid_halves(tilt=0.5), 1e-6)
    plain = measure(shape, samples=21)
    m = measure(shape, samples=21, profile=True)
    (edge,) = m["edges"]
    # The summary numbers do not depend on asking for the profile.
    assert edge["max_angle_deg"] == plain["edges"][0]["max_angle_deg"]
    assert edge["max_gap"] == plain["edges"][0]["max_gap"]
    points, angles = edge["profile"]["points"], edge["profile"]["angles_deg"]
    order = np.argsort(points[:, 1])
    y, a = points[order, 1], angles[order]
    assert a[0] < 1e-6  # the tilt vanishes at y = 0 ...
    assert np.all(np.diff(a) > 0)  # ... and grows along the seam
    assert a[-1] == pytest.approx(edge["max_angle_deg"]) and a[-1] > 5.0
    assert y == pytest.approx(np.linspace(0.0, 1.0, 21), abs=1e-9)  # uniform on a linear seam


def test_profile_of_a_crease_is_flat() -> None:
    flat = _quad([0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0])
    slope = _quad([1, 0, 0], [2, 0, 1], [1, 1, 0], [2, 1, 1])
    shape, _ = sew([make_face(flat), make_face(slope)], 1e-6)
    (edge,) = measure(shape, samples=9, profile=True)["edges"]
    assert edge["profile"]["angles_deg"] == pytest.approx(np.full(9, 45.0), abs=1e-9)
    assert np.allclose(edge["profile"]["points"][:, [0, 2]], [1.0, 0.0], atol=1e-12)


def test_undefined_normals_are_nan_and_ignored_by_the_maximum() -> None:
    # Two triangles-as-quads sharing the side up to a collapsed apex: the normal of a
    # collapsed side may be undefined at the apex; such a sample is NaN, never a fake 0 or 180.
    apex = [0.0, 0.0, 1.0]
    left = _quad([0, 0, 0], [1, 0, 0], apex, apex)
    right = _quad([1, 0, 0], [1, 1, 0], apex, apex)
    shape, _ = sew([make_face(left), make_face(right)], 1e-6)
    (edge,) = measure(shape, samples=11, profile=True)["edges"]
    angles = edge["profile"]["angles_deg"]
    defined = angles[~np.isnan(angles)]
    assert len(defined) >= 9
    assert defined == pytest.approx(np.full(len(defined), 90.0), abs=1e-9)
    assert edge["max_angle_deg"] == pytest.approx(90.0, abs=1e-9)
