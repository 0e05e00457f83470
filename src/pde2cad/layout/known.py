"""Corners a layout already knows: an automatic layout's coarse-mesh vertices.

:func:`~pde2cad.layout.adjacency.build_layout` infers the corners of a labelled cloud from
the points alone (where three labels meet, where a border meets the open boundary, sharp
turns). On an automatic layout that inference is the weak link: the borders of projected
coarse faces bend where the surface is curved, a bend reads as a corner, and the segment
then has 5-9 corners and is split into pieces too small to fit (seen on the Stanford
bunny: 13-20 of ~90 faces per layout). The coarse mesh already says where every corner is
and which faces share it, so :func:`with_known_corners` puts those corners into the layout
instead.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.layout.adjacency import Layout


@dataclass(frozen=True)
class KnownCorners:
    """The corners of a layout and the corners of each segment.

    Attributes
    ----------
    points : (C, 3) float
        Corner positions (on or near the surface; snapped to the cloud when used).
    segments : dict[int, tuple[int, ...]]
        Per segment label, its corners as indices into ``points``, in order around it.
    on_open : (C,) bool
        Whether each corner lies on the open boundary of the surface.
    """

    points: NDArray[np.float64]
    segments: dict[int, tuple[int, ...]]
    on_open: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def moved(self, move: Callable[[NDArray[np.float64]], NDArray[np.float64]]) -> KnownCorners:
        """The same corners with ``points`` mapped by ``move`` (e.g. a frame change)."""
        return dataclasses.replace(self, points=np.asarray(move(self.points)))


def with_known_corners(
    layout: Layout, corners: KnownCorners, points: NDArray[np.float64], labels: NDArray[np.int64],
    tree: cKDTree,
) -> Layout:
    """``layout`` with its corners replaced by ``corners``.

    1. Every labelled segment must have 3 or 4 known corners (else an :class:`InputError`
       naming it).
    2. Only the borders of segments that share a side (two consecutive corners of both)
       are kept: where two segments meet at a corner, their labels can touch along a short
       stretch in the cloud, which is no edge of the layout. A side whose border the layout
       dropped as too short to be one (``BORDER_SPAN``) gets its border back
       (:func:`_short_border`).
    3. Each corner moves to the point nearest to it among the points of its segments whose
       neighbourhood holds the most of those segments' labels (the junction of their borders
       in the cloud), within a few neighbour radii; else to the nearest cloud point.

    Returns
    -------
    Layout
    """
    present = [int(s) for s in layout.labels_present]
    for s in present:
        ids = corners.segments.get(s)
        if ids is None or len(ids) not in (3, 4):
            raise InputError(
                f"segment {s} has {0 if ids is None else len(ids)} known corners; a patch "
                "needs 3 or 4")
    sides = _sides(corners, present)
    snapped = _snap(corners, points, labels, tree, layout.radius)
    used = sorted({c for s in present for c in corners.segments[s]})
    new_id = {c: i for i, c in enumerate(used)}
    on_open = corners.on_open if len(corners.on_open) else np.zeros(len(corners.points), bool)
    borders = {p: layout.borders[p] for p in layout.borders if p in sides}
    adjacency = {p: layout.adjacency[p] for p in borders}
    for pair in sorted(sides - set(borders)):
        border = _short_border(points, labels, pair, layout.radius)
        if len(border):
            borders[pair], adjacency[pair] = border, len(border)
    return dataclasses.replace(
        layout,
        adjacency=adjacency,
        borders=borders,
        corners=snapped[used],
        segment_corners={s: np.array(sorted(new_id[c] for c in corners.segments[s]),
                                     dtype=np.int64) for s in present},
        open_corners=np.asarray(on_open, dtype=bool)[used],
        sharp_corners=np.ones(len(used), dtype=bool),
    )


def _sides(corners: KnownCorners, present: list[int]) -> set[tuple[int, int]]:
    """Step 2 of :func:`with_known_corners`: the segment pairs that share a side."""
    owner: dict[tuple[int, int], list[int]] = {}
    for s in present:
        ids = corners.segments[s]
        for a, b in zip(ids, ids[1:] + ids[:1]):
            owner.setdefault((min(a, b), max(a, b)), []).append(s)
    return {(min(o), max(o)) for o in owner.values() if len(o) == 2}


def _short_border(points: NDArray[np.float64], labels: NDArray[np.int64], pair: tuple[int, int],
                  radius: float) -> NDArray[np.float64]:
    """The points of either segment of ``pair`` within ``radius`` of the other."""
    a, b = (points[labels == s] for s in pair)
    near_b = np.isfinite(cKDTree(b).query(a, distance_upper_bound=radius)[0])
    near_a = np.isfinite(cKDTree(a).query(b, distance_upper_bound=radius)[0])
    return np.vstack([a[near_b], b[near_a]])


#: Neighbour radii around a known corner searched for its junction in the cloud.
SNAP_REACH = 4.0
#: Neighbours per point whose labels show a junction.
SNAP_NEIGHBOURS = 12


def _snap(corners: KnownCorners, points: NDArray[np.float64], labels: NDArray[np.int64],
          tree: cKDTree, radius: float) -> NDArray[np.float64]:
    """Step 3 of :func:`with_known_corners`: each corner on its junction in the cloud."""
    owners: dict[int, set[int]] = {}
    for s, ids in corners.segments.items():
        for c in ids:
            owners.setdefault(c, set()).add(s)
    out = np.asarray(corners.points, dtype=np.float64).copy()
    _, nearest = tree.query(out, workers=-1)
    out[:] = points[nearest]
    near = tree.query_ball_point(out, SNAP_REACH * radius, workers=-1)
    for c, own in owners.items():
        idx = np.asarray(near[c], dtype=np.int64)
        if len(own) < 2 or len(idx) < 2:
            continue
        _, hood = tree.query(points[idx], k=min(SNAP_NEIGHBOURS, len(points)), workers=-1)
        lab = np.where(np.isin(labels[hood], list(own)), labels[hood], -1)
        lab.sort(axis=1)
        distinct = (np.diff(lab, axis=1) != 0).sum(axis=1) + (lab[:, 0] >= 0)
        if distinct.max() < 2:
            continue
        best = distinct == distinct.max()
        cand = idx[best]
        out[c] = points[cand[np.argmin(np.linalg.norm(points[cand] - out[c], axis=1))]]
    return out
