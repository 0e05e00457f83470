"""OCP adapter: B-spline faces, sewing, STEP/IGES round trips and seam continuity (real OCCT)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.typing import NDArray

pytest.importorskip("OCP")

from OCP.BRep import BRep_Tool  # noqa: E402
from OCP.BRepAdaptor import BRepAdaptor_Curve  # noqa: E402
from OCP.ShapeAnalysis import ShapeAnalysis_Surface  # noqa: E402
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE  # noqa: E402
from OCP.TopExp import TopExp, TopExp_Explorer  # noqa: E402
from OCP.TopoDS import TopoDS  # noqa: E402
from OCP.TopTools import TopTools_IndexedMapOfShape  # noqa: E402

from pde2cad.errors import ExportError, InputError  # noqa: E402
from pde2cad.occ import (  # noqa: E402
    make_face,
    measure,
    read_iges,
    read_step,
    sew,
    to_build123d,
    to_cadquery,
    to_geom_surface,
    write_iges,
    write_step,
)
from pde2cad.occ.continuity import _FaceSampler  # noqa: E402
from pde2cad.occ.shape import volume  # noqa: E402

pytestmark = pytest.mark.occ

try:
    from pde2cad.bspline.data import BSplineSurface  # type: ignore[import-not-found]
except ImportError:  # the kernel-neutral model is written in parallel; same shape here

    @dataclass(frozen=True)
    class BSplineSurface:  # type: ignore[no-redef]
        poles: NDArray[np.float64]
        knots_u: NDArray[np.float64]
        knots_v: NDArray[np.float64]
        degree_u: int
        degree_v: int


def _bezier(poles: NDArray[np.float64]) -> BSplineSurface:
    """A single-span B-spline (Bezier) patch on [0, 1]^2 with the given pole grid."""
    nu, nv = poles.shape[:2]
    ku = np.r_[np.zeros(nu), np.ones(nu)]
    kv = np.r_[np.zeros(nv), np.ones(nv)]
    return BSplineSurface(poles, ku, kv, nu - 1, nv - 1)


def _paraboloid_poles() -> NDArray[np.float64]:
    """Bicubic Bezier poles of z = x^2 + 0.3 y^2 over [0, 1]^2 (exact: u^2 has Bernstein
    coefficients 0, 0, 1/3, 1 in degree 3)."""
    lin = np.arange(4) / 3.0
    sq = np.array([0.0, 0.0, 1.0 / 3.0, 1.0])
    x, y = np.meshgrid(lin, lin, indexing="ij")
    z = sq[:, None] + 0.3 * sq[None, :]
    return np.stack([x, y, z], axis=-1)


def _split_u(
    poles: NDArray[np.float64], t: float = 0.5
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """de Casteljau split of a Bezier patch along u: two patches that are exactly C1."""
    rows = [poles]
    left, right = [poles[0]], [poles[-1]]
    while len(rows[-1]) > 1:
        prev = rows[-1]
        nxt = (1 - t) * prev[:-1] + t * prev[1:]
        rows.append(nxt)
        left.append(nxt[0])
        right.append(nxt[-1])
    return np.array(left), np.array(right[::-1])


def _c1_pair() -> list:
    a, b = _split_u(_paraboloid_poles())
    return [make_face(_bezier(a)), make_face(_bezier(b))]


def _quad(p00, p10, p01, p11) -> BSplineSurface:  # noqa: ANN001 - test helper
    return _bezier(np.array([[p00, p01], [p10, p11]], dtype=float))


def _unit_cube_faces() -> list:
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)

    def v(x: int, y: int, z: int) -> NDArray[np.float64]:
        return c[4 * x + 2 * y + z]

    # Deliberately mixed parameter orientations: sewing must make the shell consistent.
    quads = [
        (v(0, 0, 0), v(1, 0, 0), v(0, 1, 0), v(1, 1, 0)),
        (v(0, 0, 1), v(1, 0, 1), v(0, 1, 1), v(1, 1, 1)),
        (v(0, 0, 0), v(0, 1, 0), v(0, 0, 1), v(0, 1, 1)),
        (v(1, 0, 0), v(1, 1, 0), v(1, 0, 1), v(1, 1, 1)),
        (v(0, 0, 0), v(1, 0, 0), v(0, 0, 1), v(1, 0, 1)),
        (v(0, 1, 1), v(1, 1, 1), v(0, 1, 0), v(1, 1, 0)),
    ]
    return [make_face(_quad(*q)) for q in quads]


def _edges(shape) -> list:  # noqa: ANN001 - OCP shape
    edge_map = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_EDGE, edge_map)
    return [edge_map.FindKey(i) for i in range(1, edge_map.Extent() + 1)]


@pytest.fixture(scope="module")
def cube():  # noqa: ANN201 - OCP shape
    shape, info = sew(_unit_cube_faces(), 1e-6)
    return shape, info


# --- surface conversion ---------------------------------------------------------------


def test_geom_surface_matches_the_paraboloid() -> None:
    geom = to_geom_surface(_bezier(_paraboloid_poles()))
    assert (geom.UDegree(), geom.VDegree(), geom.NbUPoles(), geom.NbVPoles()) == (3, 3, 4, 4)
    for u, v in [(0.0, 0.0), (0.25, 0.7), (1.0, 0.5), (0.6, 1.0)]:
        p = geom.Value(u, v)
        assert np.allclose([p.X(), p.Y(), p.Z()], [u, v, u * u + 0.3 * v * v], atol=1e-14)


def test_full_knot_vector_becomes_unique_knots_and_multiplicities() -> None:
    rng = np.random.default_rng(1)
    poles = rng.normal(size=(5, 4, 3))
    ku = np.array([0, 0, 0, 0, 0.5, 1, 1, 1, 1.0])
    kv = np.array([0, 0, 0, 0.3, 1, 1, 1.0])
    geom = to_geom_surface(BSplineSurface(poles, ku, kv, 3, 2))
    assert geom.NbUKnots() == 3 and [geom.UMultiplicity(i) for i in (1, 2, 3)] == [4, 1, 4]
    assert geom.NbVKnots() == 3 and [geom.VMultiplicity(i) for i in (1, 2, 3)] == [3, 1, 3]
    assert geom.UKnot(2) == 0.5 and geom.VKnot(2) == 0.3
    # Pole (i, j) is OCCT pole (i + 1, j + 1); the corner of a clamped surface is pole 0, 0.
    p = geom.Value(0.0, 0.0)
    assert np.allclose([p.X(), p.Y(), p.Z()], poles[0, 0], atol=1e-14)
    p = geom.Pole(5, 4)
    assert np.allclose([p.X(), p.Y(), p.Z()], poles[4, 3], atol=0)


def test_knot_noise_is_merged() -> None:
    # Interior knots computed in floating point may differ by an ulp; OCCT would see a
    # zero-length span, so the adapter merges them into one knot of multiplicity 2.
    poles = np.zeros((6, 2, 3))
    poles[..., 0] = np.arange(6)[:, None]
    poles[..., 1] = np.arange(2)[None, :]
    ku = np.array([0, 0, 0, 0, 0.5, np.nextafter(0.5, 1.0), 1, 1, 1, 1.0])
    geom = to_geom_surface(BSplineSurface(poles, ku, np.array([0, 0, 1, 1.0]), 3, 1))
    assert geom.NbUKnots() == 3 and [geom.UMultiplicity(i) for i in (1, 2, 3)] == [4, 2, 4]


# The adapter is duck-typed and validates on its own (callers may pass unvalidated objects),
# so invalid input is built with SimpleNamespace rather than the validating dataclass.
@pytest.mark.parametrize(
    ("knots_u", "message"),
    [
        (np.array([0, 0, 0, 0, 1, 1, 1.0]), "needs 8 knots"),
        (np.array([0, 0, 0, 0.5, 1, 1, 1, 1.0]), "clamped"),
        (np.array([0, 0, 0, 0, 1, 1, 1, np.nan]), "finite"),
    ],
)
def test_bad_knots_raise_input_error(knots_u: NDArray[np.float64], message: str) -> None:
    surf = SimpleNamespace(
        poles=_paraboloid_poles(), knots_u=knots_u, knots_v=np.r_[np.zeros(4), np.ones(4)],
        degree_u=3, degree_v=3,
    )
    with pytest.raises(InputError, match=message):
        to_geom_surface(surf)


def test_bad_pole_shape_raises_input_error() -> None:
    surf = SimpleNamespace(
        poles=np.zeros((4, 4, 2)), knots_u=np.zeros(8), knots_v=np.zeros(8), degree_u=3, degree_v=3
    )
    with pytest.raises(InputError, match="shape"):
        to_geom_surface(surf)


# --- sewing, STEP round trip, continuity ----------------------------------------------


def test_c1_pair_sews_and_survives_step_exactly(tmp_path: Path) -> None:
    shape, info = sew(_c1_pair(), 1e-6)
    assert (info.n_faces, info.n_shells, info.n_free_edges) == (2, 1, 6)
    assert info.valid and not info.is_closed and not info.is_solid

    path = write_step(shape, tmp_path / "pair.step")
    back = read_step(path)
    m = measure(back)
    assert m["n_faces"] == 2 and m["n_shells"] == 1 and m["valid"] and not m["closed"]
    assert m["free_edges"] == 6 and m["shared_edges"] == 1
    assert m["edges"][0]["faces"] == (0, 1)
    assert m["max_gap"] < 1e-7
    assert m["max_angle_deg"] < 1e-6


def test_crease_gives_its_dihedral_angle(tmp_path: Path) -> None:
    flat = _quad([0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0])
    slope = _quad([1, 0, 0], [2, 0, 1], [1, 1, 0], [2, 1, 1])  # rises at 45 degrees
    shape, info = sew([make_face(flat), make_face(slope)], 1e-6)
    assert info.n_shells == 1 and info.n_free_edges == 6
    m = measure(read_step(write_step(shape, tmp_path / "crease.step")))
    assert m["shared_edges"] == 1 and m["max_gap"] < 1e-7
    assert m["max_angle_deg"] == pytest.approx(45.0, abs=1e-9)


def test_c0_split_of_a_smooth_patch_is_not_reported_as_smooth() -> None:
    # Same shared boundary as the C1 pair, but the second patch is tilted about that
    # boundary: positions agree (gap 0), tangent planes do not.
    a, b = _split_u(_paraboloid_poles())
    b = b.copy()
    b[1:, :, 2] += 0.2 * (b[1:, :, 0] - 0.5)
    shape, _ = sew([make_face(_bezier(a)), make_face(_bezier(b))], 1e-6)
    m = measure(shape)
    assert m["max_gap"] < 1e-12
    assert m["max_angle_deg"] > 5.0


def test_gap_between_unsewn_faces_is_measured() -> None:
    # A 1e-5 step in z is inside the sewing tolerance: the faces are sewn and the
    # position mismatch stays visible as a gap, not hidden.
    lo = _quad([0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0])
    hi = _quad([1, 0, 1e-5], [2, 0, 1e-5], [1, 1, 1e-5], [2, 1, 1e-5])
    shape, info = sew([make_face(lo), make_face(hi)], 1e-4)
    assert info.n_shells == 1 and info.n_free_edges == 6
    m = measure(shape)
    assert m["shared_edges"] == 1
    assert m["max_gap"] == pytest.approx(1e-5, rel=1e-6)


def test_collapsed_side_becomes_a_degenerated_edge_and_is_not_free() -> None:
    # Two triangles-as-quads sharing the apex side: the collapsed side has no 3D curve
    # and must not be counted as a free edge or measured.
    apex = [0.0, 0.0, 1.0]
    left = _quad([0, 0, 0], [1, 0, 0], apex, apex)
    right = _quad([1, 0, 0], [1, 1, 0], apex, apex)
    shape, info = sew([make_face(left), make_face(right)], 1e-6)
    assert info.valid and info.n_shells == 1
    m = measure(shape)
    # Edges: 2 x 3 real sides, one shared ((1,0,0)-apex), so 4 free; the two collapsed
    # sides are degenerated edges and count as neither.
    assert m["shared_edges"] == 1 and m["free_edges"] == 4 and m["max_gap"] < 1e-12
    assert sum(BRep_Tool.Degenerated_s(TopoDS.Edge_s(e)) for e in _edges(shape)) == 2
    # Planes y = 0 and x + z = 1 (normals (0,1,0), (1,0,1)/sqrt2) meet at 90 degrees.
    assert m["max_angle_deg"] == pytest.approx(90.0, abs=1e-9)


def test_unit_cube_becomes_a_valid_solid(cube) -> None:  # noqa: ANN001
    shape, info = cube
    assert info.is_closed and info.is_solid and info.valid
    assert (info.n_faces, info.n_shells, info.n_free_edges) == (6, 1, 0)
    assert volume(shape) == pytest.approx(1.0, abs=1e-9)
    m = measure(shape)
    assert m["closed"] and m["free_edges"] == 0 and m["shared_edges"] == 12
    assert m["max_gap"] < 1e-12
    assert m["max_angle_deg"] == pytest.approx(90.0, abs=1e-9)


def test_cube_step_round_trip_keeps_volume(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    back = read_step(write_step(shape, tmp_path / "cube.step"))
    assert volume(back) == pytest.approx(1.0, abs=1e-9)
    m = measure(back)
    assert m["valid"] and m["closed"] and m["n_faces"] == 6 and m["free_edges"] == 0


def test_step_schema_is_recorded_in_the_header(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    ap214 = write_step(shape, tmp_path / "a214.step").read_text()
    ap242 = write_step(shape, tmp_path / "a242.step", schema="AP242").read_text()
    header214 = ap214.split("ENDSEC;")[0]
    header242 = ap242.split("ENDSEC;")[0]
    assert "AUTOMOTIVE_DESIGN" in header214
    assert "AP242_MANAGED_MODEL_BASED_3D_ENGINEERING_MIM_LF" in header242
    # The schema static is process-global: writing AP214 after AP242 must switch back.
    again = write_step(shape, tmp_path / "again.step").read_text()
    assert "AUTOMOTIVE_DESIGN" in again.split("ENDSEC;")[0]
    assert volume(read_step(tmp_path / "a242.step")) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("schema", ["AP203", "AP214", "AP242"])
def test_every_schema_round_trips(cube, tmp_path: Path, schema: str) -> None:  # noqa: ANN001
    shape, _ = cube
    back = read_step(write_step(shape, tmp_path / f"{schema}.step", schema=schema))
    assert volume(back) == pytest.approx(1.0, abs=1e-9)


def test_step_units_are_declared_not_scaled(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    text = write_step(shape, tmp_path / "inch.step", units="IN").read_text()
    assert "CONVERSION_BASED_UNIT('INCH'" in text.upper()
    # Read in inches: the cube is still 1 (no scaling on write); read in mm: 25.4^3.
    assert volume(read_step(tmp_path / "inch.step", units="IN")) == pytest.approx(1.0, abs=1e-9)
    assert volume(read_step(tmp_path / "inch.step", units="MM")) == pytest.approx(25.4**3, rel=1e-9)
    metre = write_step(shape, tmp_path / "m.step", units="m").read_text()
    assert "SI_UNIT($,.METRE.)" in metre
    assert volume(read_step(tmp_path / "m.step")) == pytest.approx(1e9, rel=1e-9)
    # The unit static is process-global: a later default write must declare mm again.
    assert "SI_UNIT(.MILLI.,.METRE.)" in write_step(shape, tmp_path / "mm.step").read_text()


def test_iges_units_are_declared_not_scaled(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    path = write_iges(shape, tmp_path / "inch.igs", units="IN")
    assert ",4HINCH," in path.read_text()  # unit name in the global section
    assert volume(read_iges(path, units="IN")) == pytest.approx(1.0, abs=1e-9)
    assert volume(read_iges(path, units="MM")) == pytest.approx(25.4**3, rel=1e-9)


def test_iges_round_trip_keeps_faces(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    path = write_iges(shape, tmp_path / "cube.igs")
    back = read_iges(path)
    m = measure(back)
    assert m["n_faces"] == 6
    assert m["valid"] and m["free_edges"] == 0
    assert volume(back) == pytest.approx(1.0, abs=1e-9)


def test_iges_pair_round_trip(tmp_path: Path) -> None:
    shape, _ = sew(_c1_pair(), 1e-6)
    m = measure(read_iges(write_iges(shape, tmp_path / "pair.iges")))
    assert m["n_faces"] == 2 and m["shared_edges"] == 1 and m["free_edges"] == 6
    assert m["max_gap"] < 1e-7 and m["max_angle_deg"] < 1e-6


# --- errors and atomic writes ---------------------------------------------------------


@pytest.mark.parametrize("writer", [write_step, write_iges])
def test_write_to_missing_folder_raises_and_leaves_nothing(
    cube, tmp_path: Path, writer  # noqa: ANN001
) -> None:
    shape, _ = cube
    target = tmp_path / "missing" / "out.step"
    with pytest.raises(ExportError, match="does not exist"):
        writer(shape, target)
    assert not target.exists() and not target.parent.exists()
    assert list(tmp_path.iterdir()) == []


def test_successful_write_leaves_no_temp_file(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    write_step(shape, tmp_path / "c.stp")
    write_iges(shape, tmp_path / "c.igs")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.igs", "c.stp"]


def test_bad_arguments_raise_input_error(cube, tmp_path: Path) -> None:  # noqa: ANN001
    shape, _ = cube
    with pytest.raises(InputError, match="schema"):
        write_step(shape, tmp_path / "x.step", schema="AP999")
    with pytest.raises(InputError, match="unit"):
        write_step(shape, tmp_path / "x.step", units="furlong")
    with pytest.raises(InputError, match="does not exist"):
        read_step(tmp_path / "nope.step")
    (tmp_path / "junk.step").write_text("not a step file\n")
    with pytest.raises(InputError):
        read_step(tmp_path / "junk.step")
    with pytest.raises(InputError):
        sew([], 1e-6)
    with pytest.raises(InputError):
        measure(shape, samples=1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk.step"]


# --- wrappers -------------------------------------------------------------------------


def test_build123d_and_cadquery_wrappers_keep_the_volume(cube) -> None:  # noqa: ANN001
    pytest.importorskip("build123d")
    pytest.importorskip("cadquery")
    shape, _ = cube
    b = to_build123d(shape)
    c = to_cadquery(shape)
    assert type(b).__name__ == "Solid" and type(c).__name__ == "Solid"
    assert b.volume == pytest.approx(1.0, abs=1e-9)
    assert c.Volume() == pytest.approx(1.0, abs=1e-9)
    assert b.is_valid and c.isValid()


def test_projection_fallback_matches_the_pcurves() -> None:
    # Edges without pcurves (possible in foreign files) are mapped by projecting the 3D
    # edge points; on a sewn pair both routes must agree.
    shape, _ = sew(_c1_pair(), 1e-6)
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    face = TopoDS.Face_s(explorer.Current())
    for edge in _edges(face):
        edge = TopoDS.Edge_s(edge)
        with_pcurve = _FaceSampler(face, edge)
        projected = _FaceSampler(face, edge)
        projected.pcurve = None
        projected.projector = ShapeAnalysis_Surface(BRep_Tool.Surface_s(face))
        curve = BRepAdaptor_Curve(edge)
        for t in np.linspace(curve.FirstParameter(), curve.LastParameter(), 7):
            p = curve.Value(float(t))
            a, na = with_pcurve.sample(float(t), p)
            b, nb = projected.sample(float(t), p)
            assert np.linalg.norm(a - b) < 1e-9 and np.linalg.norm(na - nb) < 1e-7


@pytest.mark.parametrize("source", ["noisy_blob", "logo2"])
def test_faces_of_photo_outlines_are_valid(source: str) -> None:
    # Regression (issue 11): neighbouring curves crossed before sharp corners and
    # Drawing.to_build123d raised ExportError on these images.
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    import pde2cad
    from pde2cad.image.raster import read_image, to_mask
    from pde2cad.occ.drawing import drawing_faces

    if source == "noisy_blob":
        mask = read_image(Path(__file__).resolve().parents[2] / "examples" / "images" / "noisy_blob.png")
    else:
        matplotlib = pytest.importorskip("matplotlib")
        from PIL import Image

        path = Path(matplotlib.__file__).parent / "mpl-data" / "sample_data" / "logo2.png"
        mask = to_mask(np.asarray(Image.open(path).convert("L")))
    drawing = pde2cad.vectorize(mask, 1.0)
    faces = drawing_faces(drawing)
    assert len(faces) == len(drawing.shapes())
    total = 0.0
    for face in faces:
        assert BRepCheck_Analyzer(face).IsValid()
        props = GProp_GProps()
        BRepGProp.SurfaceProperties_s(face, props)
        total += abs(props.Mass())
    # The faces cover the shapes' pixels up to the tolerance band along the boundary
    # (1 px times its length) and the dropped specks (at most 2 px each).
    pad = np.pad(mask, 1)
    cracks = np.count_nonzero(pad[1:] != pad[:-1]) + np.count_nonzero(pad[:, 1:] != pad[:, :-1])
    assert abs(total - mask.sum()) <= 1.0 * cracks + 2 * drawing.specks
