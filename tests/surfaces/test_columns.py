"""Column-wise reductions give numpy's axis-0 answers (they only run faster)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pde2cad.surfaces.columns import (
    centred_columns,
    column_max,
    column_mean,
    column_min,
    scatter_matrix,
    unique_rows,
)

RNG = np.random.default_rng(13)


def test_column_reductions_equal_the_axis_reductions() -> None:
    pts = RNG.normal(size=(5000, 3)) * [1.0, 1e3, 1e-3] + 1e6
    np.testing.assert_array_equal(column_min(pts), pts.min(axis=0))
    np.testing.assert_array_equal(column_max(pts), pts.max(axis=0))
    # Pairwise sums per column: within a few roundings of the exact mean.
    exact = np.array([math.fsum(pts[:, k]) / len(pts) for k in range(3)])
    np.testing.assert_allclose(column_mean(pts), exact, rtol=1e-15)
    origin, centred = centred_columns(pts)
    assert centred.shape == (3, 5000) and centred.flags.c_contiguous
    np.testing.assert_allclose(centred, (pts - origin).T, rtol=0, atol=1e-9)
    reference = (pts - pts.mean(axis=0)).T @ (pts - pts.mean(axis=0))
    np.testing.assert_allclose(scatter_matrix(centred), reference, rtol=1e-9)


@pytest.mark.parametrize("case", ["distinct", "duplicates", "shared_first", "grid"])
def test_unique_rows_equals_numpy_unique(case: str) -> None:
    pts = RNG.random((3000, 3))
    if case == "duplicates":
        pts = np.vstack([pts, pts[:100]])[RNG.permutation(3100)]
    elif case == "shared_first":
        pts[:50, 0] = pts[50:100, 0]  # same x, different y and z
    elif case == "grid":
        pts = np.round(pts * 8) / 8
    np.testing.assert_array_equal(unique_rows(pts), np.unique(pts, axis=0))
