"""The fast paths of the layout front end give the same results as the plain computation:
the banded alpha shape, the k-NN of border points only, the cached loops."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

import pde2cad.surfaces.region as region
from pde2cad.errors import InputError
from pde2cad.layout import build_layout
from pde2cad.samples import cylinder, sphere6
from pde2cad.surfaces.region import boundary_loop, pca_frame


def _full(xy: NDArray[np.float64], monkeypatch: pytest.MonkeyPatch, **kw: object):
    with monkeypatch.context() as m:
        m.setattr(region, "BAND_POINTS", 10**12)
        return boundary_loop(xy, **kw)


def _shapes() -> list[NDArray[np.float64]]:
    rng = np.random.default_rng(11)
    rect = rng.random((40_000, 2)) * [3.0, 1.0]
    holed = rng.random((40_000, 2))
    holed = holed[np.linalg.norm(holed - 0.5, axis=1) > 0.2]
    ell = rng.random((40_000, 2)) * 2.0
    ell = ell[(ell[:, 0] < 1.0) | (ell[:, 1] < 1.0)]
    # Regular grid (cocircular points) rotated a little, plus a sparse strip.
    g = np.stack(np.meshgrid(np.arange(220.0), np.arange(120.0)), -1).reshape(-1, 2) * 0.01
    c, s = np.cos(0.3), np.sin(0.3)
    grid = g @ np.array([[c, -s], [s, c]])
    return [rect, holed, ell, grid]


@pytest.mark.parametrize("which", range(4))
def test_band_loop_equals_full_triangulation(which: int, monkeypatch: pytest.MonkeyPatch) -> None:
    xy = _shapes()[which]
    assert len(xy) > region.BAND_POINTS
    band = boundary_loop(xy)
    np.testing.assert_array_equal(band, _full(xy, monkeypatch))
    alpha = 3.0 * region.default_alpha(xy)
    np.testing.assert_array_equal(boundary_loop(xy, alpha), _full(xy, monkeypatch, alpha=alpha))


def test_band_reports_the_same_problems(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(5)
    two = np.r_[rng.random((15_000, 2)), rng.random((15_000, 2)) + [3.0, 0.0]]
    messages = []
    for full in (False, True):
        with pytest.raises(InputError) as err:
            _full(two, monkeypatch) if full else boundary_loop(two)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "2 pieces" in messages[0]
    # A sampling gap: default alpha retries until it closes, as on the full triangulation.
    xy = rng.random((40_000, 2))
    xy = xy[np.linalg.norm(xy - 0.5, axis=1) > 0.012]
    np.testing.assert_array_equal(boundary_loop(xy), _full(xy, monkeypatch))


def test_band_is_exact_on_a_sphere_face(monkeypatch: pytest.MonkeyPatch) -> None:
    cloud = sphere6(300_000)
    pts = cloud.points[cloud.labels == 2]
    origin, axes = pca_frame(pts)
    uv = (pts - origin) @ axes[:2].T
    np.testing.assert_array_equal(boundary_loop(uv), _full(uv, monkeypatch))


def _plain_borders(pts, lab, k, radius):
    """Border point sets from the k-NN of every point (the reference computation)."""
    dist, idx = cKDTree(pts).query(pts, k=k + 1)
    dist, idx = dist[:, 1:], idx[:, 1:]
    rows = np.repeat(np.arange(len(pts)), k)
    cols = idx.reshape(-1)
    cross = (dist.reshape(-1) <= radius) & (lab[rows] != lab[cols])
    out: dict[tuple[int, int], set[int]] = {}
    for i, j in zip(rows[cross], cols[cross]):
        key = (int(min(lab[i], lab[j])), int(max(lab[i], lab[j])))
        out.setdefault(key, set()).update((int(i), int(j)))
    return out


def test_border_points_equal_plain_knn() -> None:
    cloud = cylinder(40_000, split=(4, 3))
    layout = build_layout(cloud.points, cloud.labels)
    plain = _plain_borders(cloud.points, cloud.labels, 12, layout.radius)
    for pair, border in layout.borders.items():
        ref = cloud.points[sorted(plain[pair])]
        np.testing.assert_array_equal(np.unique(border, axis=0), np.unique(ref, axis=0))


def test_loops_are_cached_on_the_layout() -> None:
    cloud = sphere6(30_000)
    layout = build_layout(cloud.points, cloud.labels)
    for label, loop in layout.loops.items():
        members = np.flatnonzero(cloud.labels == label)
        origin, axes = pca_frame(cloud.points[members])
        uv = (cloud.points[members] - origin) @ axes[:2].T
        np.testing.assert_array_equal(loop, members[boundary_loop(uv)])


def test_dense_cloud_corners() -> None:
    # Sampled spacing (SAMPLE_POINTS), border-only k-NN and banded loops at 4e5 points: the
    # cube-sphere still has 8 corners, 4 per face (the dips of the alpha shape into a dense
    # random sample no longer add corners).
    cloud = sphere6(400_000, seed=1)
    layout = build_layout(cloud.points, cloud.labels)
    truth = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    dist, nearest = cKDTree(layout.corners).query(truth / np.sqrt(3.0))
    assert len(layout.corners) == 8 and len(set(nearest.tolist())) == 8
    assert dist.max() < 4.0 * layout.radius
    assert all(len(w) == 4 for w in layout.segment_corners.values())


def test_a_second_layout_of_the_same_cloud_reuses_what_it_kept_and_equals_the_first() -> None:
    """The split step lays out one cloud dozens of times; border spans, crossing tests and
    segment loops are kept between calls (by a checksum of the points), which must change
    nothing, and a moved cloud must not reuse them."""
    import pde2cad.layout.adjacency as adjacency

    cloud = sphere6(n_points=12000, seed=4)
    first = build_layout(cloud.points, cloud.labels)
    kept = dict(adjacency._MEMO)
    kinds = {key[0] for key in kept}
    assert kinds == {"span", "crossing", "loop"}, kinds
    again = build_layout(cloud.points.copy(), cloud.labels)
    assert adjacency._MEMO.keys() == kept.keys()
    assert again.adjacency == first.adjacency and np.array_equal(again.corners, first.corners)
    assert all(np.array_equal(again.borders[p], first.borders[p]) for p in first.borders)
    scaled = build_layout(cloud.points * 1.5, cloud.labels)
    assert not adjacency._MEMO.keys() & {k for k in kept if k[0] == "span"}
    assert scaled.adjacency == first.adjacency
