"""Named, traceable STEP/IGES: product and file names, author, organisation, face names."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")
from OCP.BRep import BRep_Tool  # noqa: E402
from OCP.STEPCAFControl import STEPCAFControl_Reader  # noqa: E402
from OCP.TCollection import TCollection_ExtendedString  # noqa: E402
from OCP.TDataStd import TDataStd_Name  # noqa: E402
from OCP.TDF import TDF_LabelSequence  # noqa: E402
from OCP.TDocStd import TDocStd_Document  # noqa: E402
from OCP.XCAFDoc import XCAFDoc_DocumentTool  # noqa: E402

import pde2cad  # noqa: E402
from pde2cad import samples  # noqa: E402
from pde2cad.errors import InputError  # noqa: E402
from pde2cad.occ import read_iges, read_step, volume, write_iges, write_step  # noqa: E402
from pde2cad.occ.naming import faces_of, segment_face_names  # noqa: E402
from pde2cad.reconstruct import reconstruct  # noqa: E402

pytestmark = pytest.mark.occ
SYSTEM = f"pde2cad {pde2cad.__version__}"


@pytest.fixture(scope="module")
def sphere():  # noqa: ANN201 - a Reconstruction
    cloud = samples.sphere6(8000)
    return reconstruct(cloud.points, cloud.labels, continuity="c0")


def _product_names(path: Path) -> list[str]:
    """Names of the free shapes of a STEP file, as OCCT's XCAF reader sees them."""
    doc = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    reader = STEPCAFControl_Reader()
    reader.SetNameMode(True)
    assert reader.ReadFile(str(path)).name == "IFSelect_RetDone"
    assert reader.Transfer(doc)
    labels = TDF_LabelSequence()
    XCAFDoc_DocumentTool.ShapeTool_s(doc.Main()).GetFreeShapes(labels)
    names = []
    for i in range(1, labels.Length() + 1):
        attr = TDataStd_Name()
        if labels.Value(i).FindAttribute(TDataStd_Name.GetID_s(), attr):
            names.append(attr.Get().ToExtString())
    return names


def test_step_header_and_product_carry_the_given_names(sphere, tmp_path: Path) -> None:  # noqa: ANN001
    path = write_step(
        sphere.shape, tmp_path / "ball.step", name="Ball 6", author="Jane Doe",
        organization="ACME Metrology",
    )
    text = path.read_text()
    file_name = re.search(r"FILE_NAME\((.*?)\);", text, re.S)
    assert file_name is not None
    fields = file_name.group(1)
    for value in ("'Ball 6'", "('Jane Doe')", "('ACME Metrology')", f"'{SYSTEM}'"):
        assert value in fields
    assert "PRODUCT('Ball 6','Ball 6'" in text
    assert "Open CASCADE STEP translator" not in text and "'Author'" not in text
    assert _product_names(path) == ["Ball 6"]
    # Naming changes nothing in the geometry.
    assert volume(read_step(path)) == pytest.approx(volume(sphere.shape), rel=1e-9)


def test_step_name_defaults_to_the_file_name(sphere, tmp_path: Path) -> None:  # noqa: ANN001
    path = write_step(sphere.shape, tmp_path / "pump_housing.stp")
    assert _product_names(path) == ["pump_housing"]
    assert f"'{SYSTEM}'" in path.read_text()


def test_faces_are_named_after_their_segments(sphere, tmp_path: Path) -> None:  # noqa: ANN001
    names = segment_face_names(sphere.shape, sphere.surfaces)
    assert sorted(names) == sorted(f"segment_{k}" for k in sphere.labels)
    # Each name is the segment whose surface the face carries (same poles).
    for face, name in zip(faces_of(sphere.shape), names):
        surf = sphere.surfaces[int(name.split("_")[1])]
        geom = BRep_Tool.Surface_s(face)
        pole = geom.Pole(2, 2)
        assert np.allclose([pole.X(), pole.Y(), pole.Z()], surf.poles[1, 1], atol=1e-12)
    step = write_step(sphere.shape, tmp_path / "s.step", face_names=names)
    written = re.findall(r"ADVANCED_FACE\('([^']*)'", step.read_text())
    assert sorted(written) == sorted(names)
    iges = write_iges(sphere.shape, tmp_path / "s.igs", face_names=names)
    properties = re.findall(r"406,1,\d+H(segment_\d+);", iges.read_text())
    assert sorted(properties) == sorted(names)


def test_wrong_number_of_face_names_is_refused(sphere, tmp_path: Path) -> None:  # noqa: ANN001
    with pytest.raises(InputError, match="one name per face"):
        write_step(sphere.shape, tmp_path / "x.step", face_names=["a", "b"])
    assert not list(tmp_path.iterdir())


def test_iges_global_section_names_the_file(sphere, tmp_path: Path) -> None:  # noqa: ANN001
    path = write_iges(
        sphere.shape, tmp_path / "ball.igs", name="Ball 6", author="Jane Doe",
        organization="ACME",
    )
    lines = path.read_text().splitlines()
    glob = "".join(line[:72] for line in lines if line[72:73] == "G")
    for field in ("6HBall 6", "8Hball.igs", f"{len(SYSTEM)}H{SYSTEM}", "8HJane Doe", "4HACME"):
        assert field in glob
    assert "Filename.iges" not in glob
    assert read_iges(path) is not None
    assert volume(read_iges(path)) == pytest.approx(volume(sphere.shape), rel=1e-6)


def test_non_ascii_names_are_written_safely(sphere, tmp_path: Path) -> None:  # noqa: ANN001
    path = write_step(sphere.shape, tmp_path / "w.step", name="Gehäuse 'A'", author="Zoë")
    text = path.read_text(encoding="ascii")
    assert "PRODUCT('Geh?use _A_'" in text and "('Zo?')" in text


FREECAD_LABELS = '''
import sys
sys.path.append("/usr/lib/freecad-python3/lib")
import FreeCAD, Import
doc = FreeCAD.newDocument()
Import.insert(sys.argv[1], doc.Name)
print("LABELS " + "|".join(o.Label for o in doc.Objects))
'''


@pytest.mark.parametrize("suffix", [".step", ".igs"])
def test_freecad_shows_the_part_by_its_name(sphere, tmp_path: Path, suffix: str) -> None:  # noqa: ANN001
    """The issue's symptom: FreeCAD listed the part as "Open CASCADE STEP translator"."""
    import subprocess

    from pde2cad.fc import freecad_python

    python = freecad_python()
    if python is None:
        pytest.skip("FreeCAD 0.20 not installed (apt-get install freecad-python3)")
    path = pde2cad.export_step if suffix == ".step" else pde2cad.export_iges
    out = path(sphere, tmp_path / f"pump_cover{suffix}")
    script = tmp_path / "labels.py"
    script.write_text(FREECAD_LABELS)
    proc = subprocess.run(
        [python, str(script), str(out)], capture_output=True, text=True, timeout=300
    )
    labels = [x for x in proc.stdout.splitlines() if x.startswith("LABELS ")]
    assert labels and labels[-1] == "LABELS pump_cover", proc.stdout[-1000:]
