"""Tests of mirror/rotation detection on rasterized shapes (thesis Section 3.1)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.image.contours import signed_area, trace_loops
from pde2cad.image.symmetry import Symmetry, detect_symmetry, fill_loop, fundamental_split

# ----------------------------------------------------------------------------- shapes


def _centres(h: int, w: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    yy, xx = np.mgrid[0:h, 0:w]
    return xx + 0.5, yy + 0.5


def polygon_mask(poly: NDArray[np.float64], h: int, w: int) -> NDArray[np.bool_]:
    """Pixels whose centre lies inside ``poly`` (even-odd ray casting)."""
    x, y = (a[..., None] for a in _centres(h, w))
    p = np.asarray(poly, dtype=float)
    q = np.roll(p, -1, axis=0)
    crosses = (p[:, 1] > y) != (q[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = p[:, 0] + (y - p[:, 1]) * (q[:, 0] - p[:, 0]) / (q[:, 1] - p[:, 1])
    return (np.sum(crosses & (x < xint), axis=-1) % 2).astype(bool)


def radial_mask(
    radius: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    size: int = 200,
    center: tuple[float, float] = (100.3, 99.6),
) -> NDArray[np.bool_]:
    """A star-shaped region r <= radius(angle) about an off-grid centre."""
    x, y = _centres(size, size)
    dx, dy = x - center[0], y - center[1]
    return np.hypot(dx, dy) <= radius(np.arctan2(dy, dx))


def ellipse_mask(deg: float = 30.0) -> NDArray[np.bool_]:
    x, y = _centres(160, 180)
    t = np.radians(deg)
    dx, dy = x - 90.3, y - 80.6
    u = dx * np.cos(t) + dy * np.sin(t)
    v = -dx * np.sin(t) + dy * np.cos(t)
    return (u / 60.0) ** 2 + (v / 28.0) ** 2 <= 1.0


def heart_mask() -> NDArray[np.bool_]:
    """The heart (x^2 + y^2 - 1)^3 = x^2 y^3, symmetric about the pixel line x = 75."""
    x, y = _centres(150, 150)
    u, v = (x - 75.0) / 45.0, -(y - 70.0) / 45.0
    return (u * u + v * v - 1.0) ** 3 - u * u * v**3 <= 0.0


def star_mask(scale: float = 1.0) -> NDArray[np.bool_]:
    """A 5-point star, one tip up, centred on a pixel centre (x = 100.5 is a mirror line)."""
    size = int(200 * scale)
    c = size / 2 + 0.5
    ang = -np.pi / 2 + np.arange(10) * np.pi / 5
    rad = np.where(np.arange(10) % 2 == 0, 80.0, 34.0) * scale
    return polygon_mask(np.column_stack([c + rad * np.cos(ang), c + rad * np.sin(ang)]), size, size)


def gear_mask(scale: float = 1.0) -> NDArray[np.bool_]:
    """Six trapezoid-like teeth, rotated 0.2 rad off the grid."""
    size = int(200 * scale)
    return radial_mask(
        lambda a: scale * (60.0 + 10.0 * np.clip(2.5 * np.cos(6 * (a - 0.2)), -1, 1)),
        size,
        (size / 2 + 0.3, size / 2 - 0.4),
    )


def blob_mask() -> NDArray[np.bool_]:
    rng = np.random.default_rng(3)
    amp, phase = rng.uniform(0.08, 0.16, 5), rng.uniform(0.0, 2 * np.pi, 5)
    return radial_mask(
        lambda a: 60.0 * (1 + sum(amp[m] * np.cos((m + 1) * a + phase[m]) for m in range(5)))
    )


def s_mask() -> NDArray[np.bool_]:
    """An "S" of 16 px bars: a half turn about the pixel corner (55, 70), no mirror."""
    m = np.zeros((140, 110), dtype=bool)
    m[20:36, 20:90] = True
    m[20:78, 20:36] = True
    m[62:78, 20:90] = True
    m[62:120, 74:90] = True
    m[104:120, 20:90] = True
    m[20:40, 74:90] = True
    m[100:120, 20:36] = True
    return m


def rectangle_mask() -> NDArray[np.bool_]:
    m = np.zeros((100, 140), dtype=bool)
    m[20:70, 15:115] = True
    return m


def outer(mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    return np.array(trace_loops(mask)[0].points)


# ----------------------------------------------------------------------------- helpers


def by_kind(syms: list[Symmetry], kind: str) -> list[Symmetry]:
    return [s for s in syms if s.kind == kind]


def axis_deg(sym: Symmetry) -> float:
    return float(np.degrees(sym.angle))


def angle_diff_deg(a: float, b: float, period: float = 180.0) -> float:
    return abs((a - b + period / 2) % period - period / 2)


def run_indices(i0: int, i1: int, n: int) -> NDArray[np.intp]:
    return np.mod(i0 + np.arange((i1 - i0) % n + 1), n)


def polyline_distance(path: NDArray[np.float64], pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance from ``pts`` to the open polyline ``path`` of unit crack steps (to 1/16 px)."""
    t = np.arange(8) / 8.0
    dense = (path[:-1, None, :] * (1 - t[:, None]) + path[1:, None, :] * t[:, None]).reshape(-1, 2)
    return cKDTree(np.vstack([dense, path[-1:]])).query(pts)[0]


def rotation_split_error(p: NDArray[np.float64], sym: Symmetry, i0: int, i1: int) -> float:
    """Max distance from the mapped fundamental run to the loop part that follows it.

    A crack loop's vertex count along a part depends on its direction (a staircase at angle
    a has |cos a| + |sin a| vertices per unit length), so the next part is searched in a
    window of 1.5 run lengths forward from ``i1``; the run itself lies outside it.
    """
    n = len(p)
    run = run_indices(i0, i1, n)
    nxt = np.mod(i1 - 2 + np.arange(int(1.5 * len(run))), n)
    return float(polyline_distance(p[nxt], sym.apply(p[run])).max())


# Both the loop and its mapped copy are staircases within ~0.7 px of the true outline, so for
# maps off the pixel grid they differ by up to ~1 px (measured: 99th percentile 0.95 px, max
# 1.12 px at the sharp gear teeth); grid maps must match exactly.
_STAIRCASE = 1.25


# ----------------------------------------------------------------------------- fill_loop


@pytest.mark.parametrize("make", [heart_mask, star_mask, s_mask, blob_mask])
def test_fill_loop_reproduces_mask_and_shoelace_area(make: Callable[[], NDArray[np.bool_]]) -> None:
    mask = make()
    p = outer(mask)
    fill, (r0, c0) = fill_loop(p)
    assert fill.sum() == abs(signed_area(p)) == mask.sum()
    np.testing.assert_array_equal(fill, mask[r0 : r0 + fill.shape[0], c0 : c0 + fill.shape[1]])


def test_fill_loop_hole_and_long_edges() -> None:
    ring = np.zeros((30, 30), dtype=bool)
    ring[5:25, 5:25] = True
    ring[10:18, 9:20] = False
    hole = next(lp for lp in trace_loops(ring) if lp.is_hole)
    fill, origin = fill_loop(hole.points)
    assert origin == (10, 9) and fill.shape == (8, 11) and fill.all()
    assert fill.sum() == -signed_area(hole.points) == 88
    # Corners only (edges longer than one pixel) give the same raster.
    l_shape = np.array([[0, 0], [7, 0], [7, 3], [3, 3], [3, 9], [0, 9]], dtype=float)
    fill, origin = fill_loop(l_shape)
    assert origin == (0, 0) and fill.sum() == abs(signed_area(l_shape)) == 7 * 3 + 3 * 6
    assert fill[:3].all() and fill[3:, :3].all() and not fill[3:, 3:].any()


def test_fill_loop_rejects_non_crack_input() -> None:
    with pytest.raises(InputError):
        fill_loop(np.array([[0, 0], [2, 1], [0, 2], [1, 1]], dtype=float))
    with pytest.raises(InputError):
        fill_loop(np.array([[0, 0], [1.5, 0], [1.5, 1], [0, 1]]))


# ----------------------------------------------------------------------------- detection


def test_ellipse_rotated_30_has_both_mirror_axes() -> None:
    syms = detect_symmetry(outer(ellipse_mask(30.0)))
    mirrors = by_kind(syms, "mirror")
    assert len(mirrors) == 2
    angles = sorted(axis_deg(m) for m in mirrors)
    assert angle_diff_deg(angles[0], 30.0) < 1.0
    assert angle_diff_deg(angles[1], 120.0) < 1.0
    assert all(m.iou > 0.97 for m in mirrors)
    for m in mirrors:  # the axes pass through the ellipse centre
        off = np.array([90.3, 80.6]) - m.center
        assert abs(m.axis[0] * off[1] - m.axis[1] * off[0]) < 0.1
    # A centrally symmetric shape: the half turn is found too.
    (rot,) = by_kind(syms, "rotation")
    assert rot.order == 2 and rot.iou > 0.97
    np.testing.assert_allclose(rot.center, [90.3, 80.6], atol=0.1)


def test_heart_mirror_only_vertical_axis_snapped_exactly() -> None:
    syms = detect_symmetry(outer(heart_mask()))
    assert len(syms) == 1
    (m,) = syms
    assert m.kind == "mirror" and m.order == 2 and m.iou == 1.0
    assert tuple(m.axis) == (0.0, 1.0) and m.center[0] == 75.0
    np.testing.assert_array_equal(m.matrix, [[-1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(m.offset, [150.0, 0.0], atol=1e-12)


def test_star_rotation_order_5_and_mirrors() -> None:
    syms = detect_symmetry(outer(star_mask()))
    assert syms[0].kind == "rotation" and syms[0].order == 5
    assert syms[0].iou > 0.97
    assert abs(abs(np.degrees(syms[0].angle)) - 72.0) < 1e-9
    np.testing.assert_allclose(syms[0].center, [100.5, 100.5], atol=0.01)
    mirrors = by_kind(syms, "mirror")
    assert len(mirrors) == 5
    # The tip-up axis is a pixel line: snapped and exact; the others are 36 deg apart.
    assert mirrors[0].iou == 1.0 and tuple(mirrors[0].axis) == (0.0, 1.0)
    assert mirrors[0].center[0] == 100.5
    found = np.sort([axis_deg(m) for m in mirrors])
    np.testing.assert_allclose(found, np.sort((90.0 + 36.0 * np.arange(5)) % 180.0), atol=0.1)


def test_gear_rotation_order_6_first() -> None:
    syms = detect_symmetry(outer(gear_mask()))
    assert syms[0].kind == "rotation" and syms[0].order == 6 and syms[0].iou > 0.98
    np.testing.assert_allclose(syms[0].center, [100.3, 99.6], atol=0.05)
    orders = [s.order for s in by_kind(syms, "rotation")]
    assert orders == [6, 3, 2]  # the divisors pass too, highest saving first
    mirrors = by_kind(syms, "mirror")
    assert len(mirrors) == 6
    for m in mirrors:  # tooth axes at 0.2 rad + k * 30 deg
        assert angle_diff_deg(axis_deg(m) - np.degrees(0.2), 0.0, 30.0) < 0.2
    savings = [s.saving for s in syms]
    assert savings == sorted(savings, reverse=True)


def test_random_blob_has_no_symmetry() -> None:
    assert detect_symmetry(outer(blob_mask())) == []
    # ... and nothing close: the best candidates stay far below the threshold.
    loose = detect_symmetry(outer(blob_mask()), iou_min=0.9)
    assert loose == []


def test_s_shape_half_turn_without_mirror() -> None:
    syms = detect_symmetry(outer(s_mask()))
    assert len(syms) == 1
    (rot,) = syms
    assert rot.kind == "rotation" and rot.order == 2 and rot.iou == 1.0
    np.testing.assert_array_equal(rot.center, [55.0, 70.0])
    np.testing.assert_array_equal(rot.matrix, -np.eye(2))


def test_rectangle_half_turn_two_mirrors_and_low_quarter_turn() -> None:
    p = outer(rectangle_mask())
    syms = detect_symmetry(p)
    assert [s.kind for s in syms].count("mirror") == 2
    assert [(s.kind, s.order) for s in by_kind(syms, "rotation")] == [("rotation", 2)]
    assert all(s.iou == 1.0 for s in syms)
    assert {tuple(m.axis) for m in by_kind(syms, "mirror")} == {(1.0, 0.0), (0.0, 1.0)}
    for s in syms:
        np.testing.assert_array_equal(s.center, [65.0, 45.0])
    # Quarter turn of a 100 x 50 rectangle: IoU = 50^2 / (2 * 5000 - 50^2) = 1/3.
    quarter = [s for s in detect_symmetry(p, iou_min=0.01) if s.order == 4]
    assert len(quarter) == 1 and quarter[0].iou == pytest.approx(1.0 / 3.0, abs=1e-12)


def test_tilted_rectangle_axes_not_snapped() -> None:
    poly = np.array([[-50.0, -25.0], [50.0, -25.0], [50.0, 25.0], [-50.0, 25.0]])
    t = np.radians(20.0)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    mask = polygon_mask(poly @ rot.T + [80.2, 70.7], 140, 160)
    mirrors = by_kind(detect_symmetry(outer(mask)), "mirror")
    assert len(mirrors) == 2
    angles = sorted(axis_deg(m) for m in mirrors)
    assert angle_diff_deg(angles[0], 20.0) < 0.5 and angle_diff_deg(angles[1], 110.0) < 0.5


def test_tiny_loops_return_nothing() -> None:
    m = np.zeros((10, 10), dtype=bool)
    m[3:6, 3:6] = True  # 12 vertices
    assert detect_symmetry(outer(m)) == []
    m = np.zeros((10, 40), dtype=bool)
    m[4, 3:13] = True  # 22 vertices, 10 px
    assert detect_symmetry(outer(m)) == []


def test_symmetry_apply_and_offset_agree() -> None:
    (m,) = detect_symmetry(outer(heart_mask()))
    x = np.array([[1.0, 2.0], [70.0, 40.0]])
    np.testing.assert_allclose(m.apply(x), (x - m.center) @ m.matrix.T + m.center)
    np.testing.assert_allclose(m.apply(x), x @ m.matrix.T + m.offset)
    np.testing.assert_allclose(m.apply(m.apply(x)), x)
    assert m.saving == 0.5
    with pytest.raises(ValueError):
        m.matrix[0, 0] = 2.0  # frozen, read-only


# ----------------------------------------------------------------------------- splits


@pytest.mark.parametrize(
    ("make", "order"), [(star_mask, 5), (gear_mask, 6), (s_mask, 2), (rectangle_mask, 2)]
)
def test_rotation_split_maps_run_onto_next_run(
    make: Callable[[], NDArray[np.bool_]], order: int
) -> None:
    p = outer(make())
    n = len(p)
    sym = next(s for s in detect_symmetry(p) if s.kind == "rotation")
    assert sym.order == order
    i0, i1 = fundamental_split(p, sym)
    assert abs((i1 - i0) % n - n / order) <= 0.1 * n / order
    assert np.linalg.norm(sym.apply(p[i0]) - p[i1]) < 1.0
    assert rotation_split_error(p, sym, i0, i1) < _STAIRCASE
    # Applying the map j times walks the loop forward part by part.
    start = p[i0]
    for j in range(1, order):
        start = sym.apply(start)
        expect = (i0 + j * n / order) % n
        k = int(np.argmin(np.linalg.norm(p - start, axis=1)))
        assert min(abs(k - expect), n - abs(k - expect)) <= 0.1 * n / order


def test_rotation_direction_contract_and_reversed_loop() -> None:
    p = outer(star_mask())
    sym = detect_symmetry(p)[0]
    assert sym.angle > 0  # outer loops (positive shoelace area) turn by +2 pi / k
    with pytest.raises(InputError, match="inverse"):
        fundamental_split(p, sym.inverse())
    # The reversed loop gets the opposite rotation and the same contract.
    q = p[::-1].copy()
    rsym = detect_symmetry(q)[0]
    assert rsym.order == 5 and rsym.angle < 0
    i0, i1 = fundamental_split(q, rsym)
    assert rotation_split_error(q, rsym, i0, i1) < _STAIRCASE


def test_hole_loop_rotation_split() -> None:
    # A disc with a gear-shaped hole: the hole loop has negative area (runs the other way).
    disc = radial_mask(lambda a: 95.0 + 0.0 * a)
    mask = disc & ~gear_mask()
    hole = next(lp for lp in trace_loops(mask) if lp.is_hole)
    p = np.array(hole.points)
    sym = detect_symmetry(p)[0]
    assert sym.kind == "rotation" and sym.order == 6 and sym.angle < 0
    i0, i1 = fundamental_split(p, sym)
    assert abs((i1 - i0) % len(p) - len(p) / 6) <= 0.1 * len(p) / 6
    assert rotation_split_error(p, sym, i0, i1) < _STAIRCASE


@pytest.mark.parametrize("make", [heart_mask, ellipse_mask, star_mask, rectangle_mask])
def test_mirror_split_halves_loop_on_axis(make: Callable[[], NDArray[np.bool_]]) -> None:
    p = outer(make())
    n = len(p)
    for sym in by_kind(detect_symmetry(p), "mirror"):
        i0, i1 = fundamental_split(p, sym)
        nrm = np.array([-sym.axis[1], sym.axis[0]])
        dist = (p - sym.center) @ nrm
        # Crossing vertices: the positive end of a unit step across the axis.
        assert 0.0 <= dist[i0] <= 1.0 and 0.0 <= dist[i1] <= 1.0
        run = run_indices(i0, i1, n)
        assert np.all(dist[run] >= 0.0)  # the positive side
        assert abs(len(run) - n / 2) <= 0.1 * n / 2
        rest = run_indices(i1, i0, n)
        err = polyline_distance(p[rest], sym.apply(p[run]))
        grid = sym.iou == 1.0
        assert err.max() <= (1e-9 if grid else _STAIRCASE)


@pytest.mark.parametrize(("make", "on_axis"), [(heart_mask, True), (star_mask, False)])
def test_exact_mirror_split_vertex_for_vertex(
    make: Callable[[], NDArray[np.bool_]], on_axis: bool
) -> None:
    p = outer(make())
    n = len(p)
    sym = by_kind(detect_symmetry(p), "mirror")[0]
    assert sym.iou == 1.0
    i0, i1 = fundamental_split(p, sym)
    x_axis = sym.center[0]
    if on_axis:  # heart: x = 75 is a pixel line, the loop has vertices on it
        assert p[i0][0] == p[i1][0] == x_axis == 75.0
        run = run_indices(i0, i1, n)
        np.testing.assert_array_equal(sym.apply(p[run])[::-1], p[run_indices(i1, i0, n)])
        j = len(run) // 3
        np.testing.assert_array_equal(sym.apply(p[(i0 + j) % n]), p[(i0 - j) % n])
    else:  # star: x = 100.5 runs through pixel centres, the ends sit half a pixel off it
        assert abs(p[i0][0] - x_axis) == abs(p[i1][0] - x_axis) == 0.5
        run = run_indices(i0, i1, n)
        outside = run_indices(i1 + 1, i0 - 1, n)
        np.testing.assert_array_equal(sym.apply(p[run])[::-1], p[outside])


def test_corners_eq_3_2_and_split_at_corner() -> None:
    p = outer(star_mask())
    c = 100.5
    ang = -np.pi / 2 + np.arange(10) * np.pi / 5
    rad = np.where(np.arange(10) % 2 == 0, 80.0, 34.0)
    tips = np.column_stack([c + rad * np.cos(ang), c + rad * np.sin(ang)])
    corners = np.sort(cKDTree(p).query(tips)[1])
    sym = detect_symmetry(p, corners=corners)[0]
    assert sym.kind == "rotation" and sym.order == 5
    assert abs(np.degrees(sym.angle) - 72.0) < 0.5
    i0, i1 = fundamental_split(p, sym, corners=corners)
    assert i0 in corners and i1 in corners
    assert rotation_split_error(p, sym, i0, i1) < _STAIRCASE


def test_large_loop() -> None:
    p = outer(gear_mask(scale=3.2))
    assert len(p) > 2000
    syms = detect_symmetry(p)
    assert syms[0].kind == "rotation" and syms[0].order == 6 and syms[0].iou > 0.99
    assert len(by_kind(syms, "mirror")) == 6
    i0, i1 = fundamental_split(p, syms[0])
    assert rotation_split_error(p, syms[0], i0, i1) < _STAIRCASE


def test_bad_inputs() -> None:
    p = outer(heart_mask())
    with pytest.raises(InputError):
        detect_symmetry(p, iou_min=1.5)
    with pytest.raises(InputError):
        detect_symmetry(p, max_order=1)
    with pytest.raises(InputError):
        detect_symmetry(p, corners=[0, len(p)])
    with pytest.raises(InputError):
        detect_symmetry(np.full((20, 2), np.nan))
