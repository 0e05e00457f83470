"""Shared ribbons: C1 at regular corners, G1 along edges with odd-valence ends (cube-sphere)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad import samples
from pde2cad.layout import build_layout
from pde2cad.layout.edges import EdgeNetwork, build_edges, key_of
from pde2cad.layout.ribbons import shared_ribbons
from pde2cad.surfaces.coons import BicubicCoons, Ribbons
from pde2cad.surfaces.patch import Patch, fit_patch


def _setup(shape: str, n: int) -> tuple[samples.LabelledCloud, EdgeNetwork, dict[int, Patch]]:
    cloud = samples.SHAPES[shape](n)
    pts, lab = cloud.points, np.asarray(cloud.labels)
    network = build_edges(pts, lab, build_layout(pts, lab, check=False), cKDTree(pts))
    c0 = {
        label: fit_patch(
            pts[lab == label], continuity="c0", m=6, n=6, boundary=network.sides(label)
        )
        for label in sorted(network.loops)
    }
    return cloud, network, c0


@pytest.fixture(scope="module")
def sphere() -> tuple[samples.LabelledCloud, EdgeNetwork, dict[int, Patch], dict[int, Ribbons]]:
    cloud, network, c0 = _setup("sphere6", 20000)
    return cloud, network, c0, shared_ribbons(network, c0)


def _across(
    network: EdgeNetwork, ribbons: dict[int, Ribbons], label: int, key: tuple[int, int],
    t: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The patch's ribbon across edge ``key`` at the edge parameters ``t`` (Coons sign)."""
    ids = network.loops[label]
    k = [key_of(ids[j], ids[(j + 1) % 4]) for j in range(4)].index(key)
    s = t if ids[k] == key[0] else 1.0 - t
    rib = ribbons[label]
    curve = (rib.d_bottom, rib.d_right, rib.d_top, rib.d_left)[k]
    return curve.evaluate(s if k < 2 else 1.0 - s)


def _edge_angles(
    network: EdgeNetwork, ribbons: dict[int, Ribbons], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Angle (degrees) between the two tangent planes span(C', R) along every shared edge."""
    out = []
    for key, who in network.users.items():
        if len(who) != 2:
            continue
        tangent = network.curves[key].derivative(t)
        na = np.cross(tangent, _across(network, ribbons, who[0], key, t))
        nb = np.cross(tangent, _across(network, ribbons, who[1], key, t))
        cos = np.abs(np.einsum("ij,ij->i", na, nb)) / (
            np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1)
        )
        out.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.array(out)


def test_sphere_tangent_planes_shared_between_corner_pieces(sphere) -> None:
    _, network, _, ribbons = sphere
    assert not any(network.regular.values())  # every corner joins three patches
    angles = _edge_angles(network, ribbons, np.linspace(0.25, 0.75, 101))
    assert angles.max() < 0.3  # measured 0.06: cubic interpolation of the along-edge part
    # Near the corners (vertex enclosure) only approximately, but within a degree (measured 0.4).
    assert _edge_angles(network, ribbons, np.linspace(0.0, 1.0, 201)).max() < 1.0


def test_sphere_ribbons_compatible_with_sides(sphere) -> None:
    _, network, c0, ribbons = sphere
    for label, rib in ribbons.items():
        b = c0[label].base
        base = BicubicCoons(
            b.bottom, b.right, b.top, b.left, rib.d_bottom, rib.d_right, rib.d_top, rib.d_left,
            twists=rib.twists,
        )
        for res in base.compatibility_residuals().values():
            assert max(res.values()) < 1e-9


def test_sphere_c1_fit_close_to_c0(sphere) -> None:
    """The C1 fits on the shared ribbons stay within reconstruct's fallback ratio (2) of the
    C0 fits, and within 1e-4 of the diagonal of the true sphere."""
    cloud, _, c0, ribbons = sphere
    u = np.linspace(0.0, 1.0, 30)
    uu, vv = np.meshgrid(u, u)
    true = []
    for label, rib in ribbons.items():
        c1 = fit_patch(
            c0[label].points, continuity="c1", m=6, n=6, boundary=c0[label].sides, ribbons=rib
        )
        assert c1.errors["mean"] <= 2.0 * c0[label].errors["mean"]
        true.append(cloud.distance(c1.evaluate(uu.ravel(), vv.ravel())))
    assert np.concatenate(true).mean() < 1e-4 * cloud.diagonal


def test_regular_network_shares_parallel_ribbons() -> None:
    """All corners regular (torus): ``lambda_A D`` / ``-lambda_B D`` on every edge with
    constant lambdas (the pair speed ratio kept along each line of edges), so one tangent
    plane along the whole edge (torus patches differ in width by less than the pair slack:
    ratio 1, equal and opposite ribbons, C1)."""
    _, network, c0 = _setup("torus", 12000)
    assert all(network.regular.values())
    ribbons = shared_ribbons(network, c0)
    t = np.linspace(0.0, 1.0, 41)[1:-1]
    ratios = []
    for key, who in network.users.items():
        ra = _across(network, ribbons, who[0], key, t)
        rb = _across(network, ribbons, who[1], key, t)
        # The Coons signs of the two sides' ribbons differ by the side orientation: one is a
        # constant multiple of the other, of either sign.
        k = float(np.sum(ra * rb) / np.sum(ra * ra))
        assert np.abs(rb - k * ra).max() < 1e-9 * np.abs(ra).max()
        ratios.append(abs(k))
    assert max(max(ratios), 1 / min(ratios)) < 1.0 + 1e-9


def _side_params(ids: list[int], key: tuple[int, int], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """(u, v) on a patch's side ``key`` at edge parameters ``t`` (3- or 4-sided loop)."""
    n = len(ids)
    k = [key_of(ids[j], ids[(j + 1) % n]) for j in range(n)].index(key)
    s = t if ids[k] == key[0] else 1.0 - t
    one, zero = np.ones_like(s), np.zeros_like(s)
    if k == 0:
        return np.column_stack([s, zero])
    if k == 1:
        return np.column_stack([one, s])
    if k == 2 and n == 4:
        return np.column_stack([1.0 - s, one])
    return np.column_stack([zero, 1.0 - s])


def test_triangles_around_a_pole_are_c1() -> None:
    """A sheet split by its diagonals into 4 triangles meeting at the centre: with the apex
    of every triangle at the centre, the shared ribbons make every edge C1, up to and
    including the pole (one tangent plane there), and the C1 fit is no worse than C0."""
    from pde2cad.reconstruct import apex_first

    cloud = samples.sheet(20000)
    pts = cloud.points
    xy = pts[:, :2] - 1.0
    lab = np.where(
        np.abs(xy[:, 0]) > np.abs(xy[:, 1]),
        np.where(xy[:, 0] > 0, 0, 1),
        np.where(xy[:, 1] > 0, 2, 3),
    )
    network = build_edges(pts, lab, build_layout(pts, lab, check=False), cKDTree(pts))
    network = apex_first(network)
    apexes = {ids[2] for ids in network.loops.values()}
    assert all(len(ids) == 3 for ids in network.loops.values()) and len(apexes) == 1
    c0 = {
        label: fit_patch(pts[lab == label], continuity="c0", m=6, n=6, boundary=network.sides(label))
        for label in sorted(network.loops)
    }
    ribbons = shared_ribbons(network, c0)
    assert set(ribbons) == set(network.loops)
    c1 = {
        label: fit_patch(
            c0[label].points, continuity="c1", m=6, n=6, boundary=c0[label].sides,
            ribbons=ribbons[label], params=c0[label].params, outside=c0[label].outside,
        )
        for label in sorted(network.loops)
    }
    for label, patch in c1.items():
        for residual in patch.base.compatibility_residuals().values():
            assert max(residual.values()) < 1e-9
        assert patch.fit_errors["mean"] < 1.5 * c0[label].fit_errors["mean"] + 1e-6
    t = np.linspace(0.0, 1.0, 41)
    worst = 0.0
    for key, who in network.users.items():
        if len(who) != 2:
            continue
        pa = _side_params(network.loops[who[0]], key, t)
        pb = _side_params(network.loops[who[1]], key, t)
        na = c1[who[0]].normals(pa[:, 0], pa[:, 1])
        nb = c1[who[1]].normals(pb[:, 0], pb[:, 1])
        cos = np.abs(np.einsum("ij,ij->i", na, nb))
        worst = max(worst, float(np.degrees(np.arccos(np.clip(cos.min(), -1.0, 1.0)))))
    assert worst < 0.05
    # One tangent plane at the pole: the limit normals of all four patches there agree.
    u = np.linspace(0.0, 1.0, 9)
    normals = np.vstack([p.normals(u, np.full_like(u, 1.0 - 1e-6)) for p in c1.values()])
    assert np.degrees(np.arccos(np.clip(np.abs(normals @ normals[0]).min(), -1, 1))) < 0.05
