"""DXF that CAM software and LibreCAD take as it is: crisp corners under even parameter
sampling, orientation, extents, R12/R2000, kerf offset by an exact distance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

ezdxf = pytest.importorskip("ezdxf")
pytest.importorskip("shapely")
from ezdxf.math import bulge_to_arc  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from pde2cad.curves.bezier import evaluate  # noqa: E402
from pde2cad.image.drawing import Drawing, OutlineLoop  # noqa: E402
from pde2cad.image.evaluate import boundary_samples  # noqa: E402
from pde2cad.image.vectorize import vectorize  # noqa: E402
from pde2cad.io.dxf import _signed_area, spline_data, write_dxf  # noqa: E402

from drawing_shapes import square_curves  # noqa: E402
from test_dxf import bulge_path, make_drawing, polyline_distance, read_clean  # noqa: E402


# ----------------------------------------------------------------- LibreCAD's rendering
def librecad_points(cps: NDArray[np.float64], knots: NDArray[np.float64], segs: int = 8
                    ) -> NDArray[np.float64]:
    """The polyline LibreCAD 2.2 draws for a degree-3 SPLINE (RS_Spline::update/rbspline):
    ``$SPLINESEGS x n_control_points`` points evenly spaced in parameter over the whole
    knot range, the basis from Cox-de Boor with half-open spans and the last point picked
    up at the end (librecad/src/lib/engine/rs_spline.cpp)."""
    npts, k = len(cps), 4
    x = np.asarray(knots, dtype=float)
    p1 = segs * npts
    t = x[0] + (x[-1] - x[0]) / (p1 - 1) * np.arange(p1)
    t = np.where(x[-1] - t < 5e-6, x[-1], t)
    temp = ((t[:, None] >= x[None, :-1]) & (t[:, None] < x[None, 1:])).astype(float)
    for order in range(2, k + 1):
        for i in range(npts + k - order):
            den_a, den_b = x[i + order - 1] - x[i], x[i + order] - x[i + 1]
            a = np.where(temp[:, i] != 0, (t - x[i]) * temp[:, i] / (den_a or 1.0), 0.0)
            b = np.where(temp[:, i + 1] != 0, (x[i + order] - t) * temp[:, i + 1] / (den_b or 1.0), 0.0)
            temp[:, i] = a + b
    temp[t >= x[-1], npts - 1] = 1.0
    return temp[:, :npts] @ cps


def render_splines(doc, segs: int = 8) -> list[NDArray[np.float64]]:  # noqa: ANN001
    return [librecad_points(np.array(sp.control_points)[:, :2], np.array(sp.knots), segs)
            for sp in doc.modelspace().query("SPLINE")]


def densify(polylines: list[NDArray[np.float64]], step: float) -> NDArray[np.float64]:
    out = []
    for pl in polylines:
        for a, b in zip(pl[:-1], pl[1:]):
            n = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
            out.append(a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:-1, None])
        out.append(pl[-1:])
    return np.concatenate(out)


def glyph_mask(char: str, size: int, angle: float) -> NDArray[np.bool_]:
    """A glyph of Pillow's bundled scalable font, rotated off the grid."""
    img = Image.new("L", (2 * size, 2 * size), 255)
    ImageDraw.Draw(img).text((size // 3, size // 4), char, fill=0,
                             font=ImageFont.load_default(size=size))
    return np.asarray(img.rotate(angle, fillcolor=255)) < 128


def star_mask(points: int, size: int, angle: float) -> NDArray[np.bool_]:
    img = Image.new("L", (size, size), 255)
    a = angle + np.arange(2 * points) * np.pi / points
    r = np.where(np.arange(2 * points) % 2 == 0, 0.45, 0.18) * size
    c = size / 2 + 0.37
    ImageDraw.Draw(img).polygon([tuple(v) for v in np.column_stack([c + r * np.cos(a), c + r * np.sin(a)])], fill=0)
    return np.asarray(img) < 128


IMAGES = {
    "glyph B": lambda: glyph_mask("B", 140, 7.0),
    "glyph &": lambda: glyph_mask("&", 110, -3.0),
    "star 5": lambda: star_mask(5, 220, 0.1),
    "star 7": lambda: star_mask(7, 300, -0.3),
}


def render_distances(path: Path, reference: NDArray[np.float64], height: int) -> tuple[float, float]:
    """Hausdorff distances (reference -> LibreCAD's polyline, polyline -> reference) in px;
    ``reference`` (n, 2) is dense points of the outline in the image frame."""
    doc = read_clean(path)
    rendered = [np.column_stack([pl[:, 0], height - pl[:, 1]]) for pl in render_splines(doc)]
    pts = densify(rendered, 0.05)
    return (float(cKDTree(pts).query(reference)[0].max()),
            float(cKDTree(reference).query(pts)[0].max()))


def curve_points(drawing: Drawing) -> NDArray[np.float64]:
    """Points at most 0.02 px apart along every Bézier of the drawing."""
    return densify([b for lp in drawing.loops for b in evaluate(lp.curves, np.linspace(0, 1, 200))],
                   0.02)


@pytest.mark.parametrize("name", sorted(IMAGES))
def test_librecad_rendering_stays_within_tolerance(tmp_path: Path, name: str) -> None:
    mask = IMAGES[name]()
    h = mask.shape[0]
    # (Finer tolerances take the vectorizer minutes on these images; 1 px is the default.)
    for tol in (1.0,):
        # As the CLI does for DXF: fit to 90 %, the even sampling gets the other 10 %.
        drawing = vectorize(mask, tolerance=0.9 * tol)
        assert sum(lp.corners for lp in drawing.loops) > 0
        out = tmp_path / "d.dxf"
        write_dxf(drawing, out)
        # What the DXF adds: LibreCAD's polyline within 10 % of the tolerance of the curves.
        to_render, from_render = render_distances(out, curve_points(drawing), h)
        assert max(to_render, from_render) <= 0.1 * tol * 0.9 + 0.025  # + densify steps
        if tol == 1.0:  # and the whole chain within the tolerance of the pixel boundary
            to_render, from_render = render_distances(out, boundary_samples(mask, step=0.05), h)
            assert to_render <= tol + 0.03
            assert from_render <= tol + 0.06  # chords of the boundary sampling sag outward


@pytest.mark.parametrize("name", ["star 5", "glyph &"])
def test_one_spline_per_loop_loses_corners_in_librecad(tmp_path: Path, name: str) -> None:
    """The regression: the old layout (one SPLINE per loop, corners on inner knots) drawn
    as LibreCAD draws it cuts corners by more than the tolerance the DXF may add."""
    mask = IMAGES[name]()
    drawing = vectorize(mask, tolerance=0.9)
    doc = ezdxf.new("R2010")
    h = mask.shape[0]
    for lp in drawing.loops:
        cps, knots = spline_data(lp.curves)
        sp = doc.modelspace().add_spline()
        sp.dxf.degree = 3
        sp.control_points = [(x, h - y, 0.0) for x, y in cps]
        sp.knots = knots
    doc.saveas(tmp_path / "old.dxf")
    to_render, _ = render_distances(tmp_path / "old.dxf", curve_points(drawing), h)
    assert to_render > 0.2  # corner tips of the curves far from the drawn polyline


# ----------------------------------------------------------------- orientation, extents
def wrong_way_drawing() -> Drawing:
    """An outer loop written clockwise (y up) with a hole written counter-clockwise."""
    dr = make_drawing(0.5)
    for lp in dr.loops:
        lp.curves = lp.curves[::-1, ::-1].copy()
    return dr


@pytest.mark.parametrize("curves", ["spline", "polyline", "arcs"])
@pytest.mark.parametrize("make", [make_drawing, wrong_way_drawing])
def test_outer_ccw_holes_cw_and_extents(tmp_path: Path, curves: str, make) -> None:  # noqa: ANN001
    dr = make()
    write_dxf(dr, tmp_path / "o.dxf", curves=curves)
    doc = read_clean(tmp_path / "o.dxf")
    msp = doc.modelspace()
    pts = []
    for layer, sign in (("OUTER", 1.0), ("HOLES", -1.0)):
        for e in msp.query(f'*[layer=="{layer}"]'):
            if e.dxftype() == "SPLINE":
                cps = np.array(e.control_points)[:, :2]
                bez = np.stack([cps[3 * i:3 * i + 4] for i in range((len(cps) - 1) // 3)])
                pts.append(np.concatenate([evaluate(b, np.linspace(0, 1, 201)) for b in bez]))
                continue
            assert e.closed
            verts = np.array(e.get_points("xyb"))
            samples, _ = bulge_path(verts)
            pts.append(samples)
            area = 0.5 * np.sum(samples[:, 0] * np.roll(samples[:, 1], -1)
                                - np.roll(samples[:, 0], -1) * samples[:, 1])
            assert np.sign(area) == sign
    if curves == "spline":  # a loop's runs together enclose its area with the right sign
        for lp in dr.loops:
            c = np.asarray(lp.curves)
            assert abs(_signed_area(c)) > 0
    allp = np.concatenate(pts)
    lo, hi = np.array(doc.header["$EXTMIN"])[:2], np.array(doc.header["$EXTMAX"])[:2]
    assert np.allclose(lo, allp.min(axis=0), atol=1e-3) and np.allclose(hi, allp.max(axis=0), atol=1e-3)
    assert np.all(np.abs(lo) < 1e6) and np.all(np.abs(hi) < 1e6)


def test_spline_runs_are_oriented(tmp_path: Path) -> None:
    dr = wrong_way_drawing()
    write_dxf(dr, tmp_path / "s.dxf")
    msp = read_clean(tmp_path / "s.dxf").modelspace()
    for layer, sign in (("OUTER", 1.0), ("HOLES", -1.0)):
        chain = []
        for sp in msp.query(f'SPLINE[layer=="{layer}"]'):
            cps = np.array(sp.control_points)[:, :2]
            chain.append(np.stack([cps[3 * i:3 * i + 4] for i in range((len(cps) - 1) // 3)]))
        if layer == "HOLES":
            assert np.sign(_signed_area(np.concatenate(chain))) == sign
        else:  # the square's 4 runs (entities 2..5 in writing order) enclose ccw
            assert np.sign(_signed_area(np.concatenate(chain[1:5]))) == sign


# ----------------------------------------------------------------- versions
@pytest.mark.parametrize("version, code", [("R12", "AC1009"), ("R2000", "AC1015"), ("R2010", "AC1024")])
@pytest.mark.parametrize("curves", ["spline", "polyline", "arcs"])
def test_every_version_is_audit_clean(tmp_path: Path, version: str, code: str, curves: str) -> None:
    dr = make_drawing(0.2)
    write_dxf(dr, tmp_path / "v.dxf", curves=curves, version=version)
    doc = read_clean(tmp_path / "v.dxf")
    assert doc.dxfversion == code
    types = {e.dxftype() for e in doc.modelspace()}
    if version == "R12":
        assert types == {"POLYLINE"}
        assert all(e.is_closed for e in doc.modelspace())
    elif curves == "spline":
        assert types == {"SPLINE"}
    else:
        assert types == {"LWPOLYLINE"}


def test_r12_arcs_within_tolerance(tmp_path: Path) -> None:
    dr = make_drawing(0.2)
    write_dxf(dr, tmp_path / "r12.dxf", version="R12")
    tol = 0.1 * dr.tolerance * 0.2
    polys = list(read_clean(tmp_path / "r12.dxf").modelspace().query("POLYLINE"))
    assert len(polys) == len(dr.loops)
    for pl, lp in zip(polys, [lp for shape in dr.shapes() for lp in shape]):
        verts = np.array([(v.dxf.location.x, v.dxf.location.y, v.dxf.bulge) for v in pl.vertices])
        samples, _ = bulge_path(verts)
        c = np.asarray(lp.curves) * [0.2, -0.2] + [0.0, dr.height * 0.2]
        dense = np.concatenate([evaluate(b, np.linspace(0, 1, 1001)) for b in c])
        closed = np.vstack([samples, samples[:1]])
        assert np.max(polyline_distance(dense, closed)) <= tol * 1.01
        assert np.max(polyline_distance(samples, dense)) <= tol * 1.01


# ----------------------------------------------------------------- kerf offset
def arc_radii(verts: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centres (m, 2) and radii (m,) of the arcs (non-zero bulges) of a closed bulge loop."""
    centers, radii = [], []
    for i in np.flatnonzero(verts[:, 2] != 0.0):
        c, _, _, r = bulge_to_arc(verts[i, :2], verts[(i + 1) % len(verts), :2], verts[i, 2])
        centers.append((c.x, c.y))
        radii.append(r)
    return np.array(centers), np.array(radii)


def fine_circle(cx: float, cy: float, r: float, k: int = 16) -> NDArray[np.float64]:
    """A circle as k cubic Béziers (radial error 1e-7 r for k = 16)."""
    a = 2 * np.pi * np.arange(k + 1) / k
    h = 4.0 / 3.0 * np.tan(np.pi / (2 * k))
    p = np.column_stack([np.cos(a), np.sin(a)])
    t = np.column_stack([-np.sin(a), np.cos(a)])
    return np.stack([np.stack([p[i], p[i] + h * t[i], p[i + 1] - h * t[i + 1], p[i + 1]])
                     for i in range(k)]) * r + [cx, cy]


@pytest.mark.parametrize("r, d", [(20.0, 1.5), (7.3, 0.25), (55.0, 4.0)])
@pytest.mark.parametrize("version", ["R12", "R2010"])
def test_offset_circle_radius_grows_by_exactly_d(tmp_path: Path, r: float, d: float, version: str) -> None:
    dr = Drawing(width=200, height=200, loops=[
        OutlineLoop(fine_circle(100.0, 90.0, r), is_hole=False, shape=0, depth=0),
        OutlineLoop(fine_circle(100.0, 90.0, r / 3.0)[::-1, ::-1], is_hole=True, shape=0, depth=1),
    ], tolerance=0.5)
    tol = 0.05
    write_dxf(dr, tmp_path / "k.dxf", offset=d, tolerance=tol, version=version)
    msp = read_clean(tmp_path / "k.dxf").modelspace()
    for layer, want in (("OUTER", r + d), ("HOLES", r / 3.0 - d)):
        (pl,) = msp.query(f'*[layer=="{layer}"]')
        verts = (np.array(pl.get_points("xyb")) if version != "R12" else
                 np.array([(v.dxf.location.x, v.dxf.location.y, v.dxf.bulge) for v in pl.vertices]))
        centers, radii = arc_radii(verts)
        assert np.all(verts[:, 2] != 0.0)  # arcs, not lines
        assert np.max(np.abs(radii - want)) <= tol
        assert np.max(np.hypot(*(centers - [100.0, 110.0]).T)) <= 2 * tol  # y flipped: 200 - 90
        samples, _ = bulge_path(verts)
        assert np.max(np.abs(np.hypot(*(samples - [100.0, 110.0]).T) - want)) <= tol


def test_offset_square_with_hole_and_a_hole_that_closes(tmp_path: Path) -> None:
    loops = [
        OutlineLoop(square_curves(20, 20, 120, 80), is_hole=False, shape=0, depth=0),
        OutlineLoop(square_curves(40, 40, 70, 60)[::-1, ::-1], is_hole=True, shape=0, depth=1),
        OutlineLoop(square_curves(90, 45, 93, 55)[::-1, ::-1], is_hole=True, shape=0, depth=1),
    ]
    dr = Drawing(width=150, height=100, loops=loops, tolerance=0.5)
    notes = write_dxf(dr, tmp_path / "k.dxf", offset=2.0, tolerance=0.01)
    assert notes == ["offset 2 closes 1 loop(s) of shape 0; left out"]
    msp = read_clean(tmp_path / "k.dxf").modelspace()
    (outer,) = msp.query('*[layer=="OUTER"]')
    (hole,) = msp.query('*[layer=="HOLES"]')
    o = np.array(outer.get_points("xyb"))
    samples, _ = bulge_path(o)
    # Straight sides moved out by exactly 2 (y flipped: y_dxf = 100 - y_px).
    assert samples[:, 0].min() == pytest.approx(18.0, abs=1e-9)
    assert samples[:, 0].max() == pytest.approx(122.0, abs=1e-9)
    assert samples[:, 1].min() == pytest.approx(18.0, abs=1e-9)
    assert samples[:, 1].max() == pytest.approx(82.0, abs=1e-9)
    _, radii = arc_radii(o)
    assert len(radii) == 4 and np.allclose(radii, 2.0, atol=0.01)  # round convex corners
    hv = np.array(hole.get_points("xyb"))
    assert np.all(hv[:, 2] == 0.0)  # the hole shrinks with sharp corners
    assert np.allclose(np.sort(np.unique(hv[:, 0])), [42.0, 68.0], atol=1e-9)
    assert np.allclose(np.sort(np.unique(hv[:, 1])), [42.0, 58.0], atol=1e-9)


@pytest.mark.parametrize("name, d", [("glyph &", 1.5), ("glyph B", -0.8), ("star 7", 4.0)])
def test_offset_of_vectorized_images_is_at_exactly_d(tmp_path: Path, name: str, d: float) -> None:
    """Every point of the offset outline is at distance |d| from the Bézier outline (the
    boundary of a Minkowski offset), within the tolerance."""
    mask = IMAGES[name]()
    drawing = vectorize(mask, tolerance=1.0)
    tol = 0.05
    notes = write_dxf(drawing, tmp_path / "k.dxf", offset=d, tolerance=tol)
    msp = read_clean(tmp_path / "k.dxf").modelspace()
    h = mask.shape[0]
    outline = curve_points(drawing) * [1.0, -1.0] + [0.0, h]  # DXF frame, y up
    pts = np.concatenate([bulge_path(np.array(pl.get_points("xyb")))[0]
                          for pl in msp.query("LWPOLYLINE")])
    dist = cKDTree(outline).query(pts)[0]
    assert np.max(np.abs(dist - abs(d))) <= tol + 0.02  # + the 0.02 px outline sampling
    n_out = len(msp.query('LWPOLYLINE[layer=="OUTER"]'))
    assert n_out >= 1 and (notes == [] or "closes" in notes[0])
