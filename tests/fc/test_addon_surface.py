"""The workbench's surface feature in real FreeCAD (freecadcmd): loading, recompute,
agreement with the Python API, property edits, persistence, mesh sources."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from pde2cad import samples

ROOT = Path(__file__).resolve().parents[2]
CUBE_STL = Path("/usr/share/freecad/Mod/OpenSCAD/OpenSCADTest/data/Cube.stl")


def _unseen_cloud(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A 6-patch sphere the project never fitted as such: noisy, rotated, scaled by 37 and
    moved far from the origin; stored as (N, 4) .npy with the label in column 4."""
    cloud = samples.sphere6(6000, noise=0.002, seed=11)
    a, b = 0.7, -0.4
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    pts = cloud.points @ (rx @ rz).T * 37.0 + np.array([100.0, -50.0, 20.0])
    np.save(path, np.column_stack([pts, cloud.labels]))
    return pts, cloud.labels


def test_addon_loads_without_errors(freecad) -> None:  # noqa: ANN001
    """FreeCAD's own start-up imports freecad.pde2cad (from the Mod symlink), which makes the
    core importable from the repository's src; package.xml reads as Addon Manager metadata;
    no OCP is loaded."""
    out = freecad("""
        import FreeCAD
        out["preloaded"] = "freecad.pde2cad" in sys.modules
        import pde2cad, freecad.pde2cad as addon
        from freecad.pde2cad import api
        out["core"] = pde2cad.__file__
        out["addon"] = addon.__file__
        meta = FreeCAD.Metadata(os.path.join(os.path.dirname(addon.__file__), "..", "..", "package.xml"))
        wb = meta.Content["workbench"][0]
        out["meta"] = [meta.Name, meta.Version, meta.License[0]["name"] if meta.License else None,
                       wb.Classname, meta.Icon, [d["package"] for d in wb.Depend]]
        out["icon_exists"] = os.path.isfile(addon.icon("pde2cad"))
        out["heavy"] = [m for m in ("OCP", "open3d", "matplotlib") if m in sys.modules]
    """)
    assert out["preloaded"]
    assert Path(out["core"]).resolve() == ROOT / "src" / "pde2cad" / "__init__.py"
    name, version, license_, classname, icon, depends = out["meta"]
    assert (name, version, license_, classname) == ("pde2cad", "0.1.0", "MIT", "Pde2CadWorkbench")
    assert icon.endswith(".svg") and out["icon_exists"]
    assert {"Part", "Sketcher", "numpy", "scipy"} <= set(depends)
    assert out["heavy"] == []
    assert "During initialization the error" not in freecad.last_output


def test_surface_feature_matches_api_edits_and_persists(freecad, tmp_path: Path) -> None:  # noqa: ANN001
    """A noisy, rotated, rescaled 6-patch sphere from a .npy file and from a Points object
    with a Labels property: both features are valid solids identical to fit_surfaces +
    build_shape run directly; switching Continuity recomputes (C0 kinks, C1 does not);
    saved and reopened in a fresh process, a recompute gives the same geometry to 1e-9."""
    npy = tmp_path / "sphere_unseen.npy"
    pts, labels = _unseen_cloud(npy)
    doc_path = tmp_path / "surface.FCStd"
    out = freecad("""
        import FreeCAD, Points, numpy as np
        from freecad.pde2cad import api
        from pde2cad.reconstruct import fit_surfaces
        from pde2cad.fc.shape import build_shape, continuity_figures
        doc = FreeCAD.newDocument("surf")
        f = api.make_surface(doc, ARGS["npy"], labels="column4", continuity="c1")
        def facts(o):
            return {"valid": o.isValid(), "shape_valid": o.Shape.isValid(), "type": o.Shape.ShapeType,
                    "faces": len(o.Shape.Faces), "volume": o.Shape.Volume, "area": o.Shape.Area,
                    "gap": o.MaxGap, "angle": o.MaxNormalAngle, "err": o.WorstPatchError,
                    "closed": o.Closed, "status": o.Status}
        out["file"] = facts(f)
        data = np.load(ARGS["npy"])
        model = fit_surfaces(data[:, :3], data[:, 3], continuity="c1")
        shape, faces, info = build_shape(model)
        fig = continuity_figures(model, shape)
        out["direct"] = {"faces": len(shape.Faces), "volume": shape.Volume, "area": shape.Area,
                         "gap": fig["max_gap"], "angle": fig["max_angle_deg"], "err": fig["worst_patch_error"]}
        cloud = Points.Points([FreeCAD.Vector(*p) for p in data[:, :3]])
        pobj = doc.addObject("Points::Feature", "Scan")
        pobj.Points = cloud
        pobj.addProperty("App::PropertyIntegerList", "Labels")
        pobj.Labels = [int(v) for v in data[:, 3]]
        out["points"] = facts(api.make_surface(doc, pobj, labels="Labels", name="FromPoints"))
        f.Continuity = "c0"
        doc.recompute()
        out["c0"] = facts(f)
        f.Continuity = "c1"
        doc.recompute()
        out["back"] = facts(f)
        doc.saveAs(ARGS["doc"])
    """, npy=str(npy), doc=str(doc_path))
    file, direct, pobj = out["file"], out["direct"], out["points"]
    for f in (file, pobj, out["back"], out["c0"]):
        assert f["valid"] and f["shape_valid"] and f["type"] == "Solid" and f["closed"]
        assert f["faces"] == 6
    assert "Solid: 6 faces" in file["status"]
    # Same cloud, same process: the feature is the API's result exactly.
    for key in ("volume", "area", "gap", "angle", "err"):
        assert file[key] == pytest.approx(direct[key], rel=1e-12, abs=1e-12), key
    # A Points object stores float32 coordinates (1e-7 relative): the same fit up to that.
    assert pobj["volume"] == pytest.approx(direct["volume"], rel=1e-4)
    assert pobj["area"] == pytest.approx(direct["area"], rel=1e-4)
    diag = float(np.linalg.norm(np.ptp(pts, axis=0)))
    assert file["gap"] <= 1e-7 * diag
    assert file["angle"] < 1.0 < out["c0"]["angle"]  # c1 is tangent, c0 keeps the cube's kinks
    assert out["back"]["volume"] == pytest.approx(file["volume"], rel=1e-12)
    # The sphere of radius 37: volume within 0.5 % despite the noise.
    assert file["volume"] == pytest.approx(4 / 3 * np.pi * 37.0**3, rel=5e-3)
    if importlib.util.find_spec("OCP") is not None:
        # The OCP pipeline (another numpy/scipy, another OpenCASCADE) on the same points.
        from pde2cad.occ.continuity import measure
        from pde2cad.occ.shape import volume
        from pde2cad.reconstruct import reconstruct

        rec = reconstruct(pts, labels, continuity="c1")
        assert len(rec.faces) == file["faces"] and rec.sew_info.is_solid
        assert volume(rec.shape) == pytest.approx(file["volume"], rel=1e-6)
        occ = measure(rec.shape)
        assert occ["max_angle_deg"] == pytest.approx(file["angle"], abs=1e-3)
        assert occ["max_gap"] <= 1e-7 * diag

    again = freecad("""
        import FreeCAD
        doc = FreeCAD.openDocument(ARGS["doc"])
        f = doc.getObject("Surface")
        out["restored"] = [len(f.Shape.Faces), f.Shape.Volume, f.Shape.Area, type(f.Proxy).__name__]
        f.touch()
        doc.recompute()
        out["recomputed"] = [f.isValid(), f.Shape.isValid(), len(f.Shape.Faces), f.Shape.Volume, f.Shape.Area]
    """, doc=str(doc_path))
    assert again["restored"][3] == "SurfaceFeature"
    assert again["restored"][0] == 6 and again["recomputed"][:3] == [True, True, 6]
    for got in (again["restored"], again["recomputed"][2:]):
        assert got[1] == pytest.approx(file["volume"], rel=1e-9)
        assert got[2] == pytest.approx(file["area"], rel=1e-9)


@pytest.mark.skipif(not CUBE_STL.is_file(), reason="FreeCAD's OpenSCAD test mesh Cube.stl is not installed")
def test_surface_from_segmented_mesh(freecad) -> None:  # noqa: ANN001
    """FreeCAD's own test mesh (OpenSCAD's Cube.stl), segmented by FreeCAD's planar
    segmentation: the feature samples it by area with the segments as labels and closes a
    solid of the mesh's volume."""
    out = freecad("""
        import FreeCAD, Mesh
        from freecad.pde2cad import api
        doc = FreeCAD.newDocument("mesh")
        mesh = Mesh.Mesh(ARGS["stl"])
        for facets in mesh.getPlanarSegments(1e-3):
            mesh.addSegment(facets)
        obj = doc.addObject("Mesh::Feature", "Cube")
        obj.Mesh = mesh
        f = api.make_surface(doc, obj, labels="segments", continuity="c0", sample_points=8000)
        out["r"] = [mesh.countSegments(), mesh.Volume, f.isValid(), f.Shape.isValid(),
                    f.Shape.ShapeType, len(f.Shape.Faces), f.Shape.Volume, f.MaxGap, f.Status]
    """, stl=str(CUBE_STL))
    segments, mesh_volume, valid, shape_valid, kind, faces, vol, gap, status = out["r"]
    assert segments == 6 and valid and shape_valid, status
    assert kind == "Solid" and faces == 6
    assert vol == pytest.approx(mesh_volume, rel=1e-3)
    assert gap <= 1e-9 * mesh_volume ** (1 / 3)
