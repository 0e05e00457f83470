"""Layout of segmented clouds: adjacency, corners, open boundary, and the validation errors."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad import samples
from pde2cad.errors import InputError
from pde2cad.layout import Layout, build_layout


def grid(n: int, lo: float = -1.0, hi: float = 1.0, seed: int = 0) -> NDArray[np.float64]:
    """Cell centres of an n x n grid on [lo, hi]^2, jittered by 5 % of the spacing (M, 2)."""
    rng = np.random.default_rng(seed)
    g = lo + (np.arange(n) + 0.5) / n * (hi - lo)
    uv = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    return uv + rng.normal(0.0, 0.05 * (hi - lo) / n, uv.shape)


def sheet(n: int = 100) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """z = 0.1 sin(x) sin(y) on [-1, 1]^2, labelled by quadrant (a 2 x 2 grid of patches)."""
    uv = grid(n)
    pts = np.column_stack([uv, 0.1 * np.sin(uv[:, 0]) * np.sin(uv[:, 1])])
    return pts, (uv[:, 0] > 0).astype(np.int64) + 2 * (uv[:, 1] > 0)


def cube_faces(n: int = 50) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The 6 faces of [-1, 1]^3, n x n points each, one label per face."""
    uv = grid(n)
    u, v, one = uv[:, 0], uv[:, 1], np.ones(len(uv))
    faces = [(-one, u, v), (one, u, v), (u, -one, v), (u, one, v), (u, v, -one), (u, v, one)]
    pts = np.vstack([np.column_stack(f) for f in faces])
    return pts, np.repeat(np.arange(6), len(uv))


def assert_corners(layout: Layout, truth: NDArray[np.float64], tol: float) -> None:
    """Every true corner has exactly one detected corner within ``tol`` and vice versa."""
    assert len(layout.corners) == len(truth)
    dist, nearest = cKDTree(layout.corners).query(truth)
    assert dist.max() < tol, dist.max()
    assert len(set(nearest.tolist())) == len(truth)


def test_sheet_2x2() -> None:
    pts, lab = sheet()
    layout = build_layout(pts, lab)
    np.testing.assert_array_equal(layout.labels_present, [0, 1, 2, 3])
    assert sorted(layout.adjacency) == [(0, 1), (0, 2), (1, 3), (2, 3)]  # no diagonals
    # Each border is ~100 samples long; every border point touches the other label.
    for (a, b), border in layout.borders.items():
        assert layout.adjacency[(a, b)] > 150
        assert np.abs(border[:, 0 if b - a == 1 else 1]).max() < 3 * layout.spacing
    truth_uv = np.array([[x, y] for x in (-1.0, 0.0, 1.0) for y in (-1.0, 0.0, 1.0)])
    truth = np.column_stack([truth_uv, 0.1 * np.sin(truth_uv[:, 0]) * np.sin(truth_uv[:, 1])])
    diagonal = float(np.linalg.norm(np.ptp(truth, axis=0)))
    assert_corners(layout, truth, 0.02 * diagonal)
    for label, which in layout.segment_corners.items():
        assert len(which) == 4, label
        # The centre corner (0, 0) belongs to all four segments.
        assert np.linalg.norm(layout.corners[which, :2], axis=1).min() < 0.05
    # Open boundary: the two outer sides of each quadrant, nothing on the inner borders.
    for label, ob in layout.open_boundary.items():
        assert len(ob) > 50
        assert (np.abs(ob[:, :2]).max(axis=1) > 0.95).all(), label


def test_cube_faces() -> None:
    pts, lab = cube_faces()
    layout = build_layout(pts, lab)
    assert len(layout.adjacency) == 12
    assert (0, 1) not in layout.adjacency and (2, 3) not in layout.adjacency
    truth = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    assert_corners(layout, truth, 0.02 * np.sqrt(12.0))
    assert all(len(w) == 4 for w in layout.segment_corners.values())
    assert all(len(ob) == 0 for ob in layout.open_boundary.values())  # closed surface


def test_cube_sphere() -> None:
    pts, lab = cube_faces(60)
    pts = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    layout = build_layout(pts, lab)
    assert len(layout.adjacency) == 12
    truth = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    assert_corners(layout, truth / np.sqrt(3.0), 0.02 * 2.0)
    assert all(len(w) == 4 for w in layout.segment_corners.values())
    # Each corner is where 3 patches meet.
    counts = np.bincount(np.concatenate(list(layout.segment_corners.values())))
    np.testing.assert_array_equal(counts, 3)


def test_l_shape_has_six_corners() -> None:
    # [0, 3]^2: segment 7 is the L (bottom strip + left strip), segment 2 the square [1, 3]^2.
    uv = grid(90, 0.0, 3.0)
    pts = np.column_stack([uv, np.zeros(len(uv))])
    lab = np.where((uv[:, 0] > 1.0) & (uv[:, 1] > 1.0), 2, 7)
    with pytest.raises(InputError, match="segment 7 has 6 corners; a patch needs 3 or 4"):
        build_layout(pts, lab)
    layout = build_layout(pts, lab, check=False)
    assert len(layout.segment_corners[7]) == 6
    assert len(layout.segment_corners[2]) == 4  # the kink of the border is a corner of both
    assert list(layout.adjacency) == [(2, 7)]


def test_split_segment() -> None:
    # Three strips; the outer two share label 4 and are not connected.
    uv = grid(90, 0.0, 3.0)
    pts = np.column_stack([uv, np.zeros(len(uv))])
    lab = np.where((uv[:, 0] > 1.0) & (uv[:, 0] < 2.0), 1, 4)
    with pytest.raises(InputError, match="segment 4 falls apart into 2 separate pieces"):
        build_layout(pts, lab)


def test_tiny_segment_and_bad_input() -> None:
    pts, lab = sheet(60)
    lab = lab.copy()
    lab[:20] = 9
    with pytest.raises(InputError, match="segment 9 has 20 points; a segment needs at least 50"):
        build_layout(pts, lab)
    with pytest.raises(InputError, match="one value per point"):
        build_layout(pts, lab[:-1])
    bad = pts.copy()
    bad[[3, 5]] = np.nan
    with pytest.raises(InputError, match="NaN or inf in 2 rows"):
        build_layout(bad, lab)


def test_curved_seam_and_three_sided_patch() -> None:
    # A triangle split from a square by a diagonal: two 3-sided patches, 4 corners in all.
    uv = grid(80)
    pts = np.column_stack([uv, 0.2 * uv[:, 0] ** 2])
    lab = (uv[:, 1] > uv[:, 0]).astype(np.int64)
    layout = build_layout(pts, lab)
    assert list(layout.adjacency) == [(0, 1)]
    assert len(layout.corners) == 4
    assert all(len(w) == 3 for w in layout.segment_corners.values())


def test_random_noisy_samples() -> None:
    # Uniform random samples (irregular spacing) with noise across the sheet: same topology.
    rng = np.random.default_rng(3)
    uv = rng.uniform(-1.0, 1.0, (20_000, 2))
    z = 0.1 * np.sin(uv[:, 0]) * np.sin(uv[:, 1]) + rng.normal(0.0, 0.003, len(uv))
    layout = build_layout(np.column_stack([uv, z]), (uv[:, 0] > 0) + 2 * (uv[:, 1] > 0))
    assert sorted(layout.adjacency) == [(0, 1), (0, 2), (1, 3), (2, 3)]
    truth = np.array([[x, y] for x in (-1.0, 0.0, 1.0) for y in (-1.0, 0.0, 1.0)])
    assert len(layout.corners) == 9
    assert cKDTree(layout.corners[:, :2]).query(truth)[0].max() < 0.02 * np.sqrt(8.0)
    assert all(len(w) == 4 for w in layout.segment_corners.values())


def open_shape_corners(shape: str) -> NDArray[np.float64]:
    """True corners of the ``samples`` cylinder, pot and sheet (C, 3)."""
    seams = np.arange(4) * np.pi / 2
    if shape == "cylinder":
        return np.array([[np.cos(a), np.sin(a), z] for a in seams for z in (0.0, 1.0, 2.0)])
    if shape == "pot":
        z = np.array([0.0, 0.8, 1.6])
        r = 0.8 + 0.3 * np.sin(np.pi * z / 1.2) - 0.1 * z
        return np.array(
            [[ri * np.cos(a), ri * np.sin(a), zi] for a in seams for zi, ri in zip(z, r)]
        )
    xy = np.array([[x, y] for x in (0.0, 1.0, 2.0) for y in (0.0, 1.0, 2.0)])
    return np.column_stack([xy, 0.1 * np.sin(xy[:, 0]) * np.sin(xy[:, 1])])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("shape", "n_open"), [("cylinder", 8), ("pot", 4), ("sheet", 8)])
def test_noisy_open_boundary(shape: str, n_open: int, seed: int) -> None:
    # Noise of 0.5 % of the diagonal makes the alpha shape along the open boundary wobble by
    # up to ~40 degrees over +-perimeter/32: no extra corners there, and none lost.
    cloud = samples.SHAPES[shape](20_000, noise=0.005, seed=seed)
    layout = build_layout(cloud.points, cloud.labels)  # checks 3-4 corners per segment
    truth = open_shape_corners(shape)
    assert_corners(layout, truth, 0.03 * cloud.diagonal)
    assert all(len(w) == 4 for w in layout.segment_corners.values())
    # Corners on the rims (a border meets the open boundary) and the sheet's outer corners.
    assert layout.open_corners is not None and int(layout.open_corners.sum()) == n_open
    z = layout.corners[layout.open_corners, 2]
    if shape == "cylinder":  # both rims
        assert np.minimum(np.abs(z), np.abs(z - 2.0)).max() < 0.05
    elif shape == "pot":  # the top rim; the bottom is closed
        assert np.abs(z - 1.6).max() < 0.05
    else:  # all but the centre
        centre = np.argmin(np.linalg.norm(layout.corners[:, :2] - 1.0, axis=1))
        assert not layout.open_corners[centre]


@pytest.mark.parametrize(
    ("shape", "n_points", "noise", "n_corners"),
    [("torus", 20_000, 0.005, 16), ("torus", 10_000, 0.003, 16), ("sphere6", 5_000, 0.002, 8),
     ("sphere6", 20_000, 0.005, 8)],
)
def test_noisy_closed_shapes_keep_their_corners(
    shape: str, n_points: int, noise: float, n_corners: int
) -> None:
    # No border kinks from noise (nor from the projection of the torus's inner side), and
    # every junction found, including one that no point's neighbourhood spans (sphere6 5000:
    # a sparse spot next to it).
    cloud = samples.SHAPES[shape](n_points, noise=noise, seed=0)
    layout = build_layout(cloud.points, cloud.labels)
    assert len(layout.corners) == n_corners
    assert all(len(w) == 4 for w in layout.segment_corners.values())
    assert layout.open_corners is not None and not layout.open_corners.any()


def test_teapot_lid_knob_folds_over_its_pca_plane() -> None:
    """The lid's knob quarters bulge (r from 0 at the pole out to 0.36, in to 0.17 at the
    neck, 0.2 at the seam with the ring): their PCA plane is a meridian plane, which folds
    them, and an alpha shape there missed the seam and found open boundary on the bulb. A
    tilted plane keeps them height fields: each knob quarter gets the pole and the two ends of
    its seam with the ring, no open boundary; each ring quarter those two and two on the
    lid's rim."""
    cl = samples.teapot(20000, parts=("lid",))
    layout = build_layout(cl.points, cl.labels, check=False)
    # Patch corners: 3 labels meet there or a border meets the open boundary (build_edges
    # drops the others, border kinks such as the knob's equator on a meridian seam).
    tree = cKDTree(cl.points)
    n_labels = np.array([
        len(np.unique(cl.labels[tree.query_ball_point(c, 2.5 * layout.radius)]))
        for c in layout.corners
    ])
    patch = (n_labels >= 3) | layout.open_corners
    xyz = layout.corners
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    pole = np.flatnonzero(patch & (r < 0.05))
    seam = np.flatnonzero(patch & (np.abs(r - 0.2) < 0.05) & (np.abs(xyz[:, 2] - 2.7) < 0.05))
    edge = np.flatnonzero(patch & (np.abs(r - 1.3) < 0.05) & (np.abs(xyz[:, 2] - 2.4) < 0.05))
    assert (len(pole), len(seam), len(edge)) == (1, 4, 4)
    assert patch.sum() == 9
    for label in range(20, 28):
        which = [c for c in layout.segment_corners[label] if patch[c]]
        if label < 24:
            assert len(layout.open_boundary[label]) == 0, label
            assert sorted(which) == sorted([pole[0], *np.intersect1d(which, seam)]), label
            assert len(np.intersect1d(which, seam)) == 2, label
        else:
            assert len(layout.open_boundary[label]) > 20, label
            assert len(np.intersect1d(which, seam)) == 2, label
            assert len(np.intersect1d(which, edge)) == 2, label
            assert len(which) == 4, label


@pytest.mark.parametrize("gap", [0.06, 0.1, 0.15])
def test_separate_pieces_keep_their_own_corners(gap: float) -> None:
    """Two 2 x 2 sheets side by side, a gap of 1.2-2.9 neighbour radii apart (like the Utah
    teapot's lid and rim, 0.1 apart): no cross edges, but the corners facing each other lie
    within the linkage (2.5 r) and merge (4 r) distances. They used to merge into one corner
    on one sheet (15 corners, two segments left with 3). Only corners of related segments
    (the same or adjacent) are linked, merged or assigned."""
    pts, lab = sheet()
    both = np.vstack([pts, pts + [2.0 + gap, 0.0, 0.0]])
    layout = build_layout(both, np.r_[lab, lab + 4])
    assert gap > layout.radius  # no cross edges
    assert not any(a < 4 <= b for a, b in layout.adjacency)
    assert len(layout.corners) == 18
    for label, which in layout.segment_corners.items():
        assert len(which) == 4, label
        side = layout.corners[which, 0] > 1.0 + gap / 2
        assert side.all() if label >= 4 else not side.any(), label


def test_teapot_rim_folds_over_every_plane() -> None:
    """The teapot's rim is a lip whose cross-section turns by ~175 degrees (from its inner
    free edge r = 1.4 up over a crest at r ~1.38-1.43 down to the body at r = 1.5, z = 2.4):
    no plane keeps a rim quarter a height field, and the alpha shape of any projection
    followed the crest instead of the inner edge (corners at r = 1.38, z = 2.48). Unfolded
    (along its main axis x geodesic distance from the body), each quarter gets its two
    corners on the body and two on the inner free edge, which is its open boundary. At 300k
    points: the inner and outer corners are 0.1 apart, ~4 neighbour radii."""
    cl = samples.teapot(300_000, parts=("rim", "body"))
    layout = build_layout(cl.points, cl.labels)
    assert layout.open_corners is not None
    xyz = layout.corners
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    for label in range(4):
        which = layout.segment_corners[label]
        assert len(which) == 4, label
        inner = which[np.abs(r[which] - 1.4) < 0.02]
        outer = which[np.abs(r[which] - 1.5) < 0.02]
        assert len(inner) == 2 and len(outer) == 2, label
        assert (np.abs(xyz[which, 2] - 2.4) < 0.02).all(), label
        assert layout.open_corners[inner].all() and not layout.open_corners[outer].any()
        ob = layout.open_boundary[label]
        assert len(ob) > 50, label
        assert (np.abs(np.hypot(ob[:, 0], ob[:, 1]) - 1.4) < 0.015).all(), label
        assert (ob[:, 2] < 2.43).all(), label
    for label in range(4, 12):
        assert len(layout.segment_corners[label]) == 4, label
