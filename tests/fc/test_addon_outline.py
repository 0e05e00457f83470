"""The workbench's image feature in real FreeCAD (freecadcmd): closed constrained sketch
within the tolerance of the image outline, padded to a valid solid, scale from a known
length, other planes, export through the project's writers."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageDraw
from scipy.spatial import cKDTree

from pde2cad.image.contours import trace_loops
from pde2cad.image.raster import read_image

TOL = 1.0


def _drawn_part(path: Path) -> Path:
    """A part outline nobody tuned for: a rotated slotted plate with a round hole and a
    chamfered corner, drawn with PIL at 300 x 220 px."""
    im = Image.new("L", (300, 220), 255)
    d = ImageDraw.Draw(im)
    c, s = np.cos(0.3), np.sin(0.3)
    outline = [(-110, -60), (90, -60), (110, -40), (110, 60), (-110, 60)]
    d.polygon([(150 + c * x - s * y, 110 + s * x + c * y) for x, y in outline], fill=0)
    d.ellipse((120, 80, 170, 130), fill=255)
    d.rounded_rectangle((40, 100, 100, 120), radius=10, fill=255)
    im.save(path)
    return path


def _images(tmp_path: Path) -> list[Path]:
    images = [_drawn_part(tmp_path / "plate.png")]
    spec = importlib.util.find_spec("matplotlib")
    if spec is not None and spec.origin is not None:
        icon = Path(spec.origin).parent / "mpl-data" / "images" / "move_large.png"
        if icon.is_file():
            images.append(icon)  # an icon matplotlib ships: straight runs and curves
    return images


def _boundary(path: Path) -> np.ndarray:
    """The pixel-boundary loops of the image, sampled every 0.05 px, (M, 2) pixels."""
    out = []
    for loop in trace_loops(read_image(path)):
        p = np.asarray(loop.points, dtype=float)
        q = np.roll(p, -1, axis=0)
        t = np.linspace(0, 1, 20, endpoint=False)
        out.append((p[:, None] + (q - p)[:, None] * t[None, :, None]).reshape(-1, 2))
    return np.vstack(out)


OUTLINE_SCRIPT = """
    import FreeCAD, Part, PartDesign
    from freecad.pde2cad import api
    doc = FreeCAD.newDocument("outline")
    res = []
    for k, image in enumerate(ARGS["images"]):
        o = api.make_outline(doc, image, tolerance=ARGS["tol"], known_length=ARGS["known"], name=f"Outline{k}")
        sk = doc.getObject(o.SketchName)
        s = o.Scale
        samples = []
        for g in sk.Geometry:
            for p in g.toShape().discretize(400):
                samples.append([p.x / s, ARGS["height"][k] - p.y / s])
        ends = [[g.StartPoint.x, g.StartPoint.y, g.EndPoint.x, g.EndPoint.y] for g in sk.Geometry]
        kinds = sorted({type(g).__name__ for g in sk.Geometry})
        cons = {}
        for c in sk.Constraints:
            cons[c.Type] = cons.get(c.Type, 0) + 1
        faces_area = o.Shape.Area
        body = doc.addObject("PartDesign::Body", f"Body{k}")
        body.addObject(sk)
        pad = body.newObject("PartDesign::Pad", f"Pad{k}")
        pad.Profile = sk
        pad.Length = 3.0
        doc.recompute()
        ext = o.Shape.extrude(FreeCAD.Vector(0, 0, 3.0))
        res.append({"valid": o.isValid(), "shape_valid": o.Shape.isValid(), "scale": s,
                    "sketch_valid": sk.isValid(), "solve": sk.solve(), "wires": [w.isClosed() for w in sk.Shape.Wires],
                    "loops": o.Loops, "curves": o.Curves, "max_error": o.MaxError, "geometry": len(sk.Geometry),
                    "kinds": kinds, "constraints": cons, "ends": ends, "samples": samples,
                    "area": faces_area, "pad": [pad.isValid(), pad.Shape.isValid(), len(pad.Shape.Solids), pad.Shape.Volume],
                    "extrude": [ext.isValid(), ext.Volume], "status": o.Status})
    out["res"] = res
    xz = api.make_outline(doc, ARGS["images"][0], mm_per_px=0.5, plane="XZ", sketch=False, name="OnXZ")
    box = xz.Shape.BoundBox
    out["xz"] = [xz.isValid(), box.YLength, box.XLength, box.ZLength, xz.SketchName]
    out["dxf"] = str(api.export([doc.getObject("Outline0")], ARGS["dxf"]))
    out["svg"] = str(api.export([doc.getObject("Outline0")], ARGS["svg"]))
"""


KNOWN = [(10.0, 20.0), (130.0, 70.0), 65.0]  # 130 px apart, 65 mm: 0.5 mm/px


@pytest.fixture(scope="module")
def outlines(freecad_module) -> tuple[list[Path], dict]:  # noqa: ANN001
    """One FreeCAD run over the test images: (images, measured results)."""
    images = _images(freecad_module.tmp)
    heights = [Image.open(p).size[1] for p in images]
    out = freecad_module(OUTLINE_SCRIPT, images=[str(p) for p in images], tol=TOL, known=KNOWN,
                         height=heights, dxf=str(freecad_module.tmp / "plate.dxf"),
                         svg=str(freecad_module.tmp / "plate.svg"))
    return images, out


def test_sketch_closed_within_tolerance(outlines) -> None:  # noqa: ANN001
    """Per image: the feature and its sketch are valid, the solver is clean, every loop is
    closed (each piece's end is the next one's start, the last returns to the first), every
    joint carries one constraint (Tangent at G1 joins, else Coincident), the sketch lies
    within the tolerance of the pixel boundary both ways; the scale comes from a known
    length; on the XZ plane the outline has no y extent."""
    images, out = outlines
    for image, r in zip(images, out["res"]):
        name = image.name
        assert r["valid"] and r["shape_valid"] and r["sketch_valid"], (name, r["status"])
        assert r["solve"] == 0 and r["wires"] and all(r["wires"]), name
        assert r["scale"] == pytest.approx(0.5, rel=1e-12)
        # One piece per Bézier (a Bézier looping on itself becomes two).
        assert r["geometry"] >= r["curves"] and r["max_error"] <= TOL
        assert set(r["kinds"]) <= {"LineSegment", "BSplineCurve"}
        assert sum(r["constraints"].values()) == r["geometry"]  # one per joint
        assert set(r["constraints"]) <= {"Coincident", "Tangent"}
        ends = np.asarray(r["ends"])
        # Every end point is some piece's start point (the loops close, no loose end).
        assert cKDTree(ends[:, :2]).query(ends[:, 2:])[0].max() <= 1e-9, name
        sketch_px = np.asarray(r["samples"])
        boundary = _boundary(image)
        to_sketch = cKDTree(sketch_px).query(boundary)[0]
        to_boundary = cKDTree(boundary).query(sketch_px)[0]
        assert to_sketch.max() <= TOL + 0.05, (name, to_sketch.max())
        assert to_boundary.max() <= TOL + 0.05, (name, to_boundary.max())
        assert r["extrude"][0] and r["extrude"][1] == pytest.approx(3.0 * r["area"], rel=1e-6)
    plate = out["res"][0]
    assert plate["loops"] == 3  # one shape, two holes
    pixels = int(read_image(images[0]).sum())
    assert plate["area"] == pytest.approx(0.25 * pixels, rel=0.01)  # 0.25 mm^2 per pixel
    valid, y_extent, x_extent, z_extent, sketch_name = out["xz"]
    assert valid and y_extent == pytest.approx(0.0, abs=1e-9) and x_extent > 100 and z_extent > 50
    assert sketch_name == ""


@pytest.mark.parametrize("index", [0, 1])
def test_sketch_pads_to_a_valid_solid(outlines, index: int) -> None:  # noqa: ANN001
    """PartDesign Pad of the sketch: one valid solid of the face area times the length."""
    images, out = outlines
    if index >= len(out["res"]):
        pytest.skip("matplotlib (which ships the second image) is not installed")
    r = out["res"][index]
    valid, shape_valid, solids, volume = r["pad"]
    assert valid and shape_valid and solids == 1, images[index].name
    assert volume == pytest.approx(3.0 * r["area"], rel=1e-6)


def test_export_writes_the_project_dxf_and_svg(freecad, tmp_path: Path) -> None:  # noqa: ANN001
    """DXF and SVG of an outline feature are the project's writers' files (DXF read back by
    ezdxf: one SPLINE per loop, millimetres); STEP/IGES of a surface feature read back by
    FreeCAD as the same solid."""
    image = _drawn_part(tmp_path / "plate.png")
    cloud = Path(__file__).resolve().parents[2] / "examples" / "clouds" / "sphere6.ply"
    out = freecad("""
        import FreeCAD, Part
        from freecad.pde2cad import api
        doc = FreeCAD.newDocument("export")
        o = api.make_outline(doc, ARGS["image"], dpi=254, sketch=False)
        out["dxf"] = str(api.export([o], ARGS["dxf"]))
        api.export([o], ARGS["svg"])
        s = api.make_surface(doc, ARGS["cloud"], labels="scalar_label", continuity="c1")
        res = {}
        for suffix in ("step", "igs"):
            path = ARGS["base"] + "." + suffix
            api.export([s], path)
            back = Part.read(path)
            res[suffix] = [back.isValid(), len(back.Faces), len(back.Solids), back.Volume if back.Solids else 0.0]
        out["cad"], out["volume"], out["loops"] = res, s.Shape.Volume, o.Loops
        try:
            api.export([o], ARGS["base"] + ".step")
        except Exception as exc:
            out["wrong_kind"] = f"{type(exc).__name__}: {exc}"
    """, image=str(image), cloud=str(cloud), dxf=str(tmp_path / "plate.dxf"),
        svg=str(tmp_path / "plate.svg"), base=str(tmp_path / "sphere"))
    assert out["cad"]["step"][:3] == [True, 6, 1]
    assert out["cad"]["step"][3] == pytest.approx(out["volume"], rel=1e-9)
    assert out["cad"]["igs"][0] and out["cad"]["igs"][1] == 6
    assert out["wrong_kind"].startswith("InputError") and "select surface features" in out["wrong_kind"]
    assert not (tmp_path / "sphere.step").exists() or out["cad"]["step"][1] == 6
    svg = (tmp_path / "plate.svg").read_text()
    assert svg.startswith("<?xml") or "<svg" in svg[:200]
    ezdxf = pytest.importorskip("ezdxf")
    doc = ezdxf.readfile(tmp_path / "plate.dxf")
    assert doc.header["$INSUNITS"] == 4  # mm: 254 dpi is 0.1 mm per pixel
    # The project's DXF writer: one SPLINE per corner-to-corner run of a curved loop, one
    # closed LWPOLYLINE per loop of straight lines only; the plate's 3 loops are all there.
    msp = doc.modelspace()
    polylines = msp.query("LWPOLYLINE")
    assert out["loops"] == 3 and all(p.closed for p in polylines)
    assert len(polylines) + (len(msp.query("SPLINE")) > 0) <= 3 <= len(polylines) + len(msp.query("SPLINE"))


def test_untangle_cuts_fishtails_and_self_loops(freecad) -> None:  # noqa: ANN001
    """Synthetic tangles of the kind the fit leaves within tolerance: two curves that
    overshoot a square's corner and cross (also within the last sample span, where only the
    magnified search sees it), and a cubic that loops on itself. Untangled, each
    loop makes a valid face; the cut moves the outline by less than the overshoot."""
    out = freecad("""
        import numpy as np, Part
        from pde2cad.fc.outline import crossing, loop_wire, untangle
        fish = np.array([
            [[0, 0], [3, 0], [10.8, -0.3], [10, 0]],
            [[10, 0], [10.3, -0.8], [10, 7], [10, 10]],
            [[10, 10], [7, 10], [3, 10], [0, 10]],
            [[0, 10], [0, 7], [0, 3], [0, 0]]], dtype=float)
        # The same corner on a 1 m square: the crossing falls inside the last sample span.
        cusp = fish * 100.0
        cusp[0, 2], cusp[1, 1] = [1000.8, -0.3], [1000.3, -0.8]
        out["zoom"] = [crossing(cusp[0], cusp[1], zoom=0) is None, crossing(cusp[0], cusp[1]) is not None]
        loop = np.array([
            [[0, 0], [4, 2], [-1, 2], [3, 0]],
            [[3, 0], [2, -3], [1, -3], [0, 0]]], dtype=float)
        res = {}
        for name, c in (("fish", fish), ("loop", loop)):
            u = untangle(c)
            res[name] = [Part.Face(loop_wire(c)).isValid(), Part.Face(loop_wire(u)).isValid(),
                         len(c), len(u), float(np.abs(u[:, 0] - np.roll(u[:, 3], 1, axis=0)).max())]
        out["res"] = res
    """)
    for name, (before, after, n_before, n_after, gap) in out["res"].items():
        assert not before and after, name
        assert gap == 0.0  # joints exact
    assert out["res"]["fish"][3] == 4 and out["res"]["loop"][3] == 3
    assert out["zoom"] == [True, True]


def test_outline_persists(freecad, tmp_path: Path) -> None:  # noqa: ANN001
    """Saved and reopened in a fresh process, the outline feature and its sketch keep their
    geometry, and a recompute (with an edited tolerance and back) gives it again."""
    image = _drawn_part(tmp_path / "plate.png")
    doc_path = tmp_path / "outline.FCStd"
    first = freecad("""
        import FreeCAD
        from freecad.pde2cad import api
        doc = FreeCAD.newDocument("keep")
        o = api.make_outline(doc, ARGS["image"], dpi=100, plane="YZ")
        sk = doc.getObject(o.SketchName)
        out["r"] = [o.Shape.Area, len(o.Shape.Edges), len(sk.Geometry), sk.Shape.Length]
        doc.saveAs(ARGS["doc"])
    """, image=str(image), doc=str(doc_path))
    again = freecad("""
        import FreeCAD
        doc = FreeCAD.openDocument(ARGS["doc"])
        o = doc.getObject("Outline")
        sk = doc.getObject(o.SketchName)
        out["restored"] = [o.Shape.Area, len(o.Shape.Edges), len(sk.Geometry), sk.Shape.Length]
        o.Tolerance = 3.0
        doc.recompute()
        out["coarse"] = len(sk.Geometry)
        o.Tolerance = 1.0
        doc.recompute()
        doc.recompute()
        out["recomputed"] = [o.Shape.Area, len(o.Shape.Edges), len(sk.Geometry), sk.Shape.Length,
                             o.isValid(), sk.isValid(), o.Shape.BoundBox.XLength]
    """, doc=str(doc_path))
    area, edges, pieces, length = first["r"]
    for got in (again["restored"], again["recomputed"][:4]):
        assert got[1:3] == [edges, pieces]
        assert got[0] == pytest.approx(area, rel=1e-9) and got[3] == pytest.approx(length, rel=1e-9)
    assert again["coarse"] < pieces  # the edit recomputed (fewer curves at 3 px)
    assert again["recomputed"][4:6] == [True, True]
    assert again["recomputed"][6] == pytest.approx(0.0, abs=1e-9)  # on the YZ plane
