"""Shared cross-boundary derivatives (ribbons) and compatible twists for C1 reconstruction.

Each patch first estimates its own four ribbons from the points near its sides
(:func:`~pde2cad.surfaces.coons.estimate_cross_derivatives`: end values pinned to the side
derivatives, twists shared within the patch). Written as *inward* derivatives ``I(σ)`` along
the side's loop direction, two patches meeting at an edge need ``I_B = -I_A`` for a C1 join.
The corner values are fixed: bicubic Coons needs a ribbon to start at the derivative of the
patch's other side leaving the corner, and each patch keeps its own.

* **Regular edges** (both corners regular: four patches, or two and the open boundary; see
  :mod:`pde2cad.layout.edges`). Patch A uses ``lambda_A D``, patch B ``-lambda_B D``, with
  ``D`` shared, node by node of the Hermite pieces on the edge's own parameter. The joint
  edge fit made the side derivatives at such corners opposite, each scaled to its edge's
  length (a pair's speed ratio ``r``), so ``lambda_A / lambda_B = r`` at each end meets both
  patches' end values; the edge fit keeps ``r`` equal at both ends of such an edge, so the
  lambdas are constants and both ribbons are parallel all along it: G1 along the whole
  edge (C1 where ``r = 1``). Should the two ends differ, the lambdas blend between them
  with zero end slopes (:func:`_pair_lambdas`), exact at the nodes only. At a corner every
  patch needs one twist ``S_uv`` matching both its ribbons; the inward ribbons' slopes *away
  from the corner* flip sign and scale by ``r`` across each shared edge, so one vector ``ω``
  per corner, times each patch's product of its two sides' speeds there and with
  alternating signs around it, keeps all patches compatible.
* **Edges with an odd-valence end** (three or five patches, e.g. a cube-sphere; vertex
  enclosure: exact G1 of bicubic patches is impossible there). Averaging ``I_A`` and
  ``-I_B`` would cancel each patch's component *along* the edge, the shear of its
  parameterization, which near such a corner is large (the patches meet at angles far from
  90 degrees) and pinned at the corner, so the ribbon would swing back within one Hermite
  piece; and a zero twist (the only compatible one around an odd cycle) bends the base
  further. Instead each patch keeps its own along-edge part ``alpha C'`` and only the part
  across the edge, ``D``, is shared: ``R_A = D + alpha_A C'``, ``R_B = -D + alpha_B C'``,
  both in the plane of ``C'`` and ``D`` (G1 between the end pieces). Each patch has its own
  twist at such a corner, and the node data (``D``, twists, the slopes ``D'`` at the ends)
  are one least-squares fit of all bicubic bases to their points (re-projected ``ROUNDS``
  times), plus a penalty (``G1_WEIGHT``) asking each end slope's component along the
  corner normal to keep the tangent planes shared to first order. Between the nodes the
  two ribbons (pinned to different end values) still part, 2-6 degrees inside the end
  pieces on k-means capsules; so the slopes ``D'`` at the interior nodes are each side's
  own, and more penalty rows (``PIECE_WEIGHT``) ask both ribbons to have no component along
  the shared normal at ``PIECE_SAMPLES`` of every piece (:func:`_piece_rows`).
* **Edges ending at the apex of one of their users only** (a 3-sided piece next to a
  4-sided one, common where a split cuts a segment) are fitted as odd-valence edges: the
  3-sided side's ribbon vanishes at its apex, the other's does not, so only the cross part
  can be shared.
* After the fit, an edge whose two ribbons still give normals more than ``FOLD_ANGLE``
  apart somewhere (a ribbon folding over between two nodes) is fitted again with each
  side's own ribbon (:func:`_folded`).

Measured on the 6-patch cube-sphere (20000 clean points): no C0 fallback (C1 fit at most
1.1 times the C0 one), largest normal angle across edges 0.4 degrees, within the end pieces
(under 0.1 elsewhere, from the cubic interpolation of ``alpha C'``), true error 6e-5 of the
diagonal. With ``±D`` everywhere and zero twists the C1 fits were 4-7 times worse than C0
and every patch fell back to it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from pde2cad.errors import FitError
from pde2cad.layout.edges import EdgeNetwork, Key, key_of, mls_project
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import (
    BicubicCoons,
    BilinearCoons,
    Ribbons,
    apex_ribbon,
    estimate_cross_derivatives,
)
from pde2cad.surfaces.patch import Patch
from pde2cad.surfaces.projection import project_points

#: Hermite pieces per ribbon (a power of two: reversed breaks stay exact).
PIECES = 4
#: The ribbons' nodes (uniform breaks).
BREAKS = np.linspace(0.0, 1.0, PIECES + 1)
#: Number of ribbon nodes.
NODES = BREAKS.size
#: Edges where the two patches' own tangent planes differ by more than this (degrees) are
#: creases: their ribbons are not shared.
CREASE_ANGLE = 40.0
#: Points of a patch whose quadric gives its own normal along a crease side (one-sided
#: normals at a border scatter more than centred ones, so wider than a projection's).
CREASE_NEIGHBOURS = 120
#: Band of points per side used by the estimate, in parameter units.
BAND = 0.2
#: Ridge weight pulling the joint fit towards the per-patch estimates, relative to the mean
#: diagonal of the normal equations (only matters where the points leave an unknown loose).
RIDGE = 1e-6
#: Weight of the tangent-plane agreement of the ribbons' end slopes at odd-valence corners,
#: relative to the mean diagonal of the normal equations.
G1_WEIGHT = 1.0
#: Re-projections of the points onto the fitted bases (each followed by a refit).
ROUNDS = 1
#: 3-sided patches: apex twists of a uniform sweep of the tangent directions (see
#: :func:`_sweep_twists`) instead of the estimate's (which carries the bilinear patch's
#: uneven parameterization near the apex, twice as fast measured on the teapot bottom).
APEX_SWEEP = True
#: (band, pieces) retried, in order, when a 3-sided patch's estimate is rank-deficient.
APEX_RETRIES = ((0.3, PIECES), (BAND, 2), (BAND, 1))


def _nodes(curve: PiecewiseBezier, reverse: bool, sign: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Values and slopes of ``sign * curve(1 - σ if reverse else σ)`` at the ribbon nodes
    ``BREAKS``."""
    s = BREAKS
    if reverse:
        return sign * curve.evaluate(1.0 - s), -sign * curve.derivative(1.0 - s)
    return sign * curve.evaluate(s), sign * curve.derivative(s)


def _inward(rib: Ribbons, n_sides: int = 4) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The ribbons of the real sides as inward derivatives along each side's loop direction
    (nodes): four, or three for a 3-sided patch (bottom, right, left; the top is the apex)."""
    if n_sides == 3:
        return [
            _nodes(rib.d_bottom, False, 1.0),
            _nodes(rib.d_right, False, -1.0),
            _nodes(rib.d_left, True, 1.0),
        ]
    return [
        _nodes(rib.d_bottom, False, 1.0),
        _nodes(rib.d_right, False, -1.0),
        _nodes(rib.d_top, True, -1.0),
        _nodes(rib.d_left, True, 1.0),
    ]


def _on_crease_sheets(
    network: EdgeNetwork, label: int,
    inward: list[tuple[NDArray[np.float64], NDArray[np.float64]]], points: NDArray[np.float64],
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """``inward`` node data with the sides on creases moved into the patch's own tangent
    plane along them (its points' quadric, ``CREASE_NEIGHBOURS`` of them, at each node).

    A crease ribbon is not shared: it alone sets the patch's normal along the crease. The
    estimate from the points near the side reads their bilinear parameters, which on a
    curved side (a fillet's run into a flat) are skewed along it, so the estimate leans out
    of the surface (a filleted box: side band normals 18 deg off at its sharp edges). The
    own surface's normal at the side does not depend on the parameterization.
    """
    ids = network.loops[label]
    sides = [k for k in range(len(inward)) if key_of(ids[k], ids[(k + 1) % len(ids)]) in network.creases]
    if not sides or len(points) < 12:
        return inward
    tree = cKDTree(points)
    out = list(inward)
    for k in sides:
        key = key_of(ids[k], ids[(k + 1) % len(ids)])
        along = BREAKS if ids[k] == key[0] else 1.0 - BREAKS
        _, normal = mls_project(network.curves[key].evaluate(along), points, tree, CREASE_NEIGHBOURS)
        val, slope = inward[k]
        out[k] = (val - np.einsum("ij,ij->i", val, normal)[:, None] * normal,
                  slope - np.einsum("ij,ij->i", slope, normal)[:, None] * normal)
    return out


def _sweep_twists(
    left: PiecewiseBezier,
    right: PiecewiseBezier,
    normal: NDArray[np.float64],
    estimate: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Apex twists ``S_uv(0, 1), S_uv(1, 1)`` of a 3-sided patch for which
    ``d_top(u) = S_v(u, 1)`` turns uniformly from ``L = left'(1)`` to ``R = right'(1)`` in the
    tangent plane (normal ``normal``) with linearly varying length: with ``theta`` the angle
    between them, ``e_L, e_R`` their directions and ``p_L, p_R`` the in-plane unit normals
    to them in the sense of the turn,
    ``S_uv(0, 1) = (|R| - |L|) e_L + theta |L| p_L`` and
    ``S_uv(1, 1) = (|R| - |L|) e_R + theta |R| p_R``
    (the derivatives of ``r(u) (cos theta u, sin theta u)``, a uniform polar parameterization
    of the pole). ``estimate`` (2, D), the fitted twists, only decides the sense of the turn
    when ``L`` and ``R`` are (anti)parallel."""
    end = np.array([1.0])
    lv, rv = left.derivative(end)[0], right.derivative(end)[0]
    nrm = normal / max(float(np.linalg.norm(normal)), 1e-300)
    ll, lr = max(float(np.linalg.norm(lv)), 1e-300), max(float(np.linalg.norm(rv)), 1e-300)
    el, er = lv / ll, rv / lr
    theta = float(np.arccos(np.clip(el @ er, -1.0, 1.0)))
    pl, pr = np.cross(nrm, el), np.cross(nrm, er)
    pl /= max(float(np.linalg.norm(pl)), 1e-300)
    pr /= max(float(np.linalg.norm(pr)), 1e-300)
    # Sense: towards R at the L end (and away from L at the R end).
    sense = float(pl @ er - pr @ el)
    if abs(sense) < 1e-6:
        sense = float(pl @ estimate[0] + pr @ estimate[1])
    sign = 1.0 if sense >= 0.0 else -1.0
    return (lr - ll) * el + sign * theta * ll * pl, (lr - ll) * er + sign * theta * lr * pr


def _corner_signs(
    corner: int, network: EdgeNetwork, four_sided: set[int], apex: dict[int, int] | None = None
) -> dict[int, float] | None:
    """Alternating sign per patch around ``corner`` (flipping across shared edges), or None
    when an odd cycle makes it impossible. Patches whose apex is ``corner`` (3-sided) take
    no part: their twists there are the apex ones (see :func:`shared_ribbons`)."""
    apex = apex or {}
    four_sided = {label for label in four_sided if apex.get(label) != corner}
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
        For each 3- or 4-sided segment whose points determine its own ribbons (sparse ones
        are left to a C0 fit).

    Notes
    -----
    A 3-sided segment (loop ``[a, b, apex]``, Fig. 5.11) shares the ribbons of its three real
    sides exactly as a 4-sided one. At its apex the left and right ribbons vanish (the top
    side is a point) and their slopes there are the apex twists, which are also the end
    slopes of ``d_top`` (:func:`~pde2cad.surfaces.coons.apex_ribbon`). Across an edge ending
    at the apex of both its users, C1 asks the two inward ribbons' slopes at the apex to be
    opposite: one vector per edge (the average of the two estimates, projected into the
    corner's tangent plane ``network.normals``), so every ``d_top`` around a pole lies in
    one plane and the pole has one tangent plane. An edge ending at the apex of only one of
    its users cannot be C1 near that end; only its cross part is shared (as at an
    odd-valence corner).
    """
    four = {label for label, ids in network.loops.items() if len(ids) in (3, 4)}
    apex = {label: ids[2] for label, ids in network.loops.items() if len(ids) == 3}
    # 1. Each patch's own estimate, as inward node data per loop side.
    own: dict[int, list[tuple[NDArray[np.float64], NDArray[np.float64]]]] = {}
    for label in sorted(four):
        patch = c0_patches[label]
        bilinear = patch.base
        pts, params, outside = patch.points, patch.params, patch.outside
        # A 3-sided patch's apex band is small in space and can leave the top ribbon's
        # pieces undetermined (its d_top is replaced by apex_ribbon anyway): retry wider,
        # then coarser.
        tries = ((BAND, PIECES),) if label not in apex else ((BAND, PIECES), *APEX_RETRIES)
        rib = None
        for band, pieces in tries:
            try:
                rib = estimate_cross_derivatives(
                    pts[~outside], params[~outside], bilinear.bottom, bilinear.right,
                    bilinear.top, bilinear.left, band=band, pieces=pieces,
                )
                break
            except FitError:
                continue
        if rib is None:
            # Too few points along a side to estimate its ribbon (sparse clouds): this patch
            # stays C0 (the caller lists it), its neighbours use their own ribbons there.
            continue
        own[label] = _on_crease_sheets(network, label, _inward(rib, len(network.loops[label])), pts)
        if label in apex and APEX_SWEEP:
            normal = network.normals[apex[label]]
            tau0, tau1 = _sweep_twists(bilinear.left, bilinear.right, normal, rib.twists[:, 1])
            # Inward slopes at the apex (loop sides 1 = right, ends there; 2 = left, starts
            # there) are -S_uv(1, 1) and -S_uv(0, 1).
            own[label][1][1][-1] = -tau1
            own[label][2][1][0] = -tau0
    four = set(own)

    # 2. Twists: one vector per corner where the patch signs alternate (regular corners);
    # elsewhere (odd valence) no compatible value exists, so one per patch corner.
    eps: dict[int, dict[int, float]] = {}
    for corner in range(len(network.corners)):
        signs = _corner_signs(corner, network, four, apex)
        regular = signs is not None and network.regular.get(corner, False)
        eps[corner] = signs if regular and signs is not None else {}
    omega = {corner: _omega(network, own, corner, signs) for corner, signs in eps.items() if signs}

    # 3. The joint fit of the shared ribbons; edges where it left the two sides' tangent
    # planes far apart (a ribbon folding over between nodes) are refitted plainly (shared
    # slopes, no plane rows), then if still folded with each side's own ribbon.
    plain: set[Key] = set()
    skip: set[Key] = set()
    for round_ in range(3):
        nodes = _joint(network, c0_patches, own, four, apex, eps, omega, plain, skip)
        folded = {key for key, users in network.users.items() if _folded(network, nodes, key, users)}
        if not folded - skip:
            break
        # Folded: first without the plane rows and own slopes, then with own ribbons.
        skip |= folded & plain if round_ else set()
        plain |= folded
    out: dict[int, Ribbons] = {}
    for label in sorted(four):
        n_sides = len(network.loops[label])
        bil = c0_patches[label].base
        out[label] = _to_ribbons(
            [(nodes[label][k, 0], nodes[label][k, 1]) for k in range(n_sides)], bil.left, bil.right
        )
    return out


#: A shared edge whose fitted ribbons leave the two tangent planes more than this far apart
#: (degrees, between the nodes) is refitted with each side's own ribbon.
FOLD_ANGLE = 10.0


def _folded(network: EdgeNetwork, nodes: dict[int, NDArray[np.float64]], key: Key, users: list[int]) -> bool:
    """Whether the fitted ribbons of the two ``users`` of edge ``key`` (node data per loop
    side, ``nodes``) give normals ``C' x I`` more than ``FOLD_ANGLE`` apart anywhere along it
    (sampled at 8 points per piece; the inward ribbons of the two sides point opposite)."""
    if len(users) != 2 or any(u not in nodes for u in users):
        return False
    t = np.linspace(0.0, 1.0, 8 * PIECES + 1)
    tangent = network.curves[key].derivative(t)
    normal = []
    for label, sign in zip(users, (1.0, -1.0), strict=True):
        k, forward = _side_of(network, label, key)
        val, slope = nodes[label][k, 0], nodes[label][k, 1]
        if not forward:
            val, slope = val[::-1], -slope[::-1]
        normal.append(np.cross(tangent, sign * PiecewiseBezier.from_hermite(val, slope, BREAKS).evaluate(t)))
    na, nb = normal
    cos = np.einsum("ij,ij->i", na, nb) / np.maximum(np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1), 1e-300)
    inner = slice(1, -1)  # the corners themselves may be degenerate (an apex)
    return bool(np.any(cos[inner] < np.cos(np.radians(FOLD_ANGLE))))


def _joint(
    network: EdgeNetwork, c0_patches: dict[int, Patch],
    own: dict[int, list[tuple[NDArray[np.float64], NDArray[np.float64]]]],
    four: set[int], apex: dict[int, int], eps: dict[int, dict[int, float]],
    omega: dict[int, NDArray[np.float64]], plain: set[Key], skip: set[Key],
) -> dict[int, NDArray[np.float64]]:
    """Step 3 of :func:`shared_ribbons`: per shared edge (but those in ``skip``; those in
    ``plain`` with shared slopes and no plane rows if split), each user's
    node data on the edge parameter t, as a linear map of the unknowns (see _Terms); then one
    least-squares fit of all bases to their points. Returns each patch's inward node data
    (S, 2, NODES, 3)."""
    unknowns = _Unknowns()
    sides: dict[tuple[int, Key], _Terms] = {}
    # Inward slope (edge parameter) at the apex end of edges ending at both users' apex.
    apex_slope: dict[tuple[int, Key], NDArray[np.float64]] = {}
    # Split edges: what their shared normals between the nodes come from (_piece_normals).
    piece_normals: dict[Key, tuple[Any, ...]] = {}
    for key, who in network.users.items():
        users = [u for u in who if u in four]
        if len(users) != 2 or len(who) != 2 or key in skip:
            continue
        at_apex = [[apex.get(u) == c for u in users] for c in key]
        # The apex of one user only (its ribbon vanishes there, the other's does not): each
        # keeps its own along-edge part, the part across is shared (see _split_edge).
        one_apex = any(a != b for a, b in at_apex)
        (va, sa), (vb, sb) = (_in_t(network, own[u], u, key) for u in users)
        if key in network.creases and _crease(network.curves[key], va, -vb):
            # A real crease (in the points and in both estimates): each side keeps its own
            # ribbon (C0 there). The estimates alone are not enough: one running nearly along
            # the edge (a sheared piece of a k-means capsule) read a smooth seam as 172 deg.
            continue
        # Scales of the two sides' ribbons at the ends (1 but on regular edges).
        lam = np.ones((2, NODES))
        if not one_apex and all(eps[c] or at_apex[j][0] for j, c in enumerate(key)):
            poles = (at_apex[0][0], at_apex[1][0])
            sides.update(_paired_edge(key, users, (va, sa), (vb, sb), poles))
            (lam[0], _), (lam[1], _) = _pair_lambdas(va, vb, poles)
        else:
            sides.update(_split_edge(
                network.curves[key], key, users, (va, sa), (vb, sb), unknowns, key not in plain
            ))
            if key not in plain:
                cross = [unknowns.index[("edge", key, 0, i)] for i in range(1, NODES - 1)]
                piece_normals[key] = (network.curves[key], va, vb, np.array(cross))
        for j, c in enumerate(key):
            if at_apex[j][0] and at_apex[j][1]:
                node = 0 if j == 0 else NODES - 1
                normal = network.normals[c] / max(float(np.linalg.norm(network.normals[c])), 1e-300)
                w = 0.5 * (sa[node] / lam[0, node] - sb[node] / lam[1, node])
                w = w - (w @ normal) * normal
                apex_slope[(users[0], key)] = lam[0, node] * w
                apex_slope[(users[1], key)] = -lam[1, node] * w
    data = {
        label: _patch_terms(label, network, own[label], sides, eps, omega, unknowns, apex, apex_slope)
        for label in sorted(four)
    }
    solution = _fit(network, c0_patches, data, unknowns, piece_normals)
    return {label: data[label][0].evaluate(solution) for label in sorted(four)}


class _Unknowns:
    """Vector unknowns of the joint ribbon fit, allocated by name with an initial guess."""

    def __init__(self) -> None:
        self.index: dict[tuple[object, ...], int] = {}
        self.guess: list[NDArray[np.float64]] = []

    def get(self, name: tuple[object, ...], guess: NDArray[np.float64]) -> int:
        """Index of unknown ``name``; created with value ``guess`` if new."""
        if name not in self.index:
            self.index[name] = len(self.guess)
            self.guess.append(np.asarray(guess, dtype=float))
        return self.index[name]


class _Terms:
    """Node data ``(..., 2, NODES)`` (values, slopes) that are affine in the unknowns:
    ``fixed[e] + sum coef * x[unknown]`` per entry ``e`` (scalar coefficients on vectors)."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.fixed = np.zeros((*shape, 3))
        self.terms: list[tuple[int, int, float]] = []  # (flat entry, unknown, coefficient)
        self.shape = shape

    def add(self, entry: tuple[int, ...], unknown: int, coef: float) -> None:
        """Add ``coef * x[unknown]`` to ``entry``."""
        self.terms.append((int(np.ravel_multi_index(entry, self.shape)), unknown, float(coef)))

    def matrix(self, n_unk: int) -> NDArray[np.float64]:
        """(entries, n_unk) coefficient matrix."""
        out = np.zeros((int(np.prod(self.shape)), n_unk))
        for e, u, c in self.terms:
            out[e, u] += c
        return out

    def evaluate(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The node data for unknown values ``x`` (n_unk, 3)."""
        return self.fixed + (self.matrix(x.shape[0]) @ x).reshape(self.fixed.shape)


def _in_t(
    network: EdgeNetwork,
    own: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
    label: int,
    key: Key,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A patch's own inward ribbon across edge ``key``, node data on the edge parameter."""
    k, forward = _side_of(network, label, key)
    val, slope = own[k]
    return (val, slope) if forward else (val[::-1], -slope[::-1])


def _side_of(network: EdgeNetwork, label: int, key: Key) -> tuple[int, bool]:
    """Loop side of ``label`` on edge ``key`` and whether it runs with the edge parameter."""
    ids = network.loops[label]
    for k in range(len(ids)):
        if key_of(ids[k], ids[(k + 1) % len(ids)]) == key:
            return k, ids[k] == key[0]
    raise KeyError(key)


def _omega(
    network: EdgeNetwork,
    own: dict[int, list[tuple[NDArray[np.float64], NDArray[np.float64]]]],
    corner: int,
    signs: dict[int, float],
) -> NDArray[np.float64]:
    """Twist vector of a regular corner: the mean over its patches of the own ribbons'
    slopes away from it, with the alternating signs, per unit product of the patch's side
    speeds there (:func:`_corner_speeds`)."""
    samples = []
    for label, e in signs.items():
        ids = network.loops[label]
        i = ids.index(corner)
        speeds = _corner_speeds(network, label, corner)
        for k in ((i - 1) % len(ids), i):  # the sides ending and starting at the corner
            _, slope = own[label][k]
            samples.append(e * (slope[0] if ids[k] == corner else -slope[-1]) / speeds)
    return np.mean(samples, axis=0)


def _corner_speeds(network: EdgeNetwork, label: int, corner: int) -> float:
    """Product of the speeds ``|C'|`` of the patch's two sides at ``corner``: its twist
    there scales with it (``S_uv`` of a reparameterization ``u -> a u, v -> b v`` is
    ``a b`` times the old one), which keeps the twists compatible across scaled pairs."""
    ids = network.loops[label]
    i = ids.index(corner)
    out = 1.0
    for other in (ids[i - 1], ids[(i + 1) % len(ids)]):
        key = key_of(corner, other)
        end = np.array([0.0 if key[0] == corner else 1.0])
        out *= float(np.linalg.norm(network.curves[key].derivative(end)[0]))
    return max(out, 1e-300)


def _paired_edge(
    key: Key,
    users: list[int],
    own_a: tuple[NDArray[np.float64], NDArray[np.float64]],
    own_b: tuple[NDArray[np.float64], NDArray[np.float64]],
    poles: tuple[bool, bool] = (False, False),
) -> dict[tuple[int, Key], _Terms]:
    """Both ends regular (or the apex of both users, ``poles``): ``+lambda_A D`` for the first user, ``-lambda_B D`` for the second
    (:func:`_pair_lambdas`; one tangent plane along the edge, C1 where the lambdas are 1).

    1. Each side's own estimate divided by its lambda (slopes by the product rule) gives
       ``D``; the two are averaged.
    2. Each side's node data are its signed lambda times ``D`` (values and slopes)."""
    (lam_a, dlam_a), (lam_b, dlam_b) = _pair_lambdas(own_a[0], own_b[0], poles)
    d_a, d_b = own_a[0] / lam_a[:, None], -own_b[0] / lam_b[:, None]
    s_a = (own_a[1] - dlam_a[:, None] * d_a) / lam_a[:, None]
    s_b = (-own_b[1] - dlam_b[:, None] * d_b) / lam_b[:, None]
    guess_val, guess_slope = (d_a + d_b) / 2, (s_a + s_b) / 2
    out = {}
    for label, sign, lam, dlam in zip(users, (1.0, -1.0), (lam_a, lam_b), (dlam_a, dlam_b), strict=True):
        # Not refitted: the averaged estimates measured better after the deformation on the
        # cylinder than a least-squares refit of the bases (which weighs the interior, where
        # the deformation works anyway), though slightly worse on the torus.
        terms = _Terms((2, NODES))
        terms.fixed[0] = sign * lam[:, None] * guess_val
        terms.fixed[1] = sign * (dlam[:, None] * guess_val + lam[:, None] * guess_slope)
        out[(label, key)] = terms
    return out


def _pair_lambdas(
    val_a: NDArray[np.float64], val_b: NDArray[np.float64], poles: tuple[bool, bool] = (False, False)
) -> tuple[tuple[NDArray[np.float64], NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Scale factors of the two inward ribbons of a regular edge on ``D``, values and slopes
    at the nodes, from the two sides' own node values ``val_a``, ``val_b`` (NODES, 3).

    1. At each end the speed ratio ``r = |I_A| / |I_B|`` (the sides' own end values are
       the pair's opposite, scaled side derivatives); an end at the apex of both users
       (``poles``; both vanish, their ratio is rounding noise) takes the other end's
       ratio, 1 when both are.
    2. ``lambda_A = 2 r / (1 + r)``, ``lambda_B = 2 / (1 + r)`` there (their ratio is
       ``r``; both 1 for ``r = 1``), blended along the edge by ``3 t^2 - 2 t^3``: zero slopes
       at the corners keep the twists of :func:`_corner_speeds` compatible, and equal end
       ratios give constants (both ribbons exactly parallel)."""
    na, nb = np.linalg.norm(val_a[[0, -1]], axis=1), np.linalg.norm(val_b[[0, -1]], axis=1)
    ok = ~np.array(poles) & (na > 0) & (nb > 0)
    r = np.where(ok, na / np.maximum(nb, 1e-300), 1.0)
    if ok.sum() == 1:
        r[:] = r[ok][0]
    t = BREAKS
    w, dw = 3 * t**2 - 2 * t**3, 6 * t - 6 * t**2
    out = []
    for end_values in (2 * r / (1 + r), 2 / (1 + r)):
        lo, hi = end_values
        out.append((lo + (hi - lo) * w, (hi - lo) * dw))
    return out[0], out[1]


def _split_edge(
    edge: PiecewiseBezier,
    key: Key,
    users: list[int],
    own_a: tuple[NDArray[np.float64], NDArray[np.float64]],
    own_b: tuple[NDArray[np.float64], NDArray[np.float64]],
    unknowns: _Unknowns,
    own_slopes: bool = True,
) -> dict[tuple[int, Key], _Terms]:
    """Edge with an end of odd valence: ``R = s D(t) + alpha(t) C'(t)`` per user.

    ``s`` = +1 / -1 for the two users and ``D`` shared (unknown), so between the end nodes
    both ribbons lie in the plane of ``C'`` and ``D``: one tangent plane on both sides.
    ``alpha C'`` is each patch's own component along the edge (``alpha = I.C' / |C'|^2`` of
    its estimate ``I``): the shear of its parameterization, different on the two sides and
    large near corners where the patches meet at other than right angles. Sharing it too
    (``(I_A - I_B) / 2``) would cancel it, and the end values (pinned to each patch's own
    side derivative) would then have to swing back within one Hermite piece.

    Besides the node data ``[0]``, ``[1]``, the returned terms carry in ``[2]`` the end
    slopes that keep the tangent plane shared to first order,
    ``s D'(end) + (alpha C')'(end)`` with ``D'(end)`` a shared unknown; only their component
    along the corner normal is asked for (see :func:`_fit`).
    """
    t = BREAKS
    d1, d2 = edge.derivative(t), edge.derivative(t, 2)
    sq = np.einsum("ij,ij->i", d1, d1)
    along = {}
    for label, (val, slope) in zip(users, (own_a, own_b), strict=True):
        dot = np.einsum("ij,ij->i", val, d1)
        alpha = dot / sq
        dalpha = (np.einsum("ij,ij->i", slope, d1) + np.einsum("ij,ij->i", val, d2)) / sq
        dalpha -= 2.0 * dot * np.einsum("ij,ij->i", d1, d2) / sq**2
        along[label] = (alpha[:, None] * d1, dalpha[:, None] * d1 + alpha[:, None] * d2)
    guess_val = (own_a[0] - along[users[0]][0] - own_b[0] + along[users[1]][0]) / 2
    guess_slope = (own_a[1] - along[users[0]][1] - own_b[1] + along[users[1]][1]) / 2
    out = {}
    for label, s in zip(users, (1.0, -1.0), strict=True):
        terms = _Terms((3, NODES))
        terms.fixed[0], terms.fixed[1] = along[label]
        for i in range(NODES):
            if i in (0, NODES - 1):
                d_slope = unknowns.get(("edge", key, 1, i), guess_slope[i])
                # End: the value is the patch's own (pinned); [2] the plane-keeping slope.
                terms.fixed[2, i] = terms.fixed[1, i]
                terms.add((2, i), d_slope, s)
                continue
            terms.add((0, i), unknowns.get(("edge", key, 0, i), guess_val[i]), s)
            # Next to the corners each side's own slope (_piece_rows keeps the plane between
            # the nodes); own slopes at the middle node too bent the 3-valent ellipsoid6
            # (volume 4.7e-4 off instead of 2e-5).
            if own_slopes and i in (1, NODES - 2):
                terms.add((1, i), unknowns.get(("edge", key, 1, i, label), guess_slope[i]), s)
            else:
                terms.add((1, i), unknowns.get(("edge", key, 1, i), guess_slope[i]), s)
        out[(label, key)] = terms
    return out


def _patch_terms(
    label: int,
    network: EdgeNetwork,
    own: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
    sides: dict[tuple[int, Key], _Terms],
    eps: dict[int, dict[int, float]],
    omega: dict[int, NDArray[np.float64]],
    unknowns: _Unknowns,
    apex: dict[int, int] | None = None,
    apex_slope: dict[tuple[int, Key], NDArray[np.float64]] | None = None,
) -> tuple[_Terms, _Terms]:
    """A patch's inward node data (S, 2, NODES) as affine terms, and the end-slope
    targets (S, 2, 2): per side, ``[k, 0]`` the entry's own expression, ``[k, 1]`` its target
    (unused entries zero). ``S`` = 3 or 4 sides; at the apex of a 3-sided patch the end
    slope is the shared ``apex_slope`` of the edge (edge parameter), else its own."""
    ids = network.loops[label]
    n_sides = len(ids)
    apex_corner = (apex or {}).get(label)
    apex_slope = apex_slope or {}
    nodes = NODES
    data = _Terms((n_sides, 2, nodes))
    targets = _Terms((n_sides, 2, 2))
    for k in range(n_sides):
        a, b = ids[k], ids[(k + 1) % n_sides]
        key = key_of(a, b)
        val_own, slope_own = own[k]
        data.fixed[k, 0, 0], data.fixed[k, 0, -1] = val_own[0], val_own[-1]
        edge = sides.get((label, key))
        forward = a == key[0]
        if edge is not None:
            sgn = 1.0 if forward else -1.0
            for i in range(nodes):
                t = i if forward else nodes - 1 - i
                if 0 < i < nodes - 1:
                    data.fixed[k, 0, i] = edge.fixed[0, t]
                    data.fixed[k, 1, i] = sgn * edge.fixed[1, t]
            for e, u, c in edge.terms:
                row, col = np.unravel_index(e, edge.shape)
                node = col if forward else nodes - 1 - col
                if 0 < node < nodes - 1 and row < 2:
                    data.add((k, int(row), int(node)), u, c if row == 0 else sgn * c)
                elif row == 2:
                    targets.add((k, 1, 0 if node == 0 else 1), u, sgn * c)
            if edge.shape[0] == 3:
                for end, i in ((0, 0), (1, nodes - 1)):
                    t = i if forward else nodes - 1 - i
                    targets.fixed[k, 1, end] = sgn * edge.fixed[2, t]
        else:
            data.fixed[k, :, 1:-1] = np.stack([val_own, slope_own])[:, 1:-1]
        # End slopes: the twist at each corner (inward slope away from it), +tau at the
        # start of a side and -tau at its end.
        ends = ((0, a, 1.0, slope_own[0]), (1, b, -1.0, -slope_own[-1]))
        for end, corner, sgn_end, guess in ends:
            i = 0 if end == 0 else nodes - 1
            if corner == apex_corner:
                # The apex: value 0 (pinned above), slope shared across the edge.
                w = apex_slope.get((label, key))
                if w is None:  # unshared: the own slope, in the corner's tangent plane
                    normal = network.normals[corner]
                    normal = normal / max(float(np.linalg.norm(normal)), 1e-300)
                    w = slope_own[i] - (slope_own[i] @ normal) * normal
                    data.fixed[k, 1, i] = w
                else:
                    data.fixed[k, 1, i] = (1.0 if forward else -1.0) * w
                continue
            if label in eps[corner]:
                speeds = _corner_speeds(network, label, corner)
                data.fixed[k, 1, i] = sgn_end * eps[corner][label] * speeds * omega[corner]
            else:
                x = unknowns.get(("twist", label, corner), guess)
                data.add((k, 1, i), x, sgn_end)
                targets.add((k, 0, end), x, sgn_end)
    # Targets only count where the side is split (its [k, 1] terms exist).
    return data, targets


def _fit(
    network: EdgeNetwork,
    patches: dict[int, Patch],
    data: dict[int, tuple[_Terms, _Terms]],
    unknowns: _Unknowns,
    piece_normals: dict[Key, tuple[Any, ...]] | None = None,
) -> NDArray[np.float64]:
    """Least-squares values of all unknowns: every patch's bicubic Coons base on its sides,
    as close as possible to its points, and the end slopes at odd-valence corners close to
    the ones that keep the tangent plane shared (weight ``G1_WEIGHT``).

    The base is linear in its ribbon data, so the columns come from one evaluation in as
    many dimensions as node entries (a unit datum each). The parameters start as the C0
    fit's and are re-projected onto the new bases ``ROUNDS`` times, so the fit stops
    matching the bilinear patch's parameterization and measures distances instead."""
    n_unk = len(unknowns.guess)
    if n_unk == 0:
        return np.zeros((0, 3))
    guess = np.array(unknowns.guess)
    params = {label: patches[label].params[~patches[label].outside] for label in data}
    points = {label: patches[label].points[~patches[label].outside] for label in data}
    mats = {label: (d.matrix(n_unk), t.matrix(n_unk)) for label, (d, t) in data.items()}
    # Penalty rows: the end slopes of split sides at odd-valence corners (where the end
    # slope is a patch twist and the target exists; at a regular end the twist stays ω).
    pen_a, pen_b, pen_n = [], [], []
    for label, (_, targets) in data.items():
        tm = mats[label][1].reshape(len(network.loops[label]), 2, 2, n_unk)
        has = (np.abs(tm[:, 0]).sum(axis=-1) > 0) & (np.abs(tm[:, 1]).sum(axis=-1) > 0)
        ids = network.loops[label]
        for k, end in zip(*np.nonzero(has), strict=True):
            pen_a.append(tm[k, 0, end] - tm[k, 1, end])
            pen_b.append(targets.fixed[k, 1, end] - targets.fixed[k, 0, end])
            pen_n.append(network.normals[ids[(k + end) % len(ids)]])
    # Each patch's node entries (rows) and the unknowns they depend on (columns): a patch
    # touches a few dozen of the network's unknowns (1124 on a 138-patch torus).
    used = {}
    for label, (mat, _) in mats.items():
        rows = np.flatnonzero(np.abs(mat).sum(axis=1) > 0)
        if rows.size:  # else nothing of this patch is fitted
            used[label] = (rows, np.flatnonzero(np.abs(mat[rows]).sum(axis=0) > 0))
    solution = guess
    for round_ in range(ROUNDS + 1):
        ata = np.zeros((n_unk, n_unk))
        atb = np.zeros((n_unk, 3))
        for label, (local, cols_of) in used.items():
            terms = data[label][0]
            bil = patches[label].base
            if round_:
                base = _bicubic(bil, terms.evaluate(solution))
                params[label] = project_points(base, points[label], initial=params[label])[0]
            u, v = params[label][:, 0], params[label][:, 1]
            base0 = _bicubic(bil, terms.fixed).evaluate(u, v)
            unit = np.zeros((mats[label][0].shape[0], local.size))
            unit[local, np.arange(local.size)] = 1.0
            cols = _bicubic(bil, unit.reshape(*terms.shape, local.size), sides=False).evaluate(u, v)
            a = cols @ mats[label][0][np.ix_(local, cols_of)]
            ata[np.ix_(cols_of, cols_of)] += a.T @ a
            atb[cols_of] += a.T @ (points[label] - base0)
        plane = _plane_penalty(network, data, mats, piece_normals or {}, solution)
        penalty = (pen_a + plane[0], pen_b + plane[1], pen_n + plane[2])
        solution = _solve(ata, atb, guess, penalty)
    return solution


def _plane_penalty(
    network: EdgeNetwork, data: dict[int, tuple[_Terms, _Terms]],
    mats: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]],
    piece_normals: dict[Key, tuple[Any, ...]], solution: NDArray[np.float64],
) -> tuple[list[Any], list[Any], list[Any]]:
    """All patches' :func:`_piece_rows`, with the normals between the nodes of the split
    edges from the shared cross parts of the current ``solution``."""
    normals = {
        key: _piece_normals(curve, own_a, own_b, solution[index])
        for key, (curve, own_a, own_b, index) in piece_normals.items()
    }
    out: tuple[list[Any], list[Any], list[Any]] = ([], [], [])
    for label, (mat, _) in mats.items():
        for part, rows in zip(out, _piece_rows(network, label, data[label][0], mat, normals), strict=True):
            part.extend(rows)
    return out

#: Samples per Hermite piece of a split edge where both ribbons are asked to stay in the
#: shared tangent plane (fractions of the piece, from its start).
PIECE_SAMPLES = np.array([0.25, 0.5, 0.75])
#: Weight of those rows, as ``G1_WEIGHT``.
PIECE_WEIGHT = 10.0


def _piece_normals(
    edge: PiecewiseBezier, own_a: NDArray[np.float64], own_b: NDArray[np.float64],
    cross: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Unit normals (PIECES, PIECE_SAMPLES, 3) of the shared tangent plane along a split
    edge, at ``PIECE_SAMPLES`` of each Hermite piece (edge parameter).

    1. At the end nodes ``C' x (I_A - I_B)`` of the two inward estimates ``own_a``,
       ``own_b`` (NODES, 3) (they point to opposite sides, so the difference adds them up;
       at an apex one of them is zero); at the interior nodes ``C' x D`` of the shared
       cross part ``cross`` (NODES - 2, 3).
    2. Oriented alike, blended linearly within each piece, made perpendicular to ``C'``
       at the sample and renormalised."""
    across = np.vstack([own_a[:1] - own_b[:1], cross, own_a[-1:] - own_b[-1:]])
    n = np.cross(edge.derivative(BREAKS), across)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    n *= np.where(n @ n[NODES // 2] < 0.0, -1.0, 1.0)[:, None]
    w = PIECE_SAMPLES[None, :, None]
    blend = (1.0 - w) * n[:-1, None] + w * n[1:, None]
    # Perpendicular to the edge at the sample: both ribbons then span one plane with C'.
    t = (BREAKS[:-1, None] + PIECE_SAMPLES[None, :] * np.diff(BREAKS)[:, None]).ravel()
    tangent = edge.derivative(t).reshape(blend.shape)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-300)
    blend -= np.einsum("psd,psd->ps", blend, tangent)[..., None] * tangent
    return blend / np.maximum(np.linalg.norm(blend, axis=-1, keepdims=True), 1e-300)


def _hermite_weights(s: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    """Cubic Hermite weights (len(s), 4) of (V0, S0, V1, S1) at fractions ``s`` of a piece
    of width ``h`` (slopes per unit parameter)."""
    return np.column_stack([
        2 * s**3 - 3 * s**2 + 1, h * (s**3 - 2 * s**2 + s), -2 * s**3 + 3 * s**2, h * (s**3 - s**2)
    ])


def _piece_rows(
    network: EdgeNetwork, label: int, terms: _Terms, mat: NDArray[np.float64],
    piece_normals: dict[Key, NDArray[np.float64]],
) -> tuple[list[Any], list[Any], list[Any]]:
    """Penalty rows asking a patch's ribbons along its split sides to have no component
    along the shared normal (``_piece_normals``) between the nodes: with the cross part
    shared only at the nodes and each side's own end values, the two ribbons measured 2-6
    degrees apart inside the pieces next to odd-valence corners on k-means capsules.

    1. Per split side and Hermite piece, the weights of the samples on its four node
       entries (the loop runs with the edge or against it).
    2. Rows: the weighted sums of those entries' coefficients (unknowns) and fixed parts
       (negated: the target), with the sample's normal."""
    ids = network.loops[label]
    h = float(BREAKS[1] - BREAKS[0])
    weights = _hermite_weights(PIECE_SAMPLES, h) * np.sqrt(PIECE_WEIGHT / G1_WEIGHT)
    pen_a, pen_b, pen_n = [], [], []
    for k in range(len(ids)):
        key = key_of(ids[k], ids[(k + 1) % len(ids)])
        if key not in piece_normals:
            continue
        forward = ids[k] == key[0]
        for piece in range(PIECES):
            # Node entries from the piece's start in edge parameter; slopes flip when the
            # loop runs the other way.
            near, far = (piece, piece + 1) if forward else (NODES - 1 - piece, NODES - 2 - piece)
            entries = [(k, 0, near), (k, 1, near), (k, 0, far), (k, 1, far)]
            flat = [int(np.ravel_multi_index(e, terms.shape)) for e in entries]
            w = weights * np.array([1.0, 1.0, 1.0, 1.0] if forward else [1.0, -1.0, 1.0, -1.0])
            pen_a.extend(w @ mat[flat])
            pen_b.extend(-(w @ terms.fixed.reshape(-1, 3)[flat]))
            pen_n.extend(piece_normals[key][piece])
    return pen_a, pen_b, pen_n


def _solve(ata: NDArray[np.float64], atb: NDArray[np.float64], guess: NDArray[np.float64],
           penalty: tuple[list[Any], list[Any], list[Any]]) -> NDArray[np.float64]:
    """The unknowns (n, 3) from the normal equations ``ata``, ``atb`` (n, 3) with a ridge
    towards ``guess`` and the tangent-plane ``penalty`` rows (slope rows, targets, normals).

    Coordinates couple only through the penalty: unknown j, coordinate d at 3 j + d. The
    system is sparse (a patch couples its own unknowns), so it is solved as such: dense, the
    3n x 3n solve of a 138-patch torus took seconds per round.
    """
    n_unk = len(ata)
    scale = max(float(np.trace(ata)) / max(n_unk, 1), 1e-300)
    ata = ata + RIDGE * scale * np.eye(n_unk)
    rhs = (atb + RIDGE * scale * guess).ravel()
    full = sparse.kron(sparse.csr_matrix(ata), sparse.identity(3), format="csr")
    pen_a, pen_b, pen_n = penalty
    if pen_a:
        pa, pb, pn = np.array(pen_a), np.array(pen_b), np.array(pen_n)
        rows = sparse.csr_matrix((pa[:, :, None] * pn[:, None, :]).reshape(len(pa), -1))
        full = full + G1_WEIGHT * scale * (rows.T @ rows)
        rhs += G1_WEIGHT * scale * (rows.T @ np.einsum("pd,pd->p", pn, pb))
    return np.asarray(spsolve(full.tocsc(), rhs)).reshape(n_unk, 3)


def _bicubic(
    bilinear: BilinearCoons | BicubicCoons, nodes: NDArray[np.float64], sides: bool = True
) -> BicubicCoons:
    """Bicubic Coons base on the sides of ``bilinear`` (a bilinear or bicubic base; or on zero
    sides of dimension D) with the ribbons of the inward node data ``nodes`` (S, 2, NODES, D),
    S = 3 or 4 sides."""
    curves = [bilinear.bottom, bilinear.right, bilinear.top, bilinear.left]
    if not sides:
        dim = nodes.shape[-1]
        curves = [PiecewiseBezier(np.zeros((c.n_curves, 4, dim)), c.breaks) for c in curves]
    n_sides = nodes.shape[0]
    rib = _to_ribbons(
        [(nodes[k, 0], nodes[k, 1]) for k in range(n_sides)], curves[3], curves[1]
    )
    bottom, right, top, left = curves
    return BicubicCoons(
        bottom, right, top, left, rib.d_bottom, rib.d_right, rib.d_top, rib.d_left,
        twists=rib.twists,
    )


def _crease(edge: PiecewiseBezier, cross_a: NDArray[np.float64], cross_b: NDArray[np.float64]) -> bool:
    """Whether the two sides' own tangent planes along the edge differ by more than
    ``CREASE_ANGLE`` at the interior nodes (the ends may be degenerate corners)."""
    s = BREAKS[1:-1]
    tangent = edge.derivative(s)
    na = np.cross(tangent, cross_a[1:-1])
    nb = np.cross(tangent, cross_b[1:-1])
    cos = np.einsum("ij,ij->i", na, nb) / np.maximum(
        np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1), 1e-300
    )
    return bool(np.any(cos < np.cos(np.radians(CREASE_ANGLE))))


def _to_ribbons(
    inward: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
    left: PiecewiseBezier | None = None,
    right: PiecewiseBezier | None = None,
    normal: NDArray[np.float64] | None = None,
) -> Ribbons:
    """Inward node data per loop side -> :class:`Ribbons` in the Coons convention.

    Three sides (bottom, right, left): a 3-sided patch, whose ``d_top`` is
    :func:`~pde2cad.surfaces.coons.apex_ribbon` of its ``left`` and ``right`` sides with the
    apex twists = the slopes of ``d_left`` and ``d_right`` at the apex (projected into the
    plane of ``normal`` when given)."""
    breaks = BREAKS

    def curve(val: NDArray[np.float64], slope: NDArray[np.float64], reverse: bool, sign: float) -> PiecewiseBezier:
        if reverse:
            val, slope = val[::-1], -slope[::-1]
        return PiecewiseBezier.from_hermite(sign * val, sign * slope, breaks)

    d_bottom = curve(*inward[0], False, 1.0)
    d_right = curve(*inward[1], False, -1.0)
    ends = np.array([0.0, 1.0])
    if len(inward) == 3:
        if left is None or right is None:
            raise ValueError("a 3-sided patch's ribbons need its left and right sides")
        d_left = curve(*inward[2], True, 1.0)
        tl = d_left.derivative(ends[1:])[0]
        tr = d_right.derivative(ends[1:])[0]
        d_top = apex_ribbon(left, right, tl, tr, normal)
    else:
        d_top = curve(*inward[2], True, -1.0)
        d_left = curve(*inward[3], True, 1.0)
    low, high = d_bottom.derivative(ends), d_top.derivative(ends)
    twists = np.stack([[low[0], high[0]], [low[1], high[1]]])  # twists[i, j] = S_uv(i, j)
    return Ribbons(d_bottom, d_right, d_top, d_left, twists)


__all__ = ["shared_ribbons"]
