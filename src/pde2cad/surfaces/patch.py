"""Fit one region of a point cloud: Coons base patch plus deformation (Chapter 5).

The public single-region fit, :func:`fit_patch`, runs the pipeline of Fig. 5.1 (c)-(g):

1. boundary: the region's 3 or 4 sides as cubic Bézier chains, from
   :func:`~pde2cad.surfaces.region.extract_boundary` (alpha shape, corners, Chapter 3 fitter)
   or handed in by the caller (the multi-patch layout shares one curve per edge);
2. base patch: the bilinear Coons patch of the sides (Eq. 5.1), or a 3-sided one (Fig. 5.11);
3. parameterization: the closest point of every input point on the base (Section 5.2.3);
4. C1 only: the cross-boundary derivative curves (ribbons) estimated from the points near each
   side, or handed in for shared edges, then the bicubic Coons patch (Eqs. 5.2-5.7) and a
   second projection onto it;
5. deformation: the least-squares sine series of Eq. 5.17 (C0) or a C1 series (Eq. 5.21,
   see below) that removes the residuals ``P_i - S_c(u_i, v_i)`` (Eqs. 5.18-5.20). Both
   vanish on the boundary (with their first derivatives for C1), so the sides (and ribbons)
   the patch shares with its neighbours are kept exactly;
6. optionally (``refine``), parameter correction: re-project the points onto the fitted
   surface and fit the deformation again, which removes the error the base patch's
   parameterization leaves where the projection folds (points near a strongly curved side
   crowd onto the same base parameters, so no deformation can fit them all).

The sin^2 terms of Eq. 5.21 are all symmetric about ``u = 1/2`` and ``v = 1/2`` and cannot fit
asymmetric residuals whatever M and N; C1 patches use the complete basis
``sin(pi u) sin(m pi u) sin(pi v) sin(n pi v)`` by default, which keeps the same boundary
data and contains Eq. 5.21 (see :mod:`pde2cad.surfaces.deformation`).

Errors follow Eq. 5.22 (parametric, ``|P_i - S(u_i, v_i)|``) and are also reported as the
orthogonal distance to the final surface.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import FitError, InputError
from pde2cad.surfaces.boundary import PiecewiseBezier, as_curve
from pde2cad.surfaces.coons import (
    BicubicCoons,
    BilinearCoons,
    Ribbons,
    cell_values,
    estimate_cross_derivatives,
    three_sided,
)
from pde2cad.surfaces.columns import centred_columns, scatter_matrix
from pde2cad.surfaces.deformation import (
    AUTO_TERMS,
    Deformation,
    DeformedPatch,
    Kind,
    choose_mn,
    fit_deformation,
    select_terms,
)
from pde2cad.surfaces.projection import closest_points, project_points
from pde2cad.surfaces.region import RegionBoundary, extract_boundary

#: Automatic term counts tried on 3-sided patches (see fit_patch).
AUTO_TERMS_THREE_SIDED = (6, 8)
#: Patches with more points than this try at most AUTO_DENSE_TERMS: the fit costs points x
#: terms^2, and on 1e6-point clouds (83k per patch) 16 instead of 12 terms cost 0.5 s of the
#: 10 s budget for a true error of 1.7e-5 instead of 2.2e-5 of the diagonal.
AUTO_DENSE_POINTS = 50_000
AUTO_DENSE_TERMS = 12

Continuity = Literal["c0", "c1"]
C1Basis = Literal["complete", "thesis"]

#: Largest M = N tried when a tolerance chooses the number of terms.
MAX_TERMS = 20
# Points examined by the collinearity test (a strided subsample bounds its cost).
_SHAPE_SAMPLE = 200_000
# Parametric step towards the centre used for normals where S_u x S_v vanishes (the
# collapsed side of a 3-sided patch): the limit normal, to about this relative accuracy.
_NORMAL_INSET = 1e-7


def _cell_values(
    base: BilinearCoons | BicubicCoons, u: NDArray[np.float64], v: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``S_c(u, v)`` at ``u, v`` (n,) on the exact polynomial cells of the base: (n, D).

    The Boolean sum (Eq. 5.2) evaluates every side, ribbon and blend per point; on the
    bicubic cells of :meth:`~pde2cad.surfaces.coons.BilinearCoons.power_cells` a value costs
    one 4 x 4 Horner scheme, several times less for a million points.
    """
    return cell_values(base.power_cells(), u, v)


@dataclass(frozen=True, eq=False)
class Patch:
    """One fitted region: ``S(u, v) = S_c(u, v) + w(u, v)`` (Eq. 5.20).

    Attributes
    ----------
    base : BilinearCoons or BicubicCoons
        The Coons base patch (Eq. 5.1 for C0, Eqs. 5.2-5.7 for C1).
    deformation : Deformation
        The sine deformation (Eq. 5.17, C0) or a C1 one (kind ``"c1full"`` or Eq. 5.21's
        ``"c1"``); zero on the boundary, with its first derivatives for C1.
    boundary : RegionBoundary or None
        The extracted boundary, or None when the caller passed the sides directly.
    sides : tuple of PiecewiseBezier
        The 3 or 4 sides as a head-to-tail loop starting at ``S(0, 0)``: ``sides[0]`` is
        ``S(u, 0)``, ``sides[1]`` is ``S(1, v)``, ``sides[2]`` is ``S(1 - u, 1)`` and
        ``sides[3]`` is ``S(0, 1 - v)`` (for 3 sides, ``sides[2]`` runs from the apex
        ``S(., 1)`` back to ``S(0, 0)``).
    continuity : {"c0", "c1"}
    ribbons : Ribbons or None
        The cross-boundary derivatives of a C1 patch (estimated or given).
    params : (N, 2) float
        ``(u_i, v_i)`` of the input points on the base patch (used by the fit).
    outside : (N,) bool
        Points whose closest point lies beyond a side (by more than 1e-3 in parameter):
        their parameter sits on the side, where the deformation is zero, so their error is
        their distance to the boundary curve.
    points : (N, 3) float
        The input points (not copied).
    """

    base: BilinearCoons | BicubicCoons
    deformation: Deformation
    boundary: RegionBoundary | None
    sides: tuple[PiecewiseBezier, ...]
    continuity: Continuity
    ribbons: Ribbons | None
    params: NDArray[np.float64]
    outside: NDArray[np.bool_]
    points: NDArray[np.float64] = field(repr=False)
    _fit_errors: dict[str, float] = field(repr=False)

    # ----------------------------------------------------------------- sizes
    @property
    def m(self) -> int:
        """Number M of deformation terms in u."""
        return self.deformation.m

    @property
    def n(self) -> int:
        """Number N of deformation terms in v."""
        return self.deformation.n

    @property
    def n_variables(self) -> int:
        """Scalars that define the patch: what a CAD file or a neighbour must store.

        ``D`` per distinct control point of the sides (a chain of ``K`` cubics adds ``3K``
        around the closed loop; a collapsed side adds none), ``D (3K + 1)`` per ribbon and
        ``4 D`` for the twists (C1), and ``M N D`` deformation amplitudes.
        """
        dim = self.base.dim
        sides = sum(3 * c.n_curves for c in self.sides if np.ptp(c.ctrl, axis=(0, 1)).any())
        total = dim * sides + self.deformation.coefficients.size
        if self.ribbons is not None:
            rib = (self.ribbons.d_bottom, self.ribbons.d_right, self.ribbons.d_top)
            curves = (*rib, self.ribbons.d_left)
            total += dim * sum(3 * c.n_curves + 1 for c in curves) + self.ribbons.twists.size
        return int(total)

    # ----------------------------------------------------------------- errors
    @property
    def fit_errors(self) -> dict[str, float]:
        """The errors known from the fit itself, without the extra projection of
        :attr:`errors`: ``mean``, ``max``, ``rms`` (Eq. 5.22 at the fitted parameters) and
        ``base_mean``, ``base_max`` (the Coons base alone)."""
        return dict(self._fit_errors)

    @cached_property
    def errors(self) -> dict[str, float]:
        """Fitting errors over all ``N`` input points (duplicates count as often as given).

        ``mean``, ``max``, ``rms``: Eq. 5.22, ``|P_i - S(u_i, v_i)|`` at the fitted
        parameters; ``base_mean``, ``base_max``: the same for the Coons base alone (what the
        deformation started from, as in Section 5.4.1); ``mean_orthogonal``,
        ``max_orthogonal``, ``rms_orthogonal``: distance from each point to its closest point
        on the final surface, found by Newton from ``params`` (a local closest point, so an
        upper bound of the true distance); ``outside``: number of points beyond a side.

        The orthogonal errors need one more projection of every point; they are computed on
        first access and cached.
        """
        _, dist, _ = project_points(self, self.points, initial=self.params)
        return {
            **self._fit_errors,
            "mean_orthogonal": float(dist.mean()),
            "max_orthogonal": float(dist.max()),
            "rms_orthogonal": float(np.sqrt(np.mean(dist * dist))),
            "outside": float(np.count_nonzero(self.outside)),
        }

    # ----------------------------------------------------------------- evaluation
    @property
    def surface(self) -> DeformedPatch:
        """The fitted surface, base + deformation (Eq. 5.20), which does the evaluation."""
        return DeformedPatch(self.base, self.deformation)

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Points ``S(u, v)``; ``u``, ``v`` broadcast, result ``shape + (3,)``."""
        return self.surface.evaluate(u, v)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """First partial derivatives ``(S_u, S_v)``, each ``shape + (3,)``."""
        return self.surface.derivatives(u, v)

    def second_derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(S_uu, S_uv, S_vv)``, each ``shape + (3,)``."""
        return self.surface.second_derivatives(u, v)

    def jet(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """``(S, S_u, S_v, S_uu, S_uv, S_vv)`` in one pass (what a projection needs)."""
        return self.surface.jet(u, v)

    def normals(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Unit normals ``S_u x S_v / |S_u x S_v|``, ``shape + (3,)``.

        Where the cross product vanishes (the collapsed side of a 3-sided patch) the normal
        is taken a tiny step towards the patch centre, i.e. its limit.
        """
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        su, sv = self.derivatives(u, v)
        nrm = np.cross(su, sv)
        length = np.linalg.norm(nrm, axis=-1)
        # Relative to the larger derivative: at the apex of a 3-sided patch S_u is rounding
        # noise (~1e-17) and their product would not flag it.
        scale = np.maximum(np.linalg.norm(su, axis=-1), np.linalg.norm(sv, axis=-1)) ** 2
        bad = length <= 1e-10 * np.maximum(scale, 1e-300)
        if bad.any():
            step = _NORMAL_INSET
            ui = u[bad] + step * np.sign(0.5 - u[bad])
            vi = v[bad] + step * np.sign(0.5 - v[bad])
            a, b = self.derivatives(ui, vi)
            nrm[bad] = np.cross(a, b)
            length[bad] = np.linalg.norm(nrm[bad], axis=-1)
        return nrm / length[..., None]


# --------------------------------------------------------------------------- checks
def _check_points(points: ArrayLike) -> NDArray[np.float64]:
    """Shape, finiteness and non-degeneracy of the cloud; returns (N, 3) float."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    # One pass over the whole array; the rows only to name the bad ones.
    if not np.isfinite(pts).all():
        finite = np.isfinite(pts).all(axis=1)
        bad = int(np.count_nonzero(~finite))
        raise InputError(
            f"{bad} of {pts.shape[0]} points contain NaN or inf (first at row "
            f"{int(np.argmin(finite))}); drop them, e.g. points[np.isfinite(points).all(1)]"
        )
    if pts.shape[0] < 3:
        raise InputError(f"a patch needs at least 3 points, got {pts.shape[0]}")
    _, centred = centred_columns(pts[:: max(1, pts.shape[0] // _SHAPE_SAMPLE)])
    # Principal spreads from the 3 x 3 scatter matrix.
    scatter = scatter_matrix(centred)
    spread = np.sqrt(np.clip(np.linalg.eigvalsh(scatter)[::-1], 0.0, None))
    if spread[0] == 0.0:
        raise InputError("all points coincide; a patch needs points spread over a surface")
    # 1e-6: the scatter matrix squares the spreads, so rounding leaves ~1e-8 on a line.
    if spread[1] <= 1e-6 * spread[0]:
        raise InputError(
            "the points are collinear (they span a line, not a surface); a patch needs points "
            "spread in two directions"
        )
    return pts


def _check_terms(
    m: int | str, n: int | str, pts: NDArray[np.float64], tolerance: float | None
) -> None:
    """M, N positive integers (or both ``"auto"``) and no more unknowns than distinct points."""
    if m == "auto" or n == "auto":
        if m != n:
            raise InputError(f'M and N are "auto" together or not at all, got M={m!r}, N={n!r}')
        return
    if isinstance(m, str) or isinstance(n, str) or int(m) != m or int(n) != n or m < 1 or n < 1:
        raise InputError(f"M and N must be positive integers, got M={m}, N={n}")
    if tolerance is not None:
        if not tolerance > 0:
            raise InputError(f"tolerance must be > 0, got {tolerance}")
        return
    unknowns = int(m) * int(n)
    # Duplicates add no information: count distinct points, but only when it can matter.
    count = pts.shape[0]
    if count < 10 * unknowns:
        count = int(np.unique(pts, axis=0).shape[0])
    if count < unknowns:
        raise InputError(
            f"M*N = {unknowns} deformation terms need at least as many distinct points, got "
            f"N = {count}; lower M and N (M*N <= {count}) or pass tolerance= to choose them"
        )


def _resolve_boundary(
    pts: NDArray[np.float64],
    boundary: RegionBoundary | Sequence[PiecewiseBezier | ArrayLike] | None,
    corners: ArrayLike | None,
    side_tolerance: float | None,
    rims: bool = True,
) -> tuple[RegionBoundary | None, tuple[PiecewiseBezier, ...]]:
    """The region boundary (extracted unless given) and its head-to-tail sides."""
    if boundary is not None and (corners is not None or side_tolerance is not None):
        raise InputError(
            "corners= and boundary_tolerance= guide the boundary extraction; with boundary= "
            "there is none, so pass only one of them"
        )
    if corners is not None:
        count = np.asarray(corners).shape[0] if np.asarray(corners).ndim else 0
        if count not in (3, 4):
            raise InputError(
                f"got {count} corners; a patch needs 3 or 4 (3 collapses one side to a point, "
                "Fig. 5.11)"
            )
    if boundary is None:
        region = extract_boundary(pts, corners=corners, tolerance=side_tolerance, rims=rims)
        return region, tuple(region.sides)
    if isinstance(boundary, RegionBoundary):
        return boundary, tuple(boundary.sides)
    sides = tuple(as_curve(c) for c in boundary)
    if len(sides) not in (3, 4):
        raise InputError(
            f"boundary has {len(sides)} sides; a patch needs 3 or 4 head-to-tail sides "
            "(a RegionBoundary, or curves c0, c1, c2[, c3] with each ending where the next starts)"
        )
    return None, sides


def _bilinear(sides: tuple[PiecewiseBezier, ...]) -> BilinearCoons:
    """Eq. 5.1 from a head-to-tail loop of 4 sides, or the 3-sided patch of Fig. 5.11."""
    if len(sides) == 4:
        return BilinearCoons.from_loop(*sides)
    return three_sided(*sides)


def _check_ribbons(ribbons: object, continuity: str) -> Ribbons | None:
    if ribbons is None:
        return None
    if continuity != "c1":
        raise InputError("ribbons= only applies to continuity='c1'; drop it or ask for C1")
    if not isinstance(ribbons, Ribbons):
        raise InputError(
            f"ribbons must be a pde2cad.surfaces.coons.Ribbons, got {type(ribbons).__name__}; "
            "build it with estimate_cross_derivatives or from shared edge data"
        )
    return ribbons


def _check_params(
    params: ArrayLike | None, outside: ArrayLike | None, count: int, boundary: object
) -> tuple[NDArray[np.float64], NDArray[np.bool_]] | None:
    """Validated ``(params, outside)`` handed to :func:`fit_patch`, or None."""
    if params is None and outside is None:
        return None
    if params is None or outside is None:
        raise InputError(
            "params= and outside= go together (Patch.params and Patch.outside of a previous "
            "fit on the same points and sides); pass both or neither"
        )
    if boundary is None:
        raise InputError(
            "params= only applies with boundary= (the parameters belong to the bilinear patch "
            "of those sides); pass the sides of the fit the parameters come from"
        )
    prm = np.asarray(params, dtype=float)
    out = np.asarray(outside)
    if prm.shape != (count, 2) or out.shape != (count,):
        raise InputError(
            f"params must have shape ({count}, 2) and outside ({count},), one per point; got "
            f"{prm.shape} and {out.shape}"
        )
    if not np.all(np.isfinite(prm)) or np.any(prm < 0.0) or np.any(prm > 1.0):
        raise InputError("params must be finite and lie in [0, 1]^2 (as project_points returns)")
    return prm, out.astype(bool, copy=False)


# --------------------------------------------------------------------------- the fit
def fit_patch(
    points: ArrayLike,
    *,
    continuity: Continuity = "c0",
    m: int | str = 5,
    n: int | str = 5,
    tolerance: float | None = None,
    corners: ArrayLike | None = None,
    boundary: RegionBoundary | Sequence[PiecewiseBezier | ArrayLike] | None = None,
    ribbons: Ribbons | None = None,
    max_terms: int = MAX_TERMS,
    refine: int = 0,
    c1_basis: C1Basis = "complete",
    boundary_tolerance: float | None = None,
    rims: bool = True,
    params: ArrayLike | None = None,
    outside: ArrayLike | None = None,
) -> Patch:
    """Fit one parametric patch to the points of one region (Sections 5.2-5.3).

    Parameters
    ----------
    points : (N, 3) float
        The region's points, structured or not. Duplicates are tolerated (kept, so they
        weigh more in the least squares; the unknown count is checked on distinct points).
    continuity : {"c0", "c1"}
        ``"c0"``: bilinear Coons base (Eq. 5.1) + sine deformation (Eq. 5.17): keeps the
        sides, hence positional continuity with neighbours sharing them. ``"c1"``: bicubic
        Coons base (Eqs. 5.2-5.7) + sin^2 deformation (Eq. 5.21): keeps sides, cross-boundary
        derivatives and twists, hence tangential continuity with neighbours sharing them.
    m, n : int or "auto"
        Numbers of deformation terms M, N (Eqs. 5.17, 5.21). Ignored with ``tolerance``.
        ``"auto"`` (both): ``M = N`` chosen by hold-out validation
        (:func:`~pde2cad.surfaces.deformation.select_terms`).
    tolerance : float, optional
        Target for the maximum parametric error (Eq. 5.22), in the units of the points: the
        fewest terms that reach it are used (M = N first, then each lowered; up to
        ``max_terms``). The boundary is not deformed, so the tolerance must exceed the
        error of the side fits (``boundary.side_errors``).
    corners : (3,) or (4,) array, optional
        Corners for :func:`~pde2cad.surfaces.region.extract_boundary` (otherwise detected
        from the curvature of the boundary, Fig. 5.2).
    boundary : RegionBoundary or sequence of 3 or 4 curves, optional
        The sides, bypassing the extraction: how the multi-patch layout hands every patch
        the same curve for a shared edge. Curves form a head-to-tail loop starting at
        ``S(0, 0)`` (:class:`~pde2cad.surfaces.boundary.PiecewiseBezier` or arrays accepted
        by :func:`~pde2cad.surfaces.boundary.as_curve`).
    ribbons : Ribbons, optional
        C1 only: the cross-boundary derivatives (module convention of
        :mod:`pde2cad.surfaces.coons`: ``d_bottom = S_v(u, 0)`` ...), e.g. shared with the
        neighbours. Estimated from the points near each side when omitted.
    max_terms : int
        Largest M = N tried with ``tolerance``.
    refine : int
        Rounds of parameter correction: re-project the points onto the fitted surface and
        refit the deformation (M, N fixed after the first fit). Each round costs about one
        projection and one fit; it matters where the base patch is far from the points.
    boundary_tolerance : float, optional
        Tolerance of the side fits when the boundary is extracted (default: the extractor's
        noise-based one, see :func:`~pde2cad.surfaces.region.extract_boundary`). The sides are
        not deformed, so the error near them is the side fit's; but a tolerance below the
        zigzag of the alpha-shape loop of unstructured points makes wavy sides and more
        points beyond them (measured: worse errors), so lower it only for clean boundaries.
    rims : bool
        When the boundary is extracted: sides on the estimated true rim (default) or on the
        boundary loop, about half a sample spacing inside (see
        :func:`~pde2cad.surfaces.region.extract_boundary`). The rim estimate costs about
        0.3 s on 1e6 points (a 100 x 60 flag of 1e6 points: 6.2e-6 D against 3.6e-5 D).
    c1_basis : {"complete", "thesis"}
        C1 deformation terms: ``sin(pi t) sin(k pi t)`` (kind ``"c1full"``, complete) or the
        thesis's ``sin^2(k pi t)`` (Eq. 5.21, kind ``"c1"``, symmetric about the patch centre
        lines, so it cannot fit asymmetric shapes).
    params : (N, 2) float, optional
        The points' closest-point parameters on the bilinear Coons patch of these sides, as
        a previous fit on the same points and sides found them (``Patch.params`` of a C0
        fit): the projection onto the bilinear base is skipped. Must come with ``outside``
        and needs ``boundary``; the result is the same as without them (to rounding: the
        base values come from an evaluation instead of the projection) when they are that
        fit's values.
    outside : (N,) bool, optional
        The matching ``Patch.outside`` flags (required with ``params``).

    Returns
    -------
    Patch

    Raises
    ------
    InputError
        Wrong shape, NaN/inf, collinear or coincident points, M N larger than the number of
        distinct points, not 3 or 4 corners / sides, ribbons with C0.
    FitError
        The tolerance cannot be reached, or the points near the sides do not determine the
        ribbons.

    Notes
    -----
    Near ``M N ~ N`` the least squares would interpolate and oscillate (the thesis's
    "M N = I gives zero error"); :func:`~pde2cad.surfaces.deformation.fit_deformation` then
    adds a small ridge, and ``tolerance`` never tries more than ``sqrt(N)`` terms per
    direction.
    """
    if continuity not in ("c0", "c1"):
        raise InputError(
            f"continuity must be 'c0' (positional) or 'c1' (tangential), got {continuity!r}"
        )
    if c1_basis not in ("complete", "thesis"):
        raise InputError(f"c1_basis must be 'complete' or 'thesis', got {c1_basis!r}")
    if int(refine) != refine or refine < 0:
        raise InputError(f"refine must be a non-negative integer, got {refine}")
    kind: Kind = "c0" if continuity == "c0" else ("c1full" if c1_basis == "complete" else "c1")
    pts = _check_points(points)
    _check_terms(m, n, pts, tolerance)
    given_ribbons = _check_ribbons(ribbons, continuity)
    region, sides = _resolve_boundary(pts, boundary, corners, boundary_tolerance, rims)
    given_params = _check_params(params, outside, pts.shape[0], boundary)
    if pts.shape[1] != sides[0].dim:
        raise InputError(f"points are 3-D but the boundary curves have dimension {sides[0].dim}")

    bilinear = _bilinear(sides)
    # S_c at the parameters: the projection's closest points (no second evaluation).
    on_base: NDArray[np.float64] | None = None
    if given_params is None:
        params, _, outside, on_base = closest_points(bilinear, pts)
    else:
        params, outside = given_params
    base: BilinearCoons | BicubicCoons = bilinear
    rib: Ribbons | None = None
    if continuity == "c1":
        rib = given_ribbons
        if rib is None:
            rib = estimate_cross_derivatives(
                pts, params, bilinear.bottom, bilinear.right, bilinear.top, bilinear.left
            )
        base = BicubicCoons(
            bilinear.bottom,
            bilinear.right,
            bilinear.top,
            bilinear.left,
            rib.d_bottom,
            rib.d_right,
            rib.d_top,
            rib.d_left,
            twists=rib.twists,
        )
        # The bicubic base is close to the bilinear one: Newton from the old parameters.
        params, _, outside, on_base = closest_points(base, pts, initial=params)
    if on_base is None:
        on_base = _cell_values(base, params[:, 0], params[:, 1])
    residuals = pts - on_base
    base_err = np.sqrt(np.einsum("ij,ij->i", residuals, residuals))
    # A 3-sided patch's top side is one point (the apex): C0 terms get zero slope across it.
    flat_top = len(sides) == 3 and kind == "c0"
    if tolerance is None:
        if m == "auto":
            # Scored on the points within the sides: those beyond keep their distance to
            # the boundary whatever the terms, and would hide the differences.
            inside = ~outside if (~outside).sum() >= 100 else np.ones(len(pts), dtype=bool)
            # A 3-sided patch's points thin out towards its collapsed top (density ~ 1 - v in
            # the parameters): many terms oscillate there unseen by the held-out points
            # (teapot bottom, C1 at 12 terms: 7.5e-2 of the diagonal near the apex).
            candidates: tuple[int, ...] = AUTO_TERMS_THREE_SIDED if len(sides) == 3 else AUTO_TERMS
            if len(pts) > AUTO_DENSE_POINTS:
                candidates = tuple(k for k in candidates if k <= AUTO_DENSE_TERMS)
            m = n = select_terms(
                residuals[inside], params[inside], kind, candidates=candidates, flat_top=flat_top
            )
        deformation = fit_deformation(residuals, params, int(m), int(n), kind, flat_top=flat_top)
    else:
        try:
            deformation = choose_mn(residuals, params, float(tolerance), kind, max_mn=max_terms)
        except FitError as exc:
            floor = float(base_err[outside].max(initial=0.0))
            raise FitError(
                f"{exc}. Points beyond the sides keep their distance to the boundary "
                f"({floor:.3g} here), which no deformation changes"
            ) from exc
    for _ in range(int(refine)):
        params, _, outside = project_points(
            DeformedPatch(base, deformation), pts, initial=params
        )
        residuals = pts - _cell_values(base, params[:, 0], params[:, 1])
        deformation = fit_deformation(
            residuals, params, deformation.m, deformation.n - int(flat_top), kind,
            flat_top=flat_top,
        )
    fit_errors = {
        "mean": deformation.mean_error,
        "max": deformation.max_error,
        "rms": deformation.rms_error,
        "base_mean": float(base_err.mean()),
        "base_max": float(base_err.max()),
    }
    return Patch(
        base=base,
        deformation=deformation,
        boundary=region,
        sides=sides,
        continuity=continuity,
        ribbons=rib,
        params=params,
        outside=outside,
        points=pts,
        _fit_errors=fit_errors,
    )
