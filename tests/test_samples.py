"""The sample clouds: the teapot's patch table, labels, area-uniform sampling, true distance."""

from __future__ import annotations

import numpy as np
import pytest

from pde2cad import samples
from pde2cad.errors import InputError


def _teapot_surface() -> tuple[samples._BezierPatches, np.ndarray]:
    index = np.array(samples._TEAPOT_PATCHES.split(), dtype=np.int64).reshape(-1, 4, 4) - 1
    vertices = np.array(samples._TEAPOT_VERTICES.split(), dtype=float).reshape(-1, 3)
    return samples._BezierPatches(vertices[index]), index


def _area(surf: samples._BezierPatches, k: int, keep=None) -> float:
    t = (np.arange(300) + 0.5) / 300
    uv = np.column_stack([a.ravel() for a in np.meshgrid(t, t, indexing="ij")])
    jac = surf.jacobian(np.full(len(uv), k), uv)
    if keep is not None:
        (p,) = surf.derivs(np.full(len(uv), k), uv[:, 0], uv[:, 1])
        jac = jac * keep(p)
    return float(jac.mean())


def test_teapot_table_is_newells() -> None:
    """32 patches x 16 indices into 306 points; rim, body, lid and bottom are four copies of a
    quarter turned about z; handle and spout are mirror pairs in y."""
    surf, index = _teapot_surface()
    assert index.shape == (32, 4, 4) and index.min() == 0 and index.max() == 305
    ctrl = surf.ctrl
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for part in ("rim", "body", "lid", "bottom"):
        ids = samples._TEAPOT_PARTS[part]
        for i in ids:
            assert any(np.abs(ctrl[i] @ turn.T - ctrl[j]).max() < 1e-12 for j in ids), (part, i)
    mirror = np.diag([1.0, -1.0, 1.0])
    for a in (12, 14, 16, 18):
        assert np.abs(ctrl[a] @ mirror - ctrl[a + 1][:, ::-1]).max() < 1e-12
    # The lid-knob and bottom patches have their first row collapsed to the pole.
    for k in (*samples._TEAPOT_PARTS["lid"][:4], *samples._TEAPOT_PARTS["bottom"]):
        assert len(set(index[k, 0].tolist())) == 1


def test_teapot_labels_counts_and_closed() -> None:
    cloud = samples.teapot(6000)
    assert cloud.points.shape == (6000, 3) and cloud.name == "teapot"
    assert set(np.unique(cloud.labels).tolist()) == {*range(12), *range(20, 32)}
    assert not cloud.closed  # the lid does not reach the rim
    counts = np.bincount(cloud.labels, minlength=32)
    for part in ("rim", "body", "lid", "bottom"):
        ids = list(samples._TEAPOT_PARTS[part])
        for group in (ids[:4], ids[4:]) if len(ids) == 8 else (ids,):
            assert counts[group].max() - counts[group].min() <= 1  # four equal quarters
    body = samples.teapot(500, parts=("body",))
    assert set(np.unique(body.labels).tolist()) == set(range(4, 12)) and not body.closed
    with pytest.raises(InputError):
        samples.teapot(500, parts=("saucer",))


def test_teapot_samples_uniformly_by_area() -> None:
    """Near the bottom's pole a parameter-uniform sampling would crowd points ~10x; by area
    the share of bottom points within r < 0.5 is that disc's share of the bottom's area."""
    surf, _ = _teapot_surface()
    cloud = samples.teapot(20000, parts=("bottom",), seed=3)
    near = np.hypot(cloud.points[:, 0], cloud.points[:, 1]) < 0.5
    expect = sum(
        _area(surf, k, lambda p: np.hypot(p[:, 0], p[:, 1]) < 0.5) for k in range(28, 32)
    ) / sum(_area(surf, k) for k in range(28, 32))
    sigma = np.sqrt(expect * (1 - expect) / len(near))
    assert abs(near.mean() - expect) < 4 * sigma


def test_teapot_distance() -> None:
    clean = samples.teapot(3000)
    assert clean.distance(clean.points[:600]).max() < 1e-12 * clean.diagonal
    noisy = samples.teapot(3000, noise=0.003, seed=1)
    # Gaussian noise of sigma = 0.003 diagonal: mean |normal component| = sigma sqrt(2 / pi).
    d = noisy.distance(noisy.points[:1500])
    sigma = 0.003 * float(np.linalg.norm(np.ptp(clean.points, axis=0)))
    assert abs(d.mean() / (sigma * np.sqrt(2 / np.pi)) - 1) < 0.08
