"""The Python API in build123d / CadQuery terms: drawings as faces, export_step/export_iges,
and the two example scripts, run as written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage

pytestmark = pytest.mark.occ
bd = pytest.importorskip("build123d")
cq = pytest.importorskip("cadquery")
from OCP.BRepCheck import BRepCheck_Analyzer  # noqa: E402
from OCP.TopoDS import TopoDS_Shape  # noqa: E402

import pde2cad  # noqa: E402
from pde2cad import samples  # noqa: E402
from pde2cad.errors import ExportError, InputError  # noqa: E402
from pde2cad.occ import read_step, volume  # noqa: E402
from pde2cad.occ.drawing import _signed_area  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
IMAGES = ROOT / "examples" / "images"


def _pixel_area(drawing: pde2cad.image.drawing.Drawing) -> float:  # type: ignore[name-defined]
    """Area the loops enclose (outer minus holes), in drawing units squared."""
    s = drawing.mm_per_px or 1.0
    return sum(
        (-1 if lp.is_hole else 1) * abs(_signed_area(np.asarray(lp.curves))) for lp in drawing.loops
    ) * s * s


@pytest.mark.parametrize("image", ["holes_keyhole_plate.png", "holes_nested.png", "glyph_B.png"])
def test_drawing_faces_keep_holes_scale_and_area(image: str) -> None:
    drawing = pde2cad.vectorize(IMAGES / image, scale=0.25)
    faces = drawing.to_build123d()
    groups = drawing.shapes()
    assert len(faces) == len(groups)
    for face, group in zip(faces, groups):
        assert isinstance(face, bd.Face) and face.is_valid
        assert len(face.inner_wires()) == sum(lp.is_hole for lp in group)
        assert face.normal_at().Z == pytest.approx(1.0)
        # Every Bézier is one exact edge.
        assert len(face.edges()) <= sum(lp.n_curves for lp in group)
    assert sum(f.area for f in faces) == pytest.approx(_pixel_area(drawing), rel=1e-6)
    # mm: the faces sit inside the image's physical size, y up.
    box = bd.Compound(faces).bounding_box()
    assert 0 <= box.min.X and box.max.X <= drawing.width * 0.25 + 1e-9
    assert 0 <= box.min.Y and box.max.Y <= drawing.height * 0.25 + 1e-9
    part = bd.extrude(faces, amount=3.0)
    # OCCT integrates volumes over Bézier faces to about 1e-5.
    assert part.is_valid and part.volume == pytest.approx(3.0 * sum(f.area for f in faces), rel=1e-4)


def _photo(blur: float) -> NDArray[np.bool_]:
    """scikit-learn's sample photo, blurred, halved and thresholded at its mean: an image
    nobody drew for us."""
    datasets = pytest.importorskip("sklearn.datasets")
    gray = ndimage.gaussian_filter(datasets.load_sample_image("china.jpg").mean(axis=2), blur)
    half = gray[::2, ::2]
    return np.asarray(half > half.mean())


def test_a_shifted_flipped_glyph_extrudes_to_a_valid_solid(tmp_path: Path) -> None:
    """glyph_B mirrored and moved 17 px into a larger canvas: its face keeps the loops' area
    and the pixel area, and extrudes to what STEP reads back."""
    from PIL import Image

    small = np.asarray(Image.open(IMAGES / "glyph_B.png").convert("L"))[:, ::-1] < 128
    big = np.zeros((small.shape[0] + 40, small.shape[1] + 40), dtype=bool)
    big[17 : 17 + small.shape[0], 23 : 23 + small.shape[1]] = small
    drawing = pde2cad.vectorize(big, tolerance=1.0, scale=0.05)
    faces = drawing.to_build123d()
    assert len(faces) == 1 and len(faces[0].inner_wires()) == 2
    assert faces[0].area == pytest.approx(_pixel_area(drawing), rel=1e-6)
    assert faces[0].area == pytest.approx(small.sum() * 0.05**2, rel=0.02)
    solid = bd.extrude(faces, amount=2.0)
    assert BRepCheck_Analyzer(solid.wrapped).IsValid()
    back = read_step(pde2cad.export_step(solid, tmp_path / "b.step"))
    assert volume(back) == pytest.approx(solid.volume, rel=1e-6)


def test_outlines_that_cross_themselves_are_named_not_a_traceback() -> None:
    """The raw photo: hundreds of ragged specks, some of whose fitted outlines cross at
    sharp corners beyond what healing may fix. No valid face exists; the error says which."""
    drawing = pde2cad.vectorize(_photo(0.0), tolerance=0.5)
    with pytest.raises(ExportError, match=r"shape\(s\) \[0, .*cross themselves.*smaller tolerance"):
        drawing.to_build123d()


def test_cadquery_faces_extrude_too() -> None:
    drawing = pde2cad.vectorize(IMAGES / "holes_target.png")
    faces = drawing.to_cadquery()
    assert all(isinstance(f, cq.Face) and f.isValid() for f in faces)
    solid = cq.Solid.extrudeLinear(faces[0], cq.Vector(0, 0, 4))
    assert solid.isValid() and solid.Volume() == pytest.approx(4 * faces[0].Area(), rel=1e-4)


@pytest.fixture(scope="module")
def ball():  # noqa: ANN201 - a Reconstruction
    cloud = samples.sphere6(6000)
    return pde2cad.reconstruct(cloud.points, cloud.labels, continuity="c0")


def test_export_takes_every_kind_of_shape(ball, tmp_path: Path) -> None:  # noqa: ANN001
    solid = pde2cad.to_build123d(ball)
    assert isinstance(solid, bd.Solid)
    assert isinstance(pde2cad.to_cadquery(ball), cq.Solid)
    box = bd.Box(1, 2, 3)
    inputs = {
        "result": ball, "topods": ball.shape, "build123d": solid,
        "cadquery": pde2cad.to_cadquery(ball), "workplane": cq.Workplane().box(1, 2, 3),
        "list": [box, bd.Pos(5, 0, 0) * bd.Box(1, 1, 1)],
    }
    expected = {"workplane": 6.0, "list": 7.0}
    for key, obj in inputs.items():
        path = pde2cad.export_step(obj, tmp_path / f"{key}.step", author="tester")
        back = read_step(path)
        assert BRepCheck_Analyzer(back).IsValid()
        assert volume(back) == pytest.approx(expected.get(key, solid.volume), rel=1e-6)
        iges = pde2cad.export_iges(obj, tmp_path / f"{key}.igs")
        assert iges.stat().st_size > 0
    # Only the reconstruction knows its segments: its faces carry their names.
    text = (tmp_path / "result.step").read_text()
    assert text.count("ADVANCED_FACE('segment_") == len(ball.labels)
    assert "ADVANCED_FACE('segment_" not in (tmp_path / "topods.step").read_text()


@pytest.mark.parametrize("bad", ["part.step", None, np.zeros((3, 3)), [], TopoDS_Shape()])
def test_export_refuses_what_is_not_a_shape(bad: object, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot export"):
        pde2cad.export_step(bad, tmp_path / "x.step")
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("script", "output", "faces"),
    [("image_to_step.py", "plate.step", None), ("cloud_to_offset_step.py", "ball_offset.step", 6)],
)
def test_example_scripts_run_as_written(
    script: str, output: str, faces: int | None, tmp_path: Path
) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    proc = subprocess.run(
        [sys.executable, str(ROOT / "examples" / script)], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    shape = read_step(tmp_path / output)
    part = bd.Shape.cast(shape)
    assert BRepCheck_Analyzer(shape).IsValid() and len(part.solids()) == 1
    if faces is None:  # the plate: 0.1 mm/px, 5 mm thick
        drawing = pde2cad.vectorize(IMAGES / "holes_keyhole_plate.png", scale=0.1)
        assert volume(shape) == pytest.approx(5 * _pixel_area(drawing), rel=1e-4)
    else:  # the unit sphere grown by 0.03: 4/3 pi 1.03^3
        assert volume(shape) == pytest.approx(4 / 3 * np.pi * 1.03**3, rel=2e-3)
