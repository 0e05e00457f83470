"""Bad input inside FreeCAD: every case ends as an invalid feature with the reason in its
Status and in the Report view (console), and the script goes on (no exception escapes)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_bad_input_marks_the_feature_invalid(freecad, tmp_path: Path) -> None:  # noqa: ANN001
    not_image = tmp_path / "notes.png"
    not_image.write_text("this is not an image")
    ply = ROOT / "examples" / "clouds" / "sphere6.ply"
    out = freecad("""
        import FreeCAD, Part, Points
        from freecad.pde2cad import api
        doc = FreeCAD.newDocument("bad")
        box = doc.addObject("Part::Box", "Box")
        scan = doc.addObject("Points::Feature", "Scan")
        scan.Points = Points.Points([FreeCAD.Vector(i, i * i, 0) for i in range(50)])
        cases = {
            "no_labels": lambda: api.make_surface(doc, ARGS["ply"]),
            "missing_file": lambda: api.make_surface(doc, ARGS["missing"], labels="scalar_label"),
            "wrong_type": lambda: api.make_surface(doc, box, labels="Labels"),
            "missing_property": lambda: api.make_surface(doc, scan, labels="Labels"),
            "label_count": lambda: api.make_surface(doc, ARGS["ply"], labels=[0, 1, 2]),
            "unreadable_image": lambda: api.make_outline(doc, ARGS["not_image"]),
            "missing_image": lambda: api.make_outline(doc, ARGS["missing"] + ".png"),
            "zero_length": lambda: api.make_outline(doc, ARGS["image"], known_length=[(5, 5), (5, 5), 10]),
        }
        res = {}
        for name, make in cases.items():
            obj = make()
            res[name] = [obj.isValid(), obj.Shape.isNull(), obj.Status, obj.State]
        out["res"] = res
        try:
            api.export([box], ARGS["missing"] + ".step")
            out["export"] = "no error"
        except Exception as exc:
            out["export"] = f"{type(exc).__name__}: {exc}"
        out["after"] = api.make_surface(doc, ARGS["ply"], labels="scalar_label", continuity="c0",
                                        terms=4).isValid()
    """, ply=str(ply), missing=str(tmp_path / "absent.xyz"), not_image=str(not_image),
        image=str(ROOT / "examples" / "images" / "glyph_B.png"))
    expected = {
        "no_labels": "no segment labels",
        "missing_file": "does not exist",
        "wrong_type": "select a Points or Mesh object",
        "missing_property": "has no property 'Labels'",
        "label_count": "LabelValues",
        "unreadable_image": "notes.png",
        "missing_image": "absent.xyz.png",
        "zero_length": "two different image points",
    }
    for name, words in expected.items():
        valid, null, status, state = out["res"][name]
        assert not valid and null and "Invalid" in state, name
        assert status.startswith("failed: ") and words in status, (name, status)
        assert words in freecad.last_output, name  # the Report view got the message
    assert out["export"].startswith("InputError") and "select surface features" in out["export"]
    assert out["after"]  # the session still works after all that
