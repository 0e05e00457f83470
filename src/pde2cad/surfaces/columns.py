"""Reductions over the rows of tall point arrays, one column at a time.

numpy reduces a C-ordered ``(N, D)`` array along ``axis=0`` with a short inner loop over its
D columns; for D = 2 or 3 that runs 10-20x slower than D reductions of the contiguous-stride
columns themselves (1e6 x 3 points: ``max(axis=0)`` 88 ms, per column 4 ms), and a whole
cloud goes through several such reductions on its way to a patch. (Row-wise tests such as
``isfinite(...).all(axis=1)`` are as slow: test the whole array, and find the bad rows only
to report them.)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray


def column_min(points: NDArray[Any]) -> NDArray[Any]:
    """Smallest value of every column of ``points`` (N, D), N >= 1: (D,), same dtype."""
    return np.array([points[:, k].min() for k in range(points.shape[1])])


def column_max(points: NDArray[Any]) -> NDArray[Any]:
    """Largest value of every column of ``points`` (N, D), N >= 1: (D,), same dtype."""
    return np.array([points[:, k].max() for k in range(points.shape[1])])


def column_mean(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean of every column of ``points`` (N, D), N >= 1 (pairwise summation): (D,)."""
    return np.array([points[:, k].mean() for k in range(points.shape[1])])


def centred_columns(
    points: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The column means (D,) and the centred points coordinate-major, ``(D, N)`` C-ordered:
    every coordinate one contiguous row, which the scatter matrix and plane coordinates
    then read at full speed."""
    origin = column_mean(points)
    return origin, np.subtract(points.T, origin[:, None], order="C")


def scatter_matrix(centred: NDArray[np.float64]) -> NDArray[np.float64]:
    """``sum_i c_i c_i^T`` (D, D) of coordinate-major points ``centred`` (D, N).

    einsum rather than ``@``: a threaded BLAS call costs more than this sum on a loaded
    machine.
    """
    return np.einsum("ik,jk->ij", centred, centred)



def unique_rows(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.unique(points, axis=0)`` of (N, D) float rows, N >= 1: the distinct rows in
    lexicographic order.

    np.unique sorts the rows as structured records (70k rows: 55 ms). When no two rows
    share their first coordinate (scanned and random clouds, unless duplicated) the rows
    sorted by it are already that answer (9 ms); otherwise np.unique decides.
    """
    order = np.argsort(points[:, 0], kind="stable")
    rows = points[order]
    if (np.diff(rows[:, 0]) == 0.0).any():
        return np.unique(points, axis=0)
    return rows
