"""Segments that cross instead of sharing a boundary, and folds thinner than the linkage
distance: Newell's full teapot, whose handle and spout pierce the body and whose rim is a
lip 0.1 wide (its inner and outer corners 1.9 neighbour radii apart at 112k points)."""

from __future__ import annotations

import numpy as np

from pde2cad import samples
from pde2cad.layout.adjacency import build_layout
from pde2cad.layout.edges import filter_corners
from pde2cad.layout.split import split_segments

PARTS = ("rim", "body", "lid", "bottom", "handle", "spout")
BODY, HANDLE, SPOUT = range(4, 12), range(12, 16), range(16, 20)


def test_full_teapot_handle_and_spout_cross_the_body() -> None:
    cloud = samples.teapot(112_000, parts=PARTS)
    layout = build_layout(cloud.points, cloud.labels, check=False)
    # Every body segment the handle or spout passes through crosses it: no border, and the
    # body keeps its own 4 corners (before: 5-6 each, the spout 7).
    pierced = {(a, b) for a, b in layout.crossing if a in BODY and (b in HANDLE or b in SPOUT)}
    assert {b for _, b in pierced} == set(HANDLE) | set(SPOUT)
    assert not any(a in BODY and (b in HANDLE or b in SPOUT) for a, b in layout.borders)
    _, corners = filter_corners(layout, layout.tree, cloud.labels)
    assert all(len(corners[s]) == 4 for s in BODY)
    # The rim resolves: 4 corners a quarter, 2 on its inner free edge (r = 1.4), 2 on the
    # body (r = 1.5); before, 2 (inner and outer merged across the lip).
    r = np.hypot(layout.corners[:, 0], layout.corners[:, 1])
    for s in range(4):
        ids = layout.segment_corners[s]
        assert len(ids) == 4
        assert (np.abs(r[ids] - 1.4) < 0.03).sum() == 2 and (np.abs(r[ids] - 1.5) < 0.03).sum() == 2
    # Handle and spout: tubes in halves, merged and cut into quads round them (the spout's
    # lip, 2-3 radii wide, joins the spout); every segment then 3- or 4-sided.
    labels, split, report = split_segments(cloud.points, cloud.labels, layout, layout.tree)
    assert {report.merged[k] for k in (13, 15, 17, 18, 19)} == {12, 14, 16}
    _, corners = filter_corners(split, split.tree, labels)
    assert all(len(ids) in (3, 4) for ids in corners.values())


def test_crossing_search_can_be_turned_off() -> None:
    """``find_crossing=False`` (pieces of crease-bounded regions): only the pairs passed in
    (and the neighbours they spread to) cross; none without them."""
    cloud = samples.teapot(40_000, parts=("body", "handle"))
    found = build_layout(cloud.points, cloud.labels, check=False)
    assert any(a in BODY and b in HANDLE for a, b in found.crossing)
    off = build_layout(cloud.points, cloud.labels, check=False, find_crossing=False)
    assert not off.crossing
    given = [p for p in sorted(found.crossing) if p[0] in BODY and p[1] in HANDLE][:1]
    assert set(given) <= set(build_layout(cloud.points, cloud.labels, check=False,
                                          crossing=given, find_crossing=False).crossing)
