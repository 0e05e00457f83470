"""Boundary curves of a surface patch: a chain of cubic Béziers on one global parameter.

A Coons patch (Eqs. 5.1-5.7) needs each side as a single curve ``C(s)``, ``s`` in [0, 1],
while the Chapter 3 fitter returns a chain of ``K`` cubic Béziers (Fig. 5.3(b)).
:class:`PiecewiseBezier` glues the chain onto one parameter: the break values
``0 = s_0 < s_1 < ... < s_K = 1`` say which part of [0, 1] each cubic covers, and curve ``k``
is reached with the local parameter ``t = (s - s_k) / (s_{k+1} - s_k)``.

The same class carries the cross-boundary derivative curves (ribbons) of the bicubic Coons
patch, and a single point for the degenerate side of a 3-sided patch (Fig. 5.11).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.curves.bezier import power_coefficients
from pde2cad.errors import InputError

#: Relative tolerance (to the control-point bounding box) for joints and corners.
JOIN_TOLERANCE = 1e-9


def bbox_diagonal(points: NDArray[np.float64]) -> float:
    """Bounding-box diagonal of ``points`` (..., D), at least 1 so a point set at the origin
    still gets an absolute tolerance."""
    flat = points.reshape(-1, points.shape[-1])
    return max(float(np.linalg.norm(flat.max(axis=0) - flat.min(axis=0))), 1.0)


@dataclass(frozen=True, eq=False)
class PiecewiseBezier:
    """A C0 chain of cubic Béziers (Eq. 2.6) on one global parameter ``s`` in [0, 1].

    Parameters
    ----------
    ctrl : (K, 4, D) float
        Control points of the ``K`` cubics; cubic ``k`` ends where cubic ``k + 1`` starts
        (checked to ``JOIN_TOLERANCE`` times the bounding-box diagonal).
    breaks : (K + 1,) float
        Strictly increasing, ``breaks[0] == 0`` and ``breaks[-1] == 1``; cubic ``k`` covers
        ``[breaks[k], breaks[k + 1]]``.

    Notes
    -----
    Evaluation outside [0, 1] extrapolates the first or last cubic, which lets a projection
    measure how far beyond a side a point lies.
    """

    ctrl: NDArray[np.float64]
    breaks: NDArray[np.float64]
    # Derived in __post_init__ (power coefficients): not constructor arguments.
    _coef_matrix: NDArray[np.float64] = field(init=False, repr=False)
    _coef: NDArray[np.float64] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        ctrl = np.array(self.ctrl, dtype=float)
        breaks = np.array(self.breaks, dtype=float)
        if ctrl.ndim != 3 or ctrl.shape[1] != 4 or ctrl.shape[0] < 1:
            raise InputError(
                f"ctrl must have shape (K, 4, D) with K >= 1, got {ctrl.shape}; "
                "wrap a single cubic with PiecewiseBezier.from_cubic"
            )
        if breaks.shape != (ctrl.shape[0] + 1,):
            raise InputError(
                f"breaks must have K + 1 = {ctrl.shape[0] + 1} values for {ctrl.shape[0]} cubics, "
                f"got shape {breaks.shape}"
            )
        if not (np.all(np.isfinite(ctrl)) and np.all(np.isfinite(breaks))):
            raise InputError("control points or breaks contain NaN or inf; clean the input curve")
        if breaks[0] != 0.0 or breaks[-1] != 1.0 or np.any(np.diff(breaks) <= 0.0):
            raise InputError(
                f"breaks must increase strictly from 0 to 1, got {breaks.tolist()}; "
                "use PiecewiseBezier.from_chain to compute them"
            )
        gaps = np.linalg.norm(ctrl[1:, 0] - ctrl[:-1, 3], axis=-1)
        if gaps.size and gaps.max() > JOIN_TOLERANCE * bbox_diagonal(ctrl):
            k = int(gaps.argmax())
            raise InputError(
                f"cubic {k} ends {gaps[k]:.3g} away from where cubic {k + 1} starts; a boundary "
                "curve must be one connected chain (check the order of the cubics)"
            )
        ctrl.setflags(write=False)
        breaks.setflags(write=False)
        object.__setattr__(self, "ctrl", ctrl)
        object.__setattr__(self, "breaks", breaks)
        # Power-basis coefficients per cubic, rescaled to the global parameter so evaluation
        # is one Horner scheme in t = s - s_k (no division by the interval length per point).
        h = np.diff(breaks)
        coef = power_coefficients(ctrl)  # (K, 4, D), in the local t in [0, 1]
        coef = coef / (h[:, None, None] ** np.arange(4)[None, :, None])
        # Columns grouped by piece: (4, K * D), so one product evaluates every piece.
        matrix = np.ascontiguousarray(coef.transpose(1, 0, 2).reshape(4, -1))
        matrix.setflags(write=False)
        object.__setattr__(self, "_coef_matrix", matrix)
        coef = np.ascontiguousarray(coef)
        coef.setflags(write=False)
        object.__setattr__(self, "_coef", coef)

    # ----------------------------------------------------------------- constructors
    @classmethod
    def from_chain(
        cls,
        ctrl: ArrayLike,
        breaks: ArrayLike | None = None,
        spacing: Literal["length", "uniform"] = "length",
    ) -> PiecewiseBezier:
        """Chain ``(K, 4, D)`` of cubics; ``breaks`` default from ``spacing``.

        ``"length"`` gives each cubic a share of [0, 1] proportional to its control-polygon
        length (close to arc length, so opposite sides of a Coons patch advance at similar
        rates); ``"uniform"`` gives ``k / K``.
        """
        c = np.asarray(ctrl, dtype=float)
        if c.ndim == 2:
            c = c[None]
        if c.ndim != 3 or c.shape[1] != 4:
            raise InputError(f"ctrl must have shape (K, 4, D), got {c.shape}")
        if breaks is None:
            k = c.shape[0]
            if spacing == "length":
                seg = np.linalg.norm(np.diff(c, axis=1), axis=-1).sum(axis=1)
                total = seg.sum()
                if not np.isfinite(total):
                    raise InputError("control points contain NaN or inf; clean the input curve")
                share = seg / total if total > 0 and np.all(seg > 0) else np.full(k, 1.0 / k)
            elif spacing == "uniform":
                share = np.full(k, 1.0 / k)
            else:
                raise InputError(f"spacing must be 'length' or 'uniform', got {spacing!r}")
            breaks = np.concatenate([[0.0], np.cumsum(share)])
            breaks[-1] = 1.0
        return cls(c, np.asarray(breaks, dtype=float))

    @classmethod
    def from_cubic(cls, ctrl: ArrayLike) -> PiecewiseBezier:
        """A single cubic ``(4, D)`` on [0, 1]."""
        c = np.asarray(ctrl, dtype=float)
        if c.shape[:1] != (4,) or c.ndim != 2:
            raise InputError(f"a cubic needs 4 control points of shape (4, D), got {c.shape}")
        return cls(c[None], np.array([0.0, 1.0]))

    @classmethod
    def from_point(cls, point: ArrayLike) -> PiecewiseBezier:
        """A constant curve: the degenerate side of a 3-sided patch (Fig. 5.11)."""
        p = np.asarray(point, dtype=float)
        if p.ndim != 1:
            raise InputError(f"a point must have shape (D,), got {p.shape}")
        return cls(np.broadcast_to(p, (1, 4, p.size)), np.array([0.0, 1.0]))

    @classmethod
    def from_hermite(
        cls, values: ArrayLike, slopes: ArrayLike, breaks: ArrayLike
    ) -> PiecewiseBezier:
        """C1 chain through ``values`` (K + 1, D) with derivatives ``slopes`` (K + 1, D) d/ds
        at ``breaks`` (K + 1,): cubic Hermite pieces written as Béziers."""
        v = np.asarray(values, dtype=float)
        d = np.asarray(slopes, dtype=float)
        b = np.asarray(breaks, dtype=float)
        h = np.diff(b)[:, None]
        ctrl = np.stack([v[:-1], v[:-1] + h * d[:-1] / 3.0, v[1:] - h * d[1:] / 3.0, v[1:]], axis=1)
        return cls(ctrl, b)

    # ----------------------------------------------------------------- properties
    @property
    def dim(self) -> int:
        """Dimension ``D`` of the points."""
        return int(self.ctrl.shape[2])

    @property
    def n_curves(self) -> int:
        """Number ``K`` of cubics."""
        return int(self.ctrl.shape[0])

    @property
    def start(self) -> NDArray[np.float64]:
        """``C(0)``, shape (D,)."""
        return self.ctrl[0, 0].copy()

    @property
    def end(self) -> NDArray[np.float64]:
        """``C(1)``, shape (D,)."""
        return self.ctrl[-1, 3].copy()

    # ----------------------------------------------------------------- evaluation
    def jet(self, s: ArrayLike, order: int = 2) -> NDArray[np.float64]:
        """``C(s)`` and its derivatives d^r C / ds^r for r = 0..order (order <= 3).

        Parameters
        ----------
        s : array_like, any shape
        order : int

        Returns
        -------
        (order + 1, *s.shape, D) float
        """
        if not 0 <= order <= 3:
            raise InputError(f"derivative order must be 0..3, got {order}")
        s = np.asarray(s, dtype=float)
        flat = s.reshape(-1)
        n, k_count, dim = flat.size, self.n_curves, self.dim
        if k_count == 1:
            t = flat
        else:
            k = np.clip(np.searchsorted(self.breaks, flat, side="right") - 1, 0, k_count - 1)
            t = flat - self.breaks[k]
        out = np.empty((order + 1, n, dim))
        if k_count == 1 or n <= 4 * k_count:
            for r in range(order + 1):
                # Rows of d^r/dt^r [1, t, t^2, t^3] times the power coefficients of every
                # piece in one contraction, then each point keeps its own piece. einsum
                # rather than @, as a threaded BLAS is slower than the work itself for an
                # inner dimension of 4.
                pieces = np.einsum("nj,jk->nk", monomials(t, r), self._coef_matrix)
                if k_count == 1:
                    out[r] = pieces
                else:
                    out[r] = pieces.reshape(n, k_count, dim)[np.arange(n), k]
        else:
            # Many points on a chain of many cubics: gather each point's own coefficients
            # once (cost independent of K) and sum the same monomial terms.
            cd = self._coef[k]  # (n, 4, D)
            for r in range(order + 1):
                mono = monomials(t, r)
                acc = out[r]
                np.multiply(mono[:, r, None], cd[:, r], out=acc)
                for j in range(r + 1, 4):
                    acc += mono[:, j, None] * cd[:, j]
        return out.reshape((order + 1, *s.shape, dim))

    def evaluate(self, s: ArrayLike) -> NDArray[np.float64]:
        """Points ``C(s)``: shape ``s.shape + (D,)``."""
        return self.jet(s, 0)[0]

    def derivative(self, s: ArrayLike, order: int = 1) -> NDArray[np.float64]:
        """``order``-th derivative d^r C / ds^r in the global parameter: ``s.shape + (D,)``.

        One-sided at a break (the cubic starting there is used), as a chain is only C0.
        """
        if not 1 <= order <= 3:
            raise InputError(f"derivative order must be 1, 2 or 3, got {order}")
        return self.jet(s, order)[order]

    # ----------------------------------------------------------------- transforms
    def reversed(self) -> PiecewiseBezier:
        """The same curve run backwards: ``R(s) = C(1 - s)``."""
        return PiecewiseBezier(self.ctrl[::-1, ::-1], 1.0 - self.breaks[::-1])

    def to_bspline(self) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
        """Exact clamped cubic B-spline of the chain.

        Returns
        -------
        poles : (3K + 1, D) float
        knots : (3K + 5,) float
            ``[0, 0, 0, 0, s_1, s_1, s_1, ..., s_{K-1} x3, 1, 1, 1, 1]``: a triple interior
            knot makes the B-spline C0 there, so every Bézier piece is reproduced exactly.
        degree : int
            Always 3.
        """
        poles = np.concatenate([self.ctrl[0, :1], self.ctrl[:, 1:].reshape(-1, self.dim)])
        knots = np.concatenate([[0.0] * 4, np.repeat(self.breaks[1:-1], 3), [1.0] * 4])
        return poles, knots, 3


def monomials(t: NDArray[np.float64], order: int = 0) -> NDArray[np.float64]:
    """``d^order/dt^order [1, t, t^2, t^3]`` at ``t`` (n,): shape (n, 4)."""
    out = np.zeros((t.size, 4))
    if order == 0:
        out[:, 0] = 1.0
        out[:, 1] = t
        out[:, 2] = t * t
        out[:, 3] = out[:, 2] * t
    elif order == 1:
        out[:, 1] = 1.0
        out[:, 2] = 2.0 * t
        out[:, 3] = 3.0 * t * t
    elif order == 2:
        out[:, 2] = 2.0
        out[:, 3] = 6.0 * t
    elif order == 3:
        out[:, 3] = 6.0
    else:
        raise InputError(f"derivative order must be 0..3, got {order}")
    return out


def as_curve(curve: PiecewiseBezier | ArrayLike) -> PiecewiseBezier:
    """Coerce a boundary description: a :class:`PiecewiseBezier`, a cubic ``(4, D)``,
    a chain ``(K, 4, D)`` (length spacing) or a point ``(D,)``."""
    if isinstance(curve, PiecewiseBezier):
        return curve
    a = np.asarray(curve, dtype=float)
    if a.ndim == 1:
        return PiecewiseBezier.from_point(a)
    if a.ndim == 2:
        return PiecewiseBezier.from_cubic(a)
    if a.ndim == 3:
        return PiecewiseBezier.from_chain(a)
    raise InputError(
        f"a boundary curve must be a PiecewiseBezier, a cubic (4, D), a chain (K, 4, D) or a "
        f"point (D,); got an array of shape {a.shape}"
    )
