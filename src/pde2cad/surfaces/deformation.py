"""Deformation surfaces added to a Coons base patch (Eqs. 5.17-5.21).

The C0 deformation is the particular solution of the thin-plate equation (Eq. 5.17),

    w(u, v) = sum_{m=1..M} sum_{n=1..N} a_mn sin(m pi u) sin(n pi v),
    a_mn = q_mn / (D pi^4 (m^2 + n^2)^2),

which vanishes on the four sides, so the Coons boundaries (hence shared edges) are kept.
The denominator only rescales the unknowns (the thesis shows D has no effect, Section 5.4.4),
so the fit solves for the amplitudes ``a_mn`` directly and :attr:`Deformation.loads` gives
back the thesis's ``q_mn`` with D = 1.

The C1 deformation (Eq. 5.21) uses ``sin^2(m pi u) sin^2(n pi v)``: it vanishes on the sides
together with its first derivatives (and ``w_uv``), so the sides, cross-boundary derivatives
and corner twists of a bicubic Coons patch are all kept.

Each coefficient is a D-vector (x, y, z); the three coordinates share one design matrix.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import FitError, InputError

Kind = Literal["c0", "c1"]

#: Relative Tikhonov weight used automatically when the fit is close to under-determined.
AUTO_RIDGE = 1e-6
# Rows of the design matrix per QR chunk, scaled by the number of unknowns (memory bound).
_CHUNK_ENTRIES = 4_000_000


def sine_basis(t: ArrayLike, count: int, kind: Kind, order: int = 0) -> NDArray[np.float64]:
    """The 1-D factors of Eq. 5.17 (``kind="c0"``) or Eq. 5.21 (``"c1"``) and derivatives.

    Parameters
    ----------
    t : array_like, any shape
    count : int
        Number of terms (M or N).
    kind : {"c0", "c1"}
    order : {0, 1, 2}
        Derivative order in ``t``.

    Returns
    -------
    (*t.shape, count) float
        ``c0``: ``sin(k pi t)``, ``k pi cos(k pi t)``, ``-(k pi)^2 sin(k pi t)``;
        ``c1``: ``sin^2(k pi t)``, ``k pi sin(2 k pi t)``, ``2 (k pi)^2 cos(2 k pi t)``,
        for k = 1..count.
    """
    t = np.asarray(t, dtype=float)
    freq = np.pi * np.arange(1, count + 1)
    if kind == "c0":
        angle = t[..., None] * freq
        if order == 0:
            return np.sin(angle)
        if order == 1:
            return freq * np.cos(angle)
        if order == 2:
            return -(freq**2) * np.sin(angle)
    elif kind == "c1":
        # sin^2 x = (1 - cos 2x) / 2 keeps the derivatives in closed form.
        angle = 2.0 * t[..., None] * freq
        if order == 0:
            return 0.5 * (1.0 - np.cos(angle))
        if order == 1:
            return freq * np.sin(angle)
        if order == 2:
            return 2.0 * freq**2 * np.cos(angle)
    else:
        raise InputError(f"kind must be 'c0' (Eq. 5.17) or 'c1' (Eq. 5.21), got {kind!r}")
    raise InputError(f"derivative order must be 0, 1 or 2, got {order}")


def _basis_jet(t: NDArray[np.float64], count: int, kind: Kind) -> list[NDArray[np.float64]]:
    """:func:`sine_basis` for orders 0, 1, 2 at once, coordinate-major: three (count, n).

    One sine and one cosine per point, then the angle-addition recurrence
    ``sin((k+1)a) = 2 cos(a) sin(ka) - sin((k-1)a)`` (likewise for cos) gives the multiples:
    ``count`` times fewer transcendental calls than evaluating each term directly.
    """
    angle = (np.pi if kind == "c0" else 2.0 * np.pi) * t
    sin, cos = np.empty((count, t.size)), np.empty((count, t.size))
    sin[0], cos[0] = np.sin(angle), np.cos(angle)
    twice_cos = 2.0 * cos[0]
    if count > 1:
        sin[1] = twice_cos * sin[0]
        cos[1] = twice_cos * cos[0] - 1.0
    for k in range(2, count):
        sin[k] = twice_cos * sin[k - 1] - sin[k - 2]
        cos[k] = twice_cos * cos[k - 1] - cos[k - 2]
    freq = (np.pi * np.arange(1, count + 1))[:, None]
    if kind == "c0":
        return [sin, freq * cos, -(freq**2) * sin]
    return [0.5 * (1.0 - cos), freq * sin, 2.0 * freq**2 * cos]


@dataclass(frozen=True, eq=False)
class Deformation:
    """A fitted sine (C0, Eq. 5.17) or sine-squared (C1, Eq. 5.21) deformation surface.

    Attributes
    ----------
    coefficients : (M, N, D) float
        Amplitudes ``a_mn`` (``coefficients[m-1, n-1]``), so ``w = sum a_mn f_m(u) f_n(v)``.
    kind : {"c0", "c1"}
    ridge : float
        Relative Tikhonov weight used by the fit (0 when none).
    mean_error, max_error : float
        Eq. 5.22 on the fitted residuals, ``|r_i - w(u_i, v_i)|`` (NaN if not from a fit).
    """

    coefficients: NDArray[np.float64]
    kind: Kind = "c0"
    ridge: float = 0.0
    mean_error: float = field(default=float("nan"))
    max_error: float = field(default=float("nan"))

    def __post_init__(self) -> None:
        c = np.array(self.coefficients, dtype=float)
        if c.ndim != 3:
            raise InputError(f"coefficients must have shape (M, N, D), got {c.shape}")
        if self.kind not in ("c0", "c1"):
            raise InputError(f"kind must be 'c0' or 'c1', got {self.kind!r}")
        c.setflags(write=False)
        object.__setattr__(self, "coefficients", c)

    @property
    def m(self) -> int:
        """Number M of terms in u."""
        return int(self.coefficients.shape[0])

    @property
    def n(self) -> int:
        """Number N of terms in v."""
        return int(self.coefficients.shape[1])

    @property
    def loads(self) -> NDArray[np.float64]:
        """Lateral-force coefficients ``q_mn = a_mn pi^4 (m^2 + n^2)^2`` of Eq. 5.16 (D = 1),
        shape (M, N, D). Only meaningful for ``kind="c0"``."""
        m = np.arange(1, self.m + 1)[:, None]
        n = np.arange(1, self.n + 1)[None, :]
        return self.coefficients * (np.pi**4 * (m * m + n * n) ** 2)[..., None]

    def _partial(
        self, u: NDArray[np.float64], v: NDArray[np.float64], a: int, b: int
    ) -> NDArray[np.float64]:
        fu = sine_basis(u, self.m, self.kind, a)  # (*u, M)
        fv = sine_basis(v, self.n, self.kind, b)  # (*v, N)
        d = self.coefficients.shape[2]
        # einsum rather than @: no threaded-BLAS start-up cost for these thin products.
        inner = np.einsum("...m,mk->...k", fu, self.coefficients.reshape(self.m, self.n * d))
        return np.einsum("...n,...nd->...d", fv, inner.reshape((*u.shape, self.n, d)))

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Displacement ``w(u, v)``; ``u``, ``v`` broadcast, result ``shape + (D,)``."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        return self._partial(u, v, 0, 0)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(w_u, w_v)``, analytic."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        return self._partial(u, v, 1, 0), self._partial(u, v, 0, 1)

    def second_derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(w_uu, w_uv, w_vv)``, analytic."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        return self._partial(u, v, 2, 0), self._partial(u, v, 1, 1), self._partial(u, v, 0, 2)

    def jet(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """``(w, w_u, w_v, w_uu, w_uv, w_vv)``, analytic.

        Computed coordinate-major (D, n) with the points on the fast axis and returned as
        transposed views, like the Coons patches, so sums with a base jet stay fast.
        """
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        shape = u.shape
        u, v = u.reshape(-1), v.reshape(-1)
        d = self.coefficients.shape[2]
        fu = _basis_jet(u, self.m, self.kind)  # three (M, n)
        fv = _basis_jet(v, self.n, self.kind)  # three (N, n)
        # coefficients as (N * D, M): contract m first, then n per jet order.
        flat = self.coefficients.transpose(1, 2, 0).reshape(self.n * d, self.m)
        inner = [np.einsum("km,mp->kp", flat, f).reshape(self.n, d, u.size) for f in fu]
        out = []
        for a, b in ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)):
            out.append(np.einsum("np,ndp->dp", fv[b], inner[a]).T.reshape((*shape, d)))
        return tuple(out)


class ParametricSurface(Protocol):
    """What a base patch offers (:class:`~pde2cad.surfaces.coons.BilinearCoons` and
    :class:`~pde2cad.surfaces.coons.BicubicCoons` do)."""

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]: ...

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...

    def second_derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]: ...

    def jet(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], ...]: ...


@dataclass(frozen=True, eq=False)
class DeformedPatch:
    """``S(u, v) = S_c(u, v) + w(u, v)`` (Eq. 5.20): a base patch plus a deformation."""

    base: ParametricSurface
    deformation: Deformation

    def evaluate(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Points ``S(u, v)``."""
        return self.base.evaluate(u, v) + self.deformation.evaluate(u, v)

    def derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(S_u, S_v)``."""
        a, b = self.base.derivatives(u, v), self.deformation.derivatives(u, v)
        return a[0] + b[0], a[1] + b[1]

    def second_derivatives(
        self, u: ArrayLike, v: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(S_uu, S_uv, S_vv)``."""
        a, b = self.base.second_derivatives(u, v), self.deformation.second_derivatives(u, v)
        return a[0] + b[0], a[1] + b[1], a[2] + b[2]

    def jet(self, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """``(S, S_u, S_v, S_uu, S_uv, S_vv)``."""
        return tuple(
            x + y for x, y in zip(self.base.jet(u, v), self.deformation.jet(u, v), strict=True)
        )


# --------------------------------------------------------------------------- fitting
def _check_fit_input(
    residuals: ArrayLike, params: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r = np.asarray(residuals, dtype=float)
    p = np.asarray(params, dtype=float)
    if r.ndim != 2 or p.shape != (r.shape[0], 2):
        raise InputError(
            "residuals must be (N, D) and params (N, 2) with the same N; "
            f"got {r.shape} and {p.shape}"
        )
    if r.shape[0] == 0:
        raise InputError("no residuals to fit; a deformation needs points inside the patch")
    bad = ~(np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(p), axis=1))
    if bad.any():
        raise InputError(
            f"{int(bad.sum())} of {r.shape[0]} residuals/params contain NaN or inf "
            f"(first at row {int(np.argmax(bad))}); drop those points before fitting"
        )
    if np.any(p < 0.0) or np.any(p > 1.0):
        raise InputError(
            "params must lie in [0, 1]^2; drop the points project_points flags as outside"
        )
    return r, p


def _design(
    u: NDArray[np.float64], v: NDArray[np.float64], m: int, n: int, kind: Kind
) -> NDArray[np.float64]:
    """Separable design matrix ``A[i, m*N + n] = f_m(u_i) f_n(v_i)``: shape (len(u), M N)."""
    fu = sine_basis(u, m, kind)
    fv = sine_basis(v, n, kind)
    return (fu[:, :, None] * fv[:, None, :]).reshape(u.size, m * n)


def fit_deformation(
    residuals: ArrayLike,
    params: ArrayLike,
    m: int,
    n: int,
    kind: Kind = "c0",
    ridge: float | None = None,
) -> Deformation:
    """Least-squares fit of a deformation to the base-patch residuals (Eqs. 5.18, 5.19).

    Minimizes ``sum_i |r_i - w(u_i, v_i)|^2 + lam sum_mn |a_mn|^2`` with the separable
    design ``f_m(u_i) f_n(v_i)``, accumulated chunk by chunk into the (M N, M N) normal
    equations (a million points need no million-by-MN matrix), refined when ill conditioned.

    Parameters
    ----------
    residuals : (N_pts, D) float
        ``P_i - S_c(u_i, v_i)``.
    params : (N_pts, 2) float
        ``(u_i, v_i)`` in [0, 1]^2.
    m, n : int
        Numbers of terms M, N (Eq. 5.17).
    kind : {"c0", "c1"}
        Eq. 5.17 or Eq. 5.21.
    ridge : float, optional
        Relative Tikhonov weight: ``lam = ridge * trace(A^T A) / (M N)``. ``None`` (default)
        uses none when the data determine every term, and ``AUTO_RIDGE`` when they nearly do
        not (fewer than 2 M N points, or a design singular-value ratio below 1e-6), which is where
        the thesis's "M N = I gives zero error" turns into oscillation. ``0`` forces none.

    Returns
    -------
    Deformation

    Raises
    ------
    InputError
        Wrong shapes, NaN, params outside [0, 1], M or N < 1.
    FitError
        Fewer points than M N unknowns and no ``ridge`` given.
    """
    r, p = _check_fit_input(residuals, params)
    if int(m) != m or int(n) != n or m < 1 or n < 1:
        raise InputError(f"M and N must be positive integers, got M={m}, N={n}")
    if kind not in ("c0", "c1"):
        raise InputError(f"kind must be 'c0' (Eq. 5.17) or 'c1' (Eq. 5.21), got {kind!r}")
    m, n = int(m), int(n)
    n_pts, dim = r.shape
    unknowns = m * n
    if ridge is None and n_pts < unknowns:
        raise FitError(
            f"{n_pts} points cannot determine M*N = {unknowns} coefficients; lower M and N "
            f"(M*N <= {n_pts}) or pass ridge=1e-6 to regularize"
        )
    if ridge is not None and ridge < 0:
        raise InputError(f"ridge must be >= 0, got {ridge}")

    rows = max(1, _CHUNK_ENTRIES // unknowns)
    chunks = [slice(i, min(i + rows, n_pts)) for i in range(0, n_pts, rows)]

    def design(part: slice) -> NDArray[np.float64]:
        return _design(p[part, 0], p[part, 1], m, n, kind)

    # Normal equations accumulated chunk by chunk: a streaming QR costs ~15x more in LAPACK
    # for these tall, thin systems, and the sine design is well conditioned on spread-out
    # points; iterative refinement below recovers the digits squaring loses when it is not.
    gram = np.zeros((unknowns, unknowns))
    rhs = np.zeros((unknowns, dim))
    for part in chunks:
        a = design(part)
        gram += a.T @ a
        rhs += a.T @ r[part]
    eig = np.linalg.eigvalsh(gram)
    scale = float(np.trace(gram)) / unknowns
    if ridge is None:
        # eig ratio 1e-12 is a singular-value ratio of 1e-6 for the design itself.
        near_singular = eig[0] <= 1e-12 * eig[-1]
        ridge = AUTO_RIDGE if (n_pts < 2 * unknowns or near_singular) else 0.0
    system = gram + ridge * scale * np.eye(unknowns)

    def solve(b: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.linalg.lstsq(system, b, rcond=None)[0]

    coef = solve(rhs)
    if eig[0] < 1e-6 * eig[-1]:
        # cond(A) > 1e3: squaring it in the normal equations costs digits, so refine once.
        correction = np.zeros_like(rhs)
        for part in chunks:
            a = design(part)
            correction += a.T @ (r[part] - a @ coef)
        coef += solve(correction - ridge * scale * coef)
    coefficients = coef.reshape(m, n, dim)
    err = np.empty(n_pts)
    for part in chunks:
        err[part] = np.linalg.norm(r[part] - design(part) @ coef, axis=1)
    return Deformation(
        coefficients=coefficients,
        kind=kind,
        ridge=float(ridge),
        mean_error=float(err.mean()),
        max_error=float(err.max()),
    )


def choose_mn(
    residuals: ArrayLike,
    params: ArrayLike,
    tolerance: float,
    kind: Kind = "c0",
    max_mn: int = 20,
    ridge: float | None = None,
) -> Deformation:
    """Fit with the fewest terms that bring the max error (Eq. 5.22) to ``tolerance``.

    First the smallest ``M = N = K`` that reaches it (the thesis tunes M = N, Section 5.4.4);
    then the smallest ``M <= K`` with ``N = K``, then the smallest ``N <= K`` with that M,
    since a patch that bends mostly in one direction needs few terms in the other.

    Parameters
    ----------
    residuals, params, kind, ridge
        As in :func:`fit_deformation`.
    tolerance : float
        Target for the max error ``max_i |r_i - w(u_i, v_i)|``, in the units of the points.
    max_mn : int
        Largest K tried (also capped so M N stays <= the number of points unless ``ridge``).

    Raises
    ------
    FitError
        If no K <= max_mn reaches the tolerance; the message gives the best error reached.
    """
    r, p = _check_fit_input(residuals, params)
    if not tolerance > 0:
        raise InputError(f"tolerance must be > 0, got {tolerance}")
    best: Deformation | None = None
    last: Deformation | None = None
    for k in range(1, max_mn + 1):
        if ridge is None and k * k > r.shape[0]:
            break
        last = fit_deformation(r, p, k, k, kind, ridge)
        if last.max_error <= tolerance:
            best = last
            break
    if best is None:
        reached = (
            "too few points for M = N = 1"
            if last is None
            else f"best max error {last.max_error:.3g} at M = N = {last.m}"
        )
        raise FitError(
            f"tolerance {tolerance:.3g} not reached with M = N <= {max_mn} ({reached}); raise "
            "max_mn, loosen the tolerance, or check the parameterization and boundaries"
        )
    k = best.m
    for m in range(1, k):
        trial = fit_deformation(r, p, m, k, kind, ridge)
        if trial.max_error <= tolerance:
            best = trial
            break
    for n in range(1, k):
        trial = fit_deformation(r, p, best.m, n, kind, ridge)
        if trial.max_error <= tolerance:
            best = trial
            break
    return best
