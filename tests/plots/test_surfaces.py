"""Surface diagnostic plots: error maps with exact statistics, zebra stripes across joins."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

pytest.importorskip("matplotlib")
from PIL import Image  # noqa: E402

from pde2cad.errors import ExportError, InputError  # noqa: E402
from pde2cad.plots.surfaces import error_map, zebra, zebra_image  # noqa: E402

RNG = np.random.default_rng(20240611)


class Plane:
    """``S(u, v) = (2u, 3v, 0.5)``."""

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        return np.stack([2.0 * u, 3.0 * v, np.full_like(u, 0.5)], axis=-1)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        one, zero = np.ones_like(u), np.zeros_like(u)
        return (
            np.stack([2.0 * one, zero, zero], axis=-1),
            np.stack([zero, 3.0 * one, zero], axis=-1),
        )


class Graph:
    """The graph ``z = f(x)`` over ``x in [x0, x1]``, ``y = v``."""

    def __init__(self, x0: float, x1: float, kind: str) -> None:
        self.x0, self.x1, self.kind = x0, x1, kind

    def _f(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if self.kind == "parabola":  # z = x^2: C1 (even C-infinity) across x = 0.5
            return x * x, 2.0 * x
        # z = |x - 0.5|: only C0 across x = 0.5; the slope is taken from the patch's own side
        side = np.sign(0.5 * (self.x0 + self.x1) - 0.5)
        return np.abs(x - 0.5), np.full_like(x, side)

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        x = self.x0 + (self.x1 - self.x0) * u
        return np.stack([x, v, self._f(x)[0]], axis=-1)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        dx = self.x1 - self.x0
        x = self.x0 + dx * u
        zero = np.zeros_like(x)
        return (
            np.stack([np.full_like(x, dx), zero, dx * self._f(x)[1]], axis=-1),
            np.stack([zero, np.ones_like(x), zero], axis=-1),
        )


def _pair(kind: str) -> list[Graph]:
    return [Graph(0.0, 0.5, kind), Graph(0.5, 1.0, kind)]


def _unit_normal(surface: Graph, u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray:
    su, sv = surface.derivatives(u, v)
    n = np.cross(su, sv)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _angle(a: NDArray, b: NDArray) -> NDArray:
    """Angles between rows of unit vectors, accurate near 0 (atan2, not arccos)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("nk,nk->n", a, b))


def _check_png(path: Path) -> None:
    assert path.is_file()
    assert path.stat().st_size > 5_000
    with Image.open(path) as img:
        assert img.format == "PNG"
        img.verify()
    with Image.open(path) as img:
        w, h = img.size
        assert w > 300 and h > 300
        assert len(set(np.asarray(img.convert("L")).reshape(-1)[::97].tolist())) > 5


def _leftovers(folder: Path, name: str) -> list[Path]:
    return [p for p in folder.iterdir() if p.name != name]


# --------------------------------------------------------------------------------------------
# error_map
# --------------------------------------------------------------------------------------------


def _plane_points(n: int) -> tuple[NDArray, NDArray, NDArray]:
    """Points above/below the plane by known offsets along z, their params and offsets."""
    uv = RNG.uniform(0.05, 0.95, size=(n, 2))
    offsets = RNG.uniform(-0.2, 0.2, size=n)
    pts = Plane().evaluate(uv[:, 0], uv[:, 1])
    pts[:, 2] += offsets
    return pts, uv, np.abs(offsets)


def test_error_map_stats_with_params(tmp_path: Path) -> None:
    pts, uv, err = _plane_points(500)
    out = tmp_path / "err.png"
    stats = error_map(Plane(), pts, uv, out, resolution=20)
    assert stats["n"] == 500
    assert stats["mean"] == pytest.approx(err.mean(), abs=1e-14)
    assert stats["max"] == pytest.approx(err.max(), abs=1e-14)
    _check_png(out)
    assert _leftovers(tmp_path, "err.png") == []


def test_error_map_stats_without_params(tmp_path: Path) -> None:
    # Interior points, offset along the normal: the closest point is the foot of the offset.
    pts, _, err = _plane_points(300)
    stats = error_map(Plane(), pts, None, tmp_path / "err.png", resolution=20)
    assert stats["n"] == 300
    assert stats["mean"] == pytest.approx(err.mean(), abs=1e-9)
    assert stats["max"] == pytest.approx(err.max(), abs=1e-9)
    _check_png(tmp_path / "err.png")


@pytest.mark.parametrize("suffix", [".svg", ".pdf"])
def test_error_map_other_formats(tmp_path: Path, suffix: str) -> None:
    pts, uv, _ = _plane_points(50)
    out = tmp_path / f"err{suffix}"
    error_map(Plane(), pts, uv, out, title="custom", resolution=10)
    head = out.read_bytes()[:200]
    assert (b"<svg" in head or b"<?xml" in head) if suffix == ".svg" else head.startswith(b"%PDF")


def test_error_map_subsamples_large_clouds(tmp_path: Path) -> None:
    pts, uv, err = _plane_points(25_000)
    stats = error_map(Plane(), pts, uv, tmp_path / "big.png", resolution=10)
    assert stats["n"] == 25_000
    assert stats["max"] == pytest.approx(err.max(), abs=1e-14)


def test_error_map_missing_folder_raises_and_leaves_nothing(tmp_path: Path) -> None:
    pts, uv, _ = _plane_points(20)
    out = tmp_path / "nope" / "err.png"
    with pytest.raises(ExportError):
        error_map(Plane(), pts, uv, out, resolution=10)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_error_map_bad_input(tmp_path: Path) -> None:
    pts, uv, _ = _plane_points(20)
    with pytest.raises(InputError, match="png"):
        error_map(Plane(), pts, uv, tmp_path / "err.jpg")
    with pytest.raises(InputError, match="params"):
        error_map(Plane(), pts, uv[:5], tmp_path / "err.png")
    bad = pts.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="row 3"):
        error_map(Plane(), bad, uv, tmp_path / "err.png")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# zebra
# --------------------------------------------------------------------------------------------


def test_c1_pair_has_equal_normals_and_continuous_stripes() -> None:
    a, b = _pair("parabola")
    v = np.linspace(0.0, 1.0, 101)
    na, nb = _unit_normal(a, np.ones_like(v), v), _unit_normal(b, np.zeros_like(v), v)
    angle = _angle(na, nb)
    assert angle.max() < 1e-9

    phase = zebra_image([a, b], resolution=61, phase=True)
    values = zebra_image([a, b], resolution=61)
    assert phase.shape == values.shape == (2, 61, 61)
    assert np.abs(phase[0, -1, :] - phase[1, 0, :]).max() < 1e-9
    np.testing.assert_array_equal(values[0, -1, :], values[1, 0, :])
    assert set(np.unique(values).tolist()) <= {0.0, 1.0}
    # The stripes do vary over the patches (the test is not vacuous).
    assert 0.1 < values.mean() < 0.9


def test_c0_pair_has_a_stripe_jump() -> None:
    a, b = _pair("abs")
    v = np.linspace(0.0, 1.0, 101)
    na, nb = _unit_normal(a, np.ones_like(v), v), _unit_normal(b, np.zeros_like(v), v)
    angle = _angle(na, nb)
    assert angle.min() == pytest.approx(np.pi / 2)  # slopes -1 and +1 meet at a right angle

    phase = zebra_image([a, b], resolution=61, phase=True)
    values = zebra_image([a, b], resolution=61)
    assert np.abs(phase[0, -1, :] - phase[1, 0, :]).min() > 0.05
    assert np.any(values[0, -1, :] != values[1, 0, :])


def test_stripes_invariant_to_normal_orientation() -> None:
    # Reversing u flips the normal; reflection lines must not change.
    class Flipped(Graph):
        def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
            return super().evaluate(1.0 - np.asarray(u, float), v)

        def derivatives(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray, NDArray]:
            su, sv = super().derivatives(1.0 - np.asarray(u, float), v)
            return -su, sv

    base = zebra_image(Graph(0.0, 1.0, "parabola"), resolution=31, phase=True)[0]
    flip = zebra_image(Flipped(0.0, 1.0, "parabola"), resolution=31, phase=True)[0]
    np.testing.assert_allclose(flip[::-1], base, atol=1e-12)


def test_zebra_direction_none_and_degenerate_normals() -> None:
    class Collapsed(Plane):  # S_v = 0 on the whole patch: no normal anywhere
        def derivatives(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray, NDArray]:
            su, sv = super().derivatives(u, v)
            return su, 0.0 * sv

    assert np.isnan(zebra_image(Collapsed(), resolution=5)).all()
    img = zebra_image(_pair("parabola"), direction=None, resolution=21)
    assert np.isfinite(img).all()
    with pytest.raises(InputError, match="direction"):
        zebra_image(Plane(), direction=(0, 0, 0))
    with pytest.raises(InputError, match="stripes"):
        zebra_image(Plane(), stripes=0)
    with pytest.raises(InputError, match="derivatives"):
        zebra_image([object()])


@pytest.mark.parametrize("kind", ["parabola", "abs"])
def test_zebra_writes_png(tmp_path: Path, kind: str) -> None:
    out = tmp_path / f"zebra_{kind}.png"
    assert zebra(_pair(kind), out, resolution=40, title=kind) is None
    _check_png(out)
    assert _leftovers(tmp_path, out.name) == []


def test_zebra_missing_folder_raises_and_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "missing" / "zebra.png"
    with pytest.raises(ExportError):
        zebra(_pair("parabola"), out, resolution=10)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_failed_render_leaves_no_file(tmp_path: Path) -> None:
    class Broken(Plane):
        def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
            raise RuntimeError("boom")

    out = tmp_path / "zebra.png"
    with pytest.raises(RuntimeError, match="boom"):
        zebra([Broken()], out, resolution=10)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# light import
# --------------------------------------------------------------------------------------------


def test_import_pde2cad_does_not_import_matplotlib() -> None:
    code = (
        "import sys, pde2cad, pde2cad.plots, pde2cad.plots.surfaces; "
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_error_map_and_zebra_on_fitted_patches(tmp_path):
    import pde2cad

    rng = np.random.default_rng(3)
    uv = rng.random((4000, 2))
    pts = np.c_[uv[:, 0], uv[:, 1], 0.1 * np.sin(3 * uv[:, 0] + 2 * uv[:, 1])]
    patch = pde2cad.fit_patch(pts, continuity="c0", m=6, n=6)
    stats = error_map(patch, pts, patch.params, tmp_path / "err.png")
    assert stats["n"] == 4000
    assert abs(stats["mean"] - patch.errors["mean"]) < 1e-12
    assert abs(stats["max"] - patch.errors["max"]) < 1e-12
    zebra([patch], tmp_path / "zebra.png")
    assert Image.open(tmp_path / "zebra.png").size[0] > 100
