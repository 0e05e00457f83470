"""Shared cross-boundary derivatives (ribbons) and compatible twists for C1 reconstruction.

Each patch first estimates its own four ribbons from the points near its sides
(:func:`~pde2cad.surfaces.coons.estimate_cross_derivatives`: end values pinned to the side
derivatives, twists shared within the patch). Written as *inward* derivatives ``I(σ)`` along
the side's loop direction, two patches meeting at an edge need ``I_B = -I_A`` for a C1 join.
So per shared edge:

* ``D(t) = (I_A - I_B) / 2`` on the edge's own parameter, node by node of the Hermite pieces;
  patch A uses ``+D``, patch B ``-D``: their tangent planes along the edge coincide exactly.
* **Corner values.** Bicubic Coons needs a ribbon to start at the derivative of the patch's
  other side leaving the corner. Where the edges pair up across the corner (four patches, or
  two patches and the open boundary; see :mod:`pde2cad.layout.edges`), the joint edge fit
  made those derivatives equal and opposite, so ``+D`` and ``-D`` satisfy both patches.
  Where three or five patches meet that is impossible (vertex enclosure): each patch keeps its
  own end value, which changes its ribbon on the first Hermite piece only, and the normals
  there agree only approximately (the tangents all lie in the corner's tangent plane).
* **Twists.** At a corner every patch needs one twist ``S_uv`` matching both its ribbons; the
  inward ribbons' slopes *away from the corner* flip sign across each shared edge, so one
  vector ``ω`` per corner, with alternating signs around it, keeps all patches compatible.
  Around an odd number of patches the only such value is zero.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pde2cad.layout.edges import EdgeNetwork, Key, key_of
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import Ribbons, estimate_cross_derivatives
from pde2cad.surfaces.patch import Patch

#: Hermite pieces per ribbon (a power of two: reversed breaks stay exact).
PIECES = 4
#: Edges where the two patches' own tangent planes differ by more than this (degrees) are
#: creases: their ribbons are not shared.
CREASE_ANGLE = 40.0
#: Band of points per side used by the estimate, in parameter units.
BAND = 0.2


def _nodes(curve: PiecewiseBezier, reverse: bool, sign: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Values and slopes of ``sign * curve(1 - σ if reverse else σ)`` at the ``PIECES + 1``
    uniform nodes. Exact: the ribbons are Hermite cubics on the same breaks."""
    s = np.linspace(0.0, 1.0, PIECES + 1)
    if reverse:
        return sign * curve.evaluate(1.0 - s), -sign * curve.derivative(1.0 - s)
    return sign * curve.evaluate(s), sign * curve.derivative(s)


def _inward(rib: Ribbons) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The four ribbons as inward derivatives along each side's loop direction (nodes)."""
    return [
        _nodes(rib.d_bottom, False, 1.0),
        _nodes(rib.d_right, False, -1.0),
        _nodes(rib.d_top, True, -1.0),
        _nodes(rib.d_left, True, 1.0),
    ]


def _corner_signs(
    corner: int, network: EdgeNetwork, four_sided: set[int]
) -> dict[int, float] | None:
    """Alternating sign per patch around ``corner`` (flipping across shared edges), or None
    when an odd cycle makes it impossible."""
    at = [label for label in four_sided if corner in network.loops[label]]
    if not at:
        return {}
    sign = {at[0]: 1.0}
    stack = [at[0]]
    while stack:
        label = stack.pop()
        ids = network.loops[label]
        i = ids.index(corner)
        for other_corner in (ids[i - 1], ids[(i + 1) % len(ids)]):
            for other in network.users[key_of(corner, other_corner)]:
                if other == label or other not in four_sided:
                    continue
                want = -sign[label]
                if other in sign:
                    if sign[other] != want:
                        return None
                    continue
                sign[other] = want
                stack.append(other)
    return sign


def shared_ribbons(network: EdgeNetwork, c0_patches: dict[int, Patch]) -> dict[int, Ribbons]:
    """C1-compatible ribbons for every 4-sided segment of the network.

    Parameters
    ----------
    network : EdgeNetwork
    c0_patches : dict[int, Patch]
        Each segment's C0 fit on the network's sides: its points, their parameters on the
        bilinear Coons base and the outside flags are reused.

    Returns
    -------
    dict[int, Ribbons]
        For each 4-sided segment (3-sided ones are left to a C0 fit).
    """
    four = {label for label, ids in network.loops.items() if len(ids) == 4}
    # 1. Each patch's own estimate, as inward node data per loop side.
    own: dict[int, list[tuple[NDArray[np.float64], NDArray[np.float64]]]] = {}
    for label in sorted(four):
        patch = c0_patches[label]
        bilinear = patch.base
        pts, params, outside = patch.points, patch.params, patch.outside
        rib = estimate_cross_derivatives(
            pts[~outside], params[~outside], bilinear.bottom, bilinear.right, bilinear.top,
            bilinear.left, band=BAND, pieces=PIECES,
        )
        own[label] = _inward(rib)

    # 2. Per edge, in its own parameter t (smaller corner id first): shared D(t).
    def side_of(label: int, key: Key) -> tuple[int, bool]:
        ids = network.loops[label]
        for k in range(4):
            if key_of(ids[k], ids[(k + 1) % 4]) == key:
                return k, ids[k] == key[0]
        raise KeyError(key)

    def in_t(label: int, key: Key) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        k, forward = side_of(label, key)
        val, slope = own[label][k]
        return (val, slope) if forward else (val[::-1], -slope[::-1])

    shared: dict[Key, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    for key, who in network.users.items():
        users = [u for u in who if u in four]
        if len(users) == 2 and len(who) == 2:
            (va, sa), (vb, sb) = in_t(users[0], key), in_t(users[1], key)
            if _crease(network.curves[key], va, -vb):
                continue  # a real crease: each side keeps its own ribbon (C0 there)
            shared[key] = ((va - vb) / 2, (sa - sb) / 2)

    # 3. Twist vector per corner (zero where the patch signs cannot alternate).
    omega: dict[int, NDArray[np.float64]] = {}
    eps: dict[int, dict[int, float]] = {}
    for corner in range(len(network.corners)):
        signs = _corner_signs(corner, network, four)
        if signs is None or not network.regular.get(corner, False):
            omega[corner] = np.zeros(3)
            eps[corner] = {}
            continue
        samples = []
        for label, e in signs.items():
            ids = network.loops[label]
            i = ids.index(corner)
            for k in (i - 1 if i > 0 else 3, i):  # the sides ending and starting at the corner
                _, slope = own[label][k]
                away = slope[0] if ids[k] == corner else -slope[-1]
                samples.append(e * away)
        omega[corner] = np.mean(samples, axis=0) if samples else np.zeros(3)
        eps[corner] = signs

    # 4. Each patch's ribbons: shared D (with its sign) or its own; corner values pinned to its
    # own (the side derivatives); end slopes from the corner's twist vector.
    out: dict[int, Ribbons] = {}
    for label in sorted(four):
        ids = network.loops[label]
        inward = []
        for k in range(4):
            a, b = ids[k], ids[(k + 1) % 4]
            key = key_of(a, b)
            val_own, slope_own = own[label][k]
            if key in shared:
                val_t, slope_t = shared[key]
                sign = 1.0 if network.users[key][0] == label else -1.0
                val_t, slope_t = sign * val_t, sign * slope_t
                if a == key[0]:
                    val, slope = val_t.copy(), slope_t.copy()
                else:
                    val, slope = val_t[::-1].copy(), -slope_t[::-1]
            else:
                val, slope = val_own.copy(), slope_own.copy()
            val[0], val[-1] = val_own[0], val_own[-1]
            slope[0] = eps[a].get(label, 0.0) * omega[a]
            slope[-1] = -eps[b].get(label, 0.0) * omega[b]
            inward.append((val, slope))
        out[label] = _to_ribbons(inward)
    return out


def _crease(edge: PiecewiseBezier, cross_a: NDArray[np.float64], cross_b: NDArray[np.float64]) -> bool:
    """Whether the two sides' own tangent planes along the edge differ by more than
    ``CREASE_ANGLE`` at the interior nodes (the ends may be degenerate corners)."""
    s = np.linspace(0.0, 1.0, PIECES + 1)[1:-1]
    tangent = edge.derivative(s)
    na = np.cross(tangent, cross_a[1:-1])
    nb = np.cross(tangent, cross_b[1:-1])
    cos = np.einsum("ij,ij->i", na, nb) / np.maximum(
        np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1), 1e-300
    )
    return bool(np.any(cos < np.cos(np.radians(CREASE_ANGLE))))


def _to_ribbons(inward: list[tuple[NDArray[np.float64], NDArray[np.float64]]]) -> Ribbons:
    """Inward node data per loop side -> :class:`Ribbons` in the Coons convention."""
    breaks = np.linspace(0.0, 1.0, PIECES + 1)

    def curve(val: NDArray[np.float64], slope: NDArray[np.float64], reverse: bool, sign: float) -> PiecewiseBezier:
        if reverse:
            val, slope = val[::-1], -slope[::-1]
        return PiecewiseBezier.from_hermite(sign * val, sign * slope, breaks)

    d_bottom = curve(*inward[0], False, 1.0)
    d_right = curve(*inward[1], False, -1.0)
    d_top = curve(*inward[2], True, -1.0)
    d_left = curve(*inward[3], True, 1.0)
    ends = np.array([0.0, 1.0])
    low, high = d_bottom.derivative(ends), d_top.derivative(ends)
    twists = np.stack([[low[0], high[0]], [low[1], high[1]]])  # twists[i, j] = S_uv(i, j)
    return Ribbons(d_bottom, d_right, d_top, d_left, twists)


__all__ = ["shared_ribbons"]
