"""The OCP adapter of the reconstruction: model -> sewn shape, and the result as build123d /
CadQuery objects."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")

from pde2cad import samples  # noqa: E402
from pde2cad.occ import measure, read_iges  # noqa: E402
from pde2cad.occ.build import build_shape  # noqa: E402
from pde2cad.reconstruct import fit_surfaces, reconstruct  # noqa: E402


@pytest.fixture(scope="module")
def torus_rec():  # type: ignore[no-untyped-def]
    cloud = samples.torus(20000)
    return cloud, reconstruct(cloud.points, cloud.labels)


def test_build_shape_sews_the_model_into_a_solid() -> None:
    cloud = samples.torus(20000)
    model = fit_surfaces(cloud.points, cloud.labels)
    shape, faces, info = build_shape(model)
    assert len(faces) == len(model.labels) == 16
    assert info.is_solid and info.valid and info.n_free_edges == 0
    m = measure(shape)
    assert m["closed"] and m["shared_edges"] == 32 and m["max_gap"] <= 1e-7 * model.diagonal


def test_to_build123d_and_cadquery_give_a_solid_of_the_torus_volume(torus_rec) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("build123d")
    pytest.importorskip("cadquery")
    import build123d
    import cadquery

    cloud, rec = torus_rec
    true = 2 * math.pi**2 * 1.0 * 0.35**2  # the sample: major radius 1, minor 0.35
    solid = rec.to_build123d()
    assert isinstance(solid, build123d.Solid) and solid.is_valid
    assert solid.volume == pytest.approx(true, rel=1e-3)
    assert len(solid.faces()) == 16
    cq = rec.to_cadquery()
    assert isinstance(cq, cadquery.Solid) and cq.isValid()
    assert cq.Volume() == pytest.approx(solid.volume, rel=1e-9)


def _grid_area(surface, count: int = 201) -> float:  # type: ignore[no-untyped-def]
    """Area of a kernel-neutral B-spline surface from a count x count grid of triangles."""
    u = np.linspace(float(surface.knots_u[0]), float(surface.knots_u[-1]), count)
    v = np.linspace(float(surface.knots_v[0]), float(surface.knots_v[-1]), count)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    p = np.asarray(surface.evaluate(uu.ravel(), vv.ravel())).reshape(count, count, 3)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    tri = np.linalg.norm(np.cross(b - a, c - a), axis=2) + np.linalg.norm(np.cross(c - a, d - a), axis=2)
    return float(0.5 * tri.sum())


def test_an_open_sheet_is_a_build123d_shell_of_the_model_area() -> None:
    """The adapter's faces carry the model's surfaces: build123d's area equals the area of
    the kernel-neutral B-splines (to the grid's discretisation)."""
    pytest.importorskip("build123d")
    import build123d

    cloud = samples.sheet(8000)
    rec = reconstruct(cloud.points, cloud.labels)
    shell = rec.to_build123d()
    assert isinstance(shell, build123d.Shell) and shell.is_valid
    assert len(shell.faces()) == 4
    model_area = sum(_grid_area(s) for s in rec.surfaces.values())
    assert shell.area == pytest.approx(model_area, rel=1e-4)
    assert 3.8 < shell.area < 4.05  # a gently curved 2 x 2 sheet


def test_write_iges_reads_back(torus_rec, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    cloud, rec = torus_rec
    m = measure(read_iges(rec.write_iges(tmp_path / "t.igs")))
    assert m["n_faces"] == 16 and m["valid"] and m["max_gap"] <= 1e-6 * cloud.diagonal
