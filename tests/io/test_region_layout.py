"""Crease regions as segments: the fallback of the automatic layout for CAD meshes whose
coarse quad faces, cut along the creases, leave pieces the pipeline rejects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pde2cad.io.meshes import read_surface, region_layout

bd = pytest.importorskip("build123d")
trimesh = pytest.importorskip("trimesh")


def _holed_box(path: Path) -> Path:
    """A 4 x 3 x 1 box, its vertical edges filleted (r 0.4), a through hole (r 0.6):
    genus 1, sharp edges round the top, the bottom and the hole."""
    part = bd.fillet(bd.Box(4, 3, 1).edges().filter_by(bd.Axis.Z), radius=0.4) - bd.Cylinder(0.6, 2)
    bd.export_stl(part, str(path), tolerance=1e-3, angular_tolerance=0.1)
    return path


def test_a_holed_box_reconstructs_from_its_crease_regions(tmp_path: Path) -> None:
    from pde2cad.reconstruct import reconstruct
    from pde2cad.report import build_report
    from pde2cad.occ import write_step

    surface = read_surface(_holed_box(tmp_path / "box.stl"), sample_points=40_000)
    layout = region_layout(surface, (surface.vertices, surface.triangles))
    assert layout is not None
    # Side band (sides and vertical fillets), top and bottom with the hole, the hole's wall.
    assert layout.summary["patches"] == 4 and layout.summary["kind"] == "crease regions"
    assert layout.summary["components"] == 1
    rec = reconstruct(surface.points, layout.labels, continuity="c1")
    step = write_step(rec.shape, tmp_path / "box.step")
    report = build_report(rec, step, orthogonal=False)
    s = report["summary"]
    diagonal = float(np.linalg.norm(surface.points.max(0) - surface.points.min(0)))
    assert s["valid"] and s["solid"] and s["free_edges"] == 0
    assert s["max_gap_rel"] <= 1e-7
    # Every sharp edge of the box is 90 deg all along (before: 0-143 deg), the seams cut
    # through its smooth faces are C1 (before: up to 4.3 deg).
    _assert_creases(report, rec, {90.0})
    # Every input point near its face (the figures: mean <= 2e-3 D, < 1 % beyond 1 % D).
    dist = np.concatenate([np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points, axis=1)
                           for p in rec.patches.values()])
    assert dist.mean() <= 2e-3 * diagonal and np.mean(dist > 0.01 * diagonal) < 0.01
    # No face where there is no part: face samples lie on the box (95 % within 5e-3 D).
    truth = read_surface(tmp_path / "box.stl", sample_points=200_000, seed=3).points
    from scipy.spatial import cKDTree

    g = np.linspace(0.0, 1.0, 30)
    uu, vv = (a.ravel() for a in np.meshgrid(g, g))
    faces = np.concatenate([p.evaluate(uu, vv) for p in rec.patches.values()])
    assert np.percentile(cKDTree(truth).query(faces)[0], 95) <= 5e-3 * diagonal


def _assert_creases(report: dict, rec: object, dihedrals: set[float], slack: float = 15.0) -> None:
    """Each seam between two crease regions is a crease whose normal angle stays within
    ``slack`` of one of the part's ``dihedrals`` along all of it; the seams the split cut
    through a region are smooth (<= 1 deg)."""
    region = {piece: label for label, pieces in rec.splits.pieces.items() for piece in pieces}
    creases = smooth = 0
    for e in report["edges"]:
        a, b = (region.get(x, x) for x in e["labels"])
        if a != b:
            creases += 1
            assert e["crease"], e
            assert any(d - slack <= e["min_angle_deg"] and e["max_angle_deg"] <= d + slack
                       for d in dihedrals), e
        else:
            smooth += 1
            assert not e["crease"] and e["max_angle_deg"] <= 1.0, e
    assert creases and smooth
    assert report["summary"]["crease_edges"] == creases


def test_a_revolved_knob_keeps_its_cone_creases(tmp_path: Path) -> None:
    """A revolved profile (disc, cylinder, 53.13-deg cone, cylinder, disc): the crease
    regions' seams keep 90 and 53.13 deg (before: one read 29 deg, two patches fell back to
    C0 with a 15-deg smooth seam)."""
    from pde2cad.reconstruct import reconstruct
    from pde2cad.report import build_report
    from pde2cad.occ import write_step

    with bd.BuildPart() as knob:
        with bd.BuildSketch(bd.Plane.XZ):
            with bd.BuildLine():
                bd.Polyline((0, 0), (1, 0), (1, 0.3), (0.6, 0.6), (0.6, 1.2), (0, 1.2), (0, 0))
            bd.make_face()
        bd.revolve(axis=bd.Axis.Z)
    path = tmp_path / "knob.stl"
    bd.export_stl(knob.part, str(path), tolerance=1e-3, angular_tolerance=0.1)
    surface = read_surface(path, sample_points=40_000)
    layout = region_layout(surface, (surface.vertices, surface.triangles))
    assert layout is not None and layout.summary["patches"] == 5
    rec = reconstruct(surface.points, layout.labels, continuity="c1")
    report = build_report(rec, write_step(rec.shape, tmp_path / "knob.step"), orthogonal=False)
    assert report["summary"]["solid"] and report["summary"]["max_gap_rel"] <= 1e-7
    assert not report["summary"]["c0_fallback"]
    _assert_creases(report, rec, {90.0, float(np.degrees(np.arctan2(0.4, 0.3)))}, slack=5.0)


def test_a_mesh_without_creases_has_no_region_layout(tmp_path: Path) -> None:
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(4).export(path)
    surface = read_surface(path, sample_points=5000)
    assert region_layout(surface, (surface.vertices, surface.triangles)) is None


def _box_cloud_report(tmp_path: Path, noise: float = 0.0, repeat: int = 1) -> tuple[dict, list[str], object]:
    """A 2 x 1.4 x 1 box's 30k samples (no faces; ``noise``: Gaussian, x the diagonal per
    axis; each written ``repeat`` times) through reconstruct_auto, C1."""
    from pde2cad.io.meshes import reconstruct_auto
    from pde2cad.report import build_report
    from pde2cad.occ import write_step

    box = trimesh.creation.box(extents=(2.0, 1.4, 1.0))
    points = trimesh.sample.sample_surface(box, 30_000, seed=1)[0]
    points = points + np.random.default_rng(3).normal(0.0, noise * np.sqrt(6.96), points.shape)
    path = tmp_path / "box.xyz"
    np.savetxt(path, np.repeat(points, repeat, axis=0))
    said: list[str] = []
    rec, layout = reconstruct_auto(read_surface(path), continuity="c1", message=said.append)
    report = build_report(rec, write_step(rec.shape, tmp_path / "box.step"), orthogonal=False)
    return report, said, layout


def test_a_cloud_with_every_point_repeated_is_laid_out_as_read_once(tmp_path: Path) -> None:
    """Each sample written 3 times (scans and exports repeat points): the repeats are read
    once, the box comes out as from the single cloud (6 faces, 12 creases, a solid), and
    every input row gets a label (repeats the same). Before, the repeats left no
    nearest-neighbour spacing and the crease regions fell into 4-point segments."""
    report, said, layout = _box_cloud_report(tmp_path, repeat=3)
    assert any("60000 repeated points read once" in line for line in said)
    assert layout.summary["kind"] == "crease regions" and layout.summary["patches"] == 6
    s = report["summary"]
    assert s["valid"] and s["solid"] and s["n_faces"] == 6 and s["max_gap_rel"] <= 1e-7
    assert s["crease_edges"] == 12 and s["mean_error_rel"] <= 1e-3
    labels = layout.labels  # type: ignore[attr-defined]
    assert len(labels) == 90_000 and (labels[0::3] == labels[1::3]).all()


def test_a_clean_cloud_of_a_box_takes_its_crease_regions(tmp_path: Path) -> None:
    """A cloud without faces is laid out by its crease regions (cloud_regions, no Poisson
    guide): the box's 6 faces, a valid solid, its 12 edges kept as creases, the points on
    the faces (measured: mean 2.9e-4 of the diagonal for the worst face)."""
    report, said, layout = _box_cloud_report(tmp_path)
    assert layout.summary["kind"] == "crease regions" and layout.summary["patches"] == 6
    assert not any("guide mesh" in line for line in said)
    s = report["summary"]
    assert s["valid"] and s["solid"] and s["n_faces"] == 6 and s["max_gap_rel"] <= 1e-7
    assert s["crease_edges"] == 12 and s["mean_error_rel"] <= 1e-3


def test_a_clean_cloud_of_a_box_keeps_its_right_angles(tmp_path: Path) -> None:
    """Crease points go to the face whose plane passes nearest (measured 77-91 deg along
    the 12 edges; 41-97 when they went to the nearest face point)."""
    lo, hi = _box_cloud_report(tmp_path)[0]["summary"]["crease_angle_deg"]
    assert 70.0 <= lo and hi <= 100.0


def test_a_noisy_cloud_of_a_box_takes_its_crease_regions(tmp_path: Path) -> None:
    """0.2 % noise of the diagonal: the box's right angles are still told (the noise
    subtracted from the variation, over more neighbours; a crease angle of at least the
    one asked for; measured 79-99 deg), and the faces lie within the noise of the points."""
    report, said, layout = _box_cloud_report(tmp_path, noise=0.002)
    assert layout.summary["kind"] == "crease regions" and layout.summary["patches"] == 6
    assert 30.0 <= layout.summary["crease_angle_told"] < 90.0
    assert layout.summary["noise"] == pytest.approx(0.002 * np.sqrt(6.96), rel=0.15)
    s = report["summary"]
    assert s["valid"] and s["solid"] and s["max_gap_rel"] <= 1e-7
    assert s["crease_edges"] == 12
    lo, hi = s["crease_angle_deg"]
    assert 65.0 <= lo and hi <= 115.0
    # Gaussian noise of sigma lies 0.8 sigma off the true faces on average.
    assert s["mean_error_rel"] <= 0.8 * 0.002 + 1e-3


def _noisy_holed_box(tmp_path: Path) -> tuple[object, float]:
    """The holed box as 40k points with 0.2 % noise of the diagonal, read as a cloud (no
    faces), and its diagonal."""
    mesh = read_surface(_holed_box(tmp_path / "box.stl"), sample_points=40_000)
    diagonal = float(np.linalg.norm(mesh.points.max(0) - mesh.points.min(0)))
    noisy = mesh.points + np.random.default_rng(5).normal(0.0, 0.002 * diagonal, mesh.points.shape)
    np.savetxt(tmp_path / "box.xyz", noisy)
    return read_surface(tmp_path / "box.xyz"), diagonal


def test_a_noisy_cloud_of_a_holed_box_tells_its_crease_regions(tmp_path: Path) -> None:
    """Through 0.2 % noise (before: no regions at all) the holed box's 4 regions, each one
    face (side band with its fillets, top, bottom, the hole's wall): the regions of the
    noisy points agree with the mesh's own regions on 95 % of the points at least."""
    surface, diagonal = _noisy_holed_box(tmp_path)
    layout = region_layout(surface, None)
    assert layout is not None and layout.summary["patches"] == 4
    assert layout.summary["crease_angle_told"] >= 30.0
    assert layout.summary["noise"] == pytest.approx(0.002 * diagonal, rel=0.15)
    mesh = read_surface(tmp_path / "box.stl", sample_points=40_000)
    truth = region_layout(mesh, (mesh.vertices, mesh.triangles)).labels
    agree = sum(np.bincount(truth[layout.labels == r]).max() for r in range(4))
    assert agree >= 0.95 * len(truth)


@pytest.mark.xfail(strict=True, reason="~2 % of the crease band's points go to the wrong face "
                   "near the fillets and the hole (up to 0.036 D off): a patch's mean reaches "
                   "2.96e-3 D, at the 1e-3 D + noise a region result must meet, and two "
                   "seams fold (177 deg) (a 60 x 40 x 30 box with r 6 fillets passes: 12 "
                   "faces, creases 62-105 deg)")
def test_a_noisy_cloud_of_a_holed_box_fits_its_crease_regions(tmp_path: Path) -> None:
    from pde2cad.io.meshes import REGION_MEAN
    from pde2cad.occ import measure, read_step
    from pde2cad.reconstruct import reconstruct

    surface, diagonal = _noisy_holed_box(tmp_path)
    layout = region_layout(surface, None)
    rec = reconstruct(surface.points, layout.labels, continuity="c1", sharp_borders=True)
    worst = max(float(np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points,
                                     axis=1).mean()) for p in rec.patches.values())
    assert worst <= (REGION_MEAN + layout.summary["noise"] / diagonal) * diagonal
    m = measure(read_step(rec.write_step(tmp_path / "box.step")), samples=20)
    assert m["valid"] and m["closed"] and m["max_angle_deg"] <= 120.0  # creases 90, no fold


def test_crease_regions_that_miss_are_kept_when_every_remeshed_layout_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A crease-region result rejected for missing points is kept aside and returned when
    the remeshed layouts are all rejected (here: forced), not an error."""
    import pde2cad.io.meshes as meshes
    import pde2cad.reconstruct as recon
    from pde2cad.errors import InputError

    real = recon.reconstruct

    def only_regions(*args: object, **kwargs: object) -> object:
        if not kwargs.get("sharp_borders"):
            raise InputError("forced: a remeshed layout rejected")
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(meshes, "REGION_MEAN", -1.0)  # every region result "misses"
    monkeypatch.setattr(meshes, "ATTEMPTS", 1)
    monkeypatch.setattr(recon, "reconstruct", only_regions)
    report, said, layout = _box_cloud_report(tmp_path)
    assert any("miss the points" in line for line in said)
    assert any("keeping the crease regions" in line for line in said)
    assert layout.summary["kind"] == "crease regions" and layout.summary["patches"] == 6
    assert report["summary"]["solid"] and report["summary"]["crease_edges"] == 12


def test_crease_regions_that_fold_give_way_to_the_remeshed_layouts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A crease-region result with a seam past FOLDED_SEAM (here: the box's own 90-deg
    edges, the limit lowered to 80) is not taken at once: the remeshed layouts are tried,
    and it is returned only when they are all rejected."""
    import pde2cad.io.meshes as meshes
    import pde2cad.reconstruct as recon
    from pde2cad.errors import InputError

    real = recon.reconstruct
    tried: list[bool] = []

    def only_regions(*args: object, **kwargs: object) -> object:
        tried.append(bool(kwargs.get("sharp_borders")))
        if not kwargs.get("sharp_borders"):
            raise InputError("forced: a remeshed layout rejected")
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(meshes, "FOLDED_SEAM", 80.0)
    monkeypatch.setattr(meshes, "ATTEMPTS", 1)
    monkeypatch.setattr(recon, "reconstruct", only_regions)
    report, said, layout = _box_cloud_report(tmp_path)
    assert tried == [True, False]
    assert any("crease regions fold (seam angle" in line for line in said)
    assert any("keeping the crease regions" in line for line in said)
    assert layout.summary["kind"] == "crease regions"
    assert report["summary"]["solid"] and report["summary"]["crease_edges"] == 12


def test_a_c_shaped_wall_is_halved_where_one_patch_would_turn_too_far(tmp_path: Path) -> None:
    """A tube wall (r 1 and 0.8, height 0.8) with a 0.6-wide slot cut out: its outer and
    inner faces turn by ~320 degrees, which no patch can take (before: refused, "2 corners",
    and the remeshed layouts with it). Each is halved across its length (the neighbours'
    T-nodes carried along their strips), and every piece is one patch again."""
    from pde2cad.layout.adjacency import plane_score
    from pde2cad.layout.split import WIDE_COS
    from pde2cad.occ import write_step
    from pde2cad.reconstruct import reconstruct
    from pde2cad.report import build_report
    from scipy.spatial import cKDTree

    part = (bd.Cylinder(1, 0.8) - bd.Cylinder(0.8, 1)
            - bd.Box(2, 0.6, 2, align=(bd.Align.MIN, bd.Align.CENTER, bd.Align.CENTER)))
    path = tmp_path / "cwall.stl"
    bd.export_stl(part, str(path), tolerance=1e-3, angular_tolerance=0.1)
    surface = read_surface(path, sample_points=40_000)
    layout = region_layout(surface, (surface.vertices, surface.triangles))
    assert layout is not None and layout.summary["patches"] == 6
    rec = reconstruct(surface.points, layout.labels, continuity="c1", sharp_borders=True)
    report = build_report(rec, write_step(rec.shape, tmp_path / "cwall.step"), orthogonal=False)
    s = report["summary"]
    assert s["valid"] and s["solid"] and s["max_gap_rel"] <= 1e-7
    # Both round walls are cut, and no piece turns past what the split allows.
    walls = [label for label in np.unique(layout.labels)
             if np.ptp(surface.points[layout.labels == label, 2]) > 0.7
             and (layout.labels == label).sum() > 0.2 * len(layout.labels)]
    assert len(walls) == 2 and all(len(rec.splits.pieces.get(w, [])) >= 2 for w in walls)
    tree = cKDTree(surface.points)
    for p in rec.patches.values():
        members = tree.query(p.points)[1]
        assert plane_score(surface.points, members, tree) >= WIDE_COS
    # Sharp edges 68-108 deg for 90 (the slot's end faces are 0.2 wide, ~7 point spacings).
    _assert_creases(report, rec, {90.0}, slack=25.0)
    dist = np.concatenate([np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points, axis=1)
                           for p in rec.patches.values()])
    diagonal = float(np.linalg.norm(np.ptp(surface.points, axis=0)))
    assert dist.mean() <= 1e-3 * diagonal and np.mean(dist > 0.01 * diagonal) < 0.01
