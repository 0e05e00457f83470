"""Our STEP and IGES files as FreeCAD 0.20 reads them (its own process, its own kernel)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("OCP")

from pde2cad import samples  # noqa: E402
from pde2cad.errors import InputError  # noqa: E402
from pde2cad.fc import freecad_python, read_back  # noqa: E402
from pde2cad.occ import write_iges  # noqa: E402
from pde2cad.reconstruct import reconstruct  # noqa: E402

pytestmark = pytest.mark.skipif(
    freecad_python() is None, reason="FreeCAD 0.20 not installed (apt-get install freecad-python3)"
)


def test_torus_c1_step_in_freecad(tmp_path: Path) -> None:
    """A closed C1 torus: FreeCAD sees one valid solid, no free edge, the shared edges
    closed to 1e-7 of the diagonal and tangent to 0.05 deg; IGES gives the same faces."""
    cloud = samples.torus(20000)
    rec = reconstruct(cloud.points, cloud.labels, continuity="c1")
    step = read_back(rec.write_step(tmp_path / "torus.step"))
    assert step["valid"] and step["n_solids"] == 1 and step["closed"]
    assert step["n_faces"] == 16 and step["free_edges"] == 0 and step["shared_edges"] == 32
    assert step["max_gap"] <= 1e-7 * cloud.diagonal
    assert step["max_angle_deg"] <= 0.05
    iges = read_back(write_iges(rec.shape, tmp_path / "torus.igs"))
    assert iges["valid"] and iges["n_faces"] == 16
    assert iges["max_gap"] <= 1e-7 * cloud.diagonal


def test_open_cylinder_step_in_freecad(tmp_path: Path) -> None:
    cloud = samples.cylinder(20000)
    rec = reconstruct(cloud.points, cloud.labels, continuity="c1")
    result = read_back(rec.write_step(tmp_path / "cyl.step"))
    assert result["valid"] and result["n_solids"] == 0 and not result["closed"]
    assert result["n_faces"] == 8 and result["free_edges"] == 8 and result["shared_edges"] == 12
    assert result["max_gap"] <= 1e-7 * cloud.diagonal
    assert result["max_angle_deg"] <= 0.05


def test_missing_file_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_back(tmp_path / "absent.step")


def test_cli_freecad_check(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--freecad-check: FreeCAD's verdict on the written STEP lands in the report and summary."""
    import json

    from pde2cad.cli import main

    root = Path(__file__).resolve().parents[2]
    out, report = tmp_path / "torus.step", tmp_path / "torus.json"
    code = main(["reconstruct", str(root / "examples/clouds/torus.ply"), "-o", str(out),
                 "--continuity", "c1", "--freecad-check", "--report", str(report)])
    assert code == 0
    fc = json.loads(report.read_text())["freecad"]
    assert fc["valid"] and fc["n_solids"] == 1 and fc["free_edges"] == 0
    assert fc["max_angle_deg"] <= 0.05
    assert "FreeCAD 0.20" in capsys.readouterr().out
