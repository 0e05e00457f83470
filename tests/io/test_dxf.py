"""DXF export: audit-clean R2010, units, layers, exact splines, polylines/arcs within tolerance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

ezdxf = pytest.importorskip("ezdxf")
from ezdxf.math import bulge_to_arc  # noqa: E402

from pde2cad.curves.bezier import evaluate  # noqa: E402
from pde2cad.errors import ExportError, InputError  # noqa: E402
from pde2cad.image.drawing import Drawing, OutlineLoop  # noqa: E402
from pde2cad.io.dxf import _signed_area, corner_joins, to_dxf_coords, write_dxf  # noqa: E402

from drawing_shapes import circle_curves, square_curves  # noqa: E402

_T = np.linspace(0.0, 1.0, 1001)




def blob_curves() -> NDArray[np.float64]:
    """A closed loop with an inflection (a bean shape), 3 cubics with a corner."""
    return np.array(
        [
            [[20.0, 100.0], [20.0, 60.0], [60.0, 80.0], [80.0, 60.0]],
            [[80.0, 60.0], [110.0, 30.0], [130.0, 120.0], [90.0, 130.0]],
            [[90.0, 130.0], [60.0, 140.0], [20.0, 140.0], [20.0, 100.0]],
        ]
    )


def make_drawing(mm_per_px: float | None = None) -> Drawing:
    """Three shapes: a circle, a square with a square hole, a bean with a corner."""
    loops = [
        OutlineLoop(circle_curves(30.0, 40.0, 20.0), is_hole=False, shape=0, depth=0),
        OutlineLoop(square_curves(60, 10, 180, 130), is_hole=False, shape=1, depth=0),
        OutlineLoop(square_curves(90, 40, 150, 100)[::-1, ::-1], is_hole=True, shape=1, depth=1),
        OutlineLoop(blob_curves() + [170.0, 0.0], is_hole=False, shape=2, depth=0),
    ]
    return Drawing(width=320, height=150, loops=loops, tolerance=0.5, mm_per_px=mm_per_px)


def read_clean(path: Path):  # noqa: ANN201 - ezdxf Drawing
    doc = ezdxf.readfile(path)
    auditor = doc.audit()
    assert not auditor.has_errors, [str(e.message) for e in auditor.errors]
    assert not auditor.has_fixes, [str(e.message) for e in auditor.fixes]
    return doc


def expected_loops(dr: Drawing) -> list[tuple[OutlineLoop, NDArray[np.float64]]]:
    """Loops in writing order (per shape, outer first) with control points in DXF coords."""
    s = dr.mm_per_px or 1.0
    return [(lp, to_dxf_coords(lp.curves, dr.height, s)) for shape in dr.shapes() for lp in shape]


def polyline_distance(pts: NDArray[np.float64], verts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance (n,) from points (n, 2) to the open polyline through ``verts`` (m, 2)."""
    a, d = verts[:-1], np.diff(verts, axis=0)
    dd = np.maximum(d[:, 0] ** 2 + d[:, 1] ** 2, 1e-300)
    out = np.empty(len(pts))
    for i in range(0, len(pts), 256):
        rx = pts[i : i + 256, 0, None] - a[:, 0]
        ry = pts[i : i + 256, 1, None] - a[:, 1]
        t = np.clip((rx * d[:, 0] + ry * d[:, 1]) / dd, 0.0, 1.0)
        gx, gy = rx - t * d[:, 0], ry - t * d[:, 1]
        out[i : i + 256] = np.sqrt(np.min(gx * gx + gy * gy, axis=1))
    return out


def bulge_path(verts: NDArray[np.float64]) -> tuple[NDArray[np.float64], list[tuple]]:
    """Dense points along a closed bulge polyline (x, y, bulge) and per-segment geometry.

    Returns the samples (m, 2) and, per segment, (start, end, start tangent, end tangent).
    The arc geometry comes from ezdxf's own ``bulge_to_arc`` (what CAD readers do).
    """
    pts, segs = [], []
    n = len(verts)
    for i in range(n):
        p0, p1, b = verts[i, :2], verts[(i + 1) % n, :2], verts[i, 2]
        chord = p1 - p0
        if b == 0.0:
            u = np.linspace(0.0, 1.0, 30)[:, None]
            pts.append(p0 + u * chord)
            t = chord / np.linalg.norm(chord)
            segs.append((p0, p1, t, t))
            continue
        center, a_start, a_end, r = bulge_to_arc(p0, p1, b)
        c = np.array([center.x, center.y])
        sweep = np.mod(a_end - a_start, 2 * np.pi)
        a = a_start + sweep * np.linspace(0.0, 1.0, 60)
        pts.append(c + r * np.stack([np.cos(a), np.sin(a)], axis=-1))
        assert np.hypot(*(p0 - c)) == pytest.approx(r, rel=1e-9)
        assert np.hypot(*(p1 - c)) == pytest.approx(r, rel=1e-9)
        # Travel direction: ccw for b > 0, cw for b < 0 (rotate the radius vector by +-90 deg).
        sgn = 1.0 if b > 0 else -1.0
        r0, r1 = (p0 - c) / r, (p1 - c) / r
        segs.append((p0, p1, sgn * np.array([-r0[1], r0[0]]), sgn * np.array([-r1[1], r1[0]])))
    return np.concatenate(pts), segs


# --------------------------------------------------------------------------- spline mode


@pytest.mark.parametrize("mm_per_px", [None, 25.4 / 300.0])
def test_spline_mode_one_spline_per_corner_run(tmp_path: Path, mm_per_px: float | None) -> None:
    dr = make_drawing(mm_per_px)
    out = tmp_path / "out.dxf"
    write_dxf(dr, out)
    doc = read_clean(out)
    assert doc.dxfversion == "AC1024"  # R2010
    splines = list(doc.modelspace().query("SPLINE"))
    # circle: no corner -> 1 run; square and its hole: 4 corners each; bean: 1 corner.
    assert [len(corner_joins(c)) for _, c in expected_loops(dr)] == [0, 4, 4, 1]
    assert len(splines) == 1 + 4 + 4 + 1
    it = iter(splines)
    for loop, c in expected_loops(dr):
        runs = [next(it) for _ in range(max(len(corner_joins(c)), 1))]
        area = 0.0
        for sp in runs:
            assert sp.dxf.layer == ("HOLES" if loop.is_hole else "OUTER")
            assert sp.dxf.degree == 3 and not sp.closed
            cps = np.array(sp.control_points)[:, :2]
            m = (len(cps) - 1) // 3
            assert list(sp.knots) == [0.0] * 4 + [float(i) for i in range(1, m) for _ in range(3)] + [
                float(m)
            ] * 4
            bez = np.stack([cps[3 * i : 3 * i + 4] for i in range(m)])
            area += _signed_area(bez)
            # ezdxf's evaluation is the Bézier chain, and lies on the original loop.
            tool = sp.construction_tool()
            got = np.array([tool.point(u) for u in np.linspace(0.0, m, 40 * m + 1)])[:, :2]
            want = np.concatenate([evaluate(b, np.linspace(0, 1, 41))[:-1] for b in bez] + [cps[-1:]])
            assert np.max(np.abs(got - want)) < 1e-9
            dense = np.concatenate([evaluate(b, _T) for b in c])
            assert np.max(polyline_distance(got, dense)) < 1e-3 * (mm_per_px or 1.0)
        # The runs tile the loop exactly: same enclosed area, ccw outside, cw for holes.
        assert area == pytest.approx(abs(_signed_area(c)) * (-1 if loop.is_hole else 1), rel=1e-12)
        # Run ends are the corners, in order, each shared by two runs.
        ends = np.array([np.array(sp.control_points)[[0, -1], :2] for sp in runs])
        assert np.allclose(ends[:, 1], np.roll(ends[:, 0], -1, axis=0), atol=1e-12, rtol=0)


def test_units_and_layers(tmp_path: Path) -> None:
    write_dxf(make_drawing(None), tmp_path / "px.dxf")
    write_dxf(make_drawing(0.1), tmp_path / "mm.dxf")
    px, mm = read_clean(tmp_path / "px.dxf"), read_clean(tmp_path / "mm.dxf")
    assert px.header["$INSUNITS"] == 0
    assert mm.header["$INSUNITS"] == 4
    assert mm.header["$MEASUREMENT"] == 1
    for doc in (px, mm):
        assert doc.layers.has_entry("OUTER") and doc.layers.has_entry("HOLES")
        assert doc.layers.get("OUTER").color != doc.layers.get("HOLES").color
        msp = doc.modelspace()
        assert len(msp.query('*[layer=="OUTER"]')) == 1 + 4 + 1  # one spline per run
        assert len(msp.query('*[layer=="HOLES"]')) == 4
    # y up and scaled: the circle's top (smallest pixel y = 20) is its largest DXF y.
    cps_mm = np.array(mm.modelspace().query("SPLINE")[0].control_points)
    assert np.max(cps_mm[:, 1]) == pytest.approx((150 - 20) * 0.1)
    assert np.max(cps_mm[:, 0]) == pytest.approx(50 * 0.1)


def test_drawing_method_writes_spline(tmp_path: Path) -> None:
    make_drawing().write_dxf(tmp_path / "d.dxf")
    assert len(read_clean(tmp_path / "d.dxf").modelspace().query("SPLINE")) == 10


# ------------------------------------------------------------------- polyline / arcs modes


@pytest.mark.parametrize("mm_per_px", [None, 0.2])
def test_polyline_mode_within_tolerance(tmp_path: Path, mm_per_px: float | None) -> None:
    dr = make_drawing(mm_per_px)
    out = tmp_path / "poly.dxf"
    write_dxf(dr, out, curves="polyline")
    doc = read_clean(out)
    polys = list(doc.modelspace().query("LWPOLYLINE"))
    exp = expected_loops(dr)
    assert len(polys) == len(exp)
    tol = 0.1 * dr.tolerance * (mm_per_px or 1.0)  # the documented default
    for pl, (loop, c) in zip(polys, exp):
        assert pl.closed
        assert pl.dxf.layer == ("HOLES" if loop.is_hole else "OUTER")
        verts = np.array(pl.get_points("xy"))
        closed = np.vstack([verts, verts[:1]])
        dense = np.concatenate([evaluate(b, _T) for b in c])
        assert np.max(polyline_distance(dense, closed)) <= tol + 1e-12
        # Every vertex lies on the curve, every chord midpoint within tol of it.
        assert np.max(polyline_distance(verts, dense)) < 1e-2 * tol  # dense-sampling sag only
        mids = 0.5 * (closed[:-1] + closed[1:])
        assert np.max(polyline_distance(mids, dense)) <= tol + 1e-6


def test_polyline_explicit_tolerance(tmp_path: Path) -> None:
    dr = make_drawing()
    write_dxf(dr, tmp_path / "a.dxf", curves="polyline", tolerance=1.0)
    write_dxf(dr, tmp_path / "b.dxf", curves="polyline", tolerance=0.01)
    n_coarse = len(read_clean(tmp_path / "a.dxf").modelspace().query("LWPOLYLINE")[0])
    n_fine = len(read_clean(tmp_path / "b.dxf").modelspace().query("LWPOLYLINE")[0])
    assert n_fine > n_coarse


@pytest.mark.parametrize("mm_per_px", [None, 0.2])
def test_arcs_mode_within_tolerance_and_g1(tmp_path: Path, mm_per_px: float | None) -> None:
    dr = make_drawing(mm_per_px)
    out = tmp_path / "arcs.dxf"
    write_dxf(dr, out, curves="arcs")
    doc = read_clean(out)
    polys = list(doc.modelspace().query("LWPOLYLINE"))
    exp = expected_loops(dr)
    assert len(polys) == len(exp)
    tol = 0.1 * dr.tolerance * (mm_per_px or 1.0)
    for pl, (loop, c) in zip(polys, exp):
        assert pl.closed
        verts = np.array(pl.get_points("xyb"))
        samples, segs = bulge_path(verts)
        dense = np.concatenate([evaluate(b, _T) for b in c])
        # Both directions of the Hausdorff distance.
        assert np.max(polyline_distance(dense, samples)) <= tol * 1.001
        assert np.max(polyline_distance(samples, dense)) <= tol * 1.001
        # G1 at every join except at the Bézier joins that are real corners.
        bez_starts = c[:, 0]
        corner_starts = [
            bez_starts[j]
            for j in range(len(c))
            if not np.allclose(
                (c[j - 1, 3] - c[j - 1, 2]) / np.linalg.norm(c[j - 1, 3] - c[j - 1, 2]),
                (c[j, 1] - c[j, 0]) / np.linalg.norm(c[j, 1] - c[j, 0]),
                atol=1e-9,
            )
        ]
        n_g1 = 0
        for i in range(len(segs)):
            _, _, _, t_end = segs[i - 1]
            p, _, t_start, _ = segs[i]
            if any(np.allclose(p, q, atol=1e-12) for q in corner_starts):
                continue
            assert float(t_end @ t_start) > 1.0 - 1e-9
            n_g1 += 1
        assert n_g1 >= len(segs) - len(corner_starts)
    # The circle (radius 20 px) at tolerance 0.05 px: 2 arcs per quarter Bézier.
    circle = np.array(polys[0].get_points("xyb"))
    assert len(circle) == 8 and np.all(circle[:, 2] != 0.0)


def test_arcs_square_is_lines(tmp_path: Path) -> None:
    write_dxf(make_drawing(), tmp_path / "a.dxf", curves="arcs")
    polys = list(read_clean(tmp_path / "a.dxf").modelspace().query("LWPOLYLINE"))
    square, hole = np.array(polys[1].get_points("xyb")), np.array(polys[2].get_points("xyb"))
    assert len(square) == 4 and np.all(square[:, 2] == 0.0)
    assert len(hole) == 4 and polys[2].dxf.layer == "HOLES"


# ------------------------------------------------------------------------------- errors


def test_bad_mode_and_tolerance(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="curves must be one of"):
        write_dxf(make_drawing(), tmp_path / "x.dxf", curves="nurbs")
    with pytest.raises(InputError, match="tolerance"):
        write_dxf(make_drawing(), tmp_path / "x.dxf", curves="arcs", tolerance=-1.0)
    assert list(tmp_path.iterdir()) == []


def test_missing_folder_raises_export_error(tmp_path: Path) -> None:
    target = tmp_path / "missing" / "out.dxf"
    with pytest.raises(ExportError, match="does not exist"):
        write_dxf(make_drawing(), target)
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("exc", [RuntimeError("boom"), OSError("disk full")])
def test_failed_save_leaves_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exc: Exception
) -> None:
    import ezdxf.document

    target = tmp_path / "out.dxf"
    real_saveas = ezdxf.document.Drawing.saveas

    def half_write(self, filename, *args, **kwargs):  # noqa: ANN001, ANN202
        Path(filename).write_text("0\nSECTION\n", encoding="ascii")  # partial output
        raise exc

    monkeypatch.setattr(ezdxf.document.Drawing, "saveas", half_write)
    expected = ExportError if isinstance(exc, OSError) else RuntimeError
    with pytest.raises(expected):
        write_dxf(make_drawing(), target)
    assert list(tmp_path.iterdir()) == []

    # An existing file survives a failed overwrite.
    monkeypatch.setattr(ezdxf.document.Drawing, "saveas", real_saveas)
    write_dxf(make_drawing(), target)
    before = target.read_bytes()
    monkeypatch.setattr(ezdxf.document.Drawing, "saveas", half_write)
    with pytest.raises(expected):
        write_dxf(make_drawing(), target, curves="arcs")
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["out.dxf"]
