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

But every ``sin^2(m pi t)`` is symmetric about ``t = 1/2`` (``sin^2(m pi (1 - t)) =
sin^2(m pi t)``), so Eq. 5.21 can only produce deformations that are mirror-symmetric in u and
in v: whatever M and N, it cannot fit a residual that differs between the two halves of the
patch. ``kind="c1full"`` replaces the factors by ``sin(pi t) sin(m pi t)``, which vanish with
their first derivative at t = 0 and 1 just the same, are complete (``sin(pi t)`` times the
sine series of Eq. 5.17) and contain Eq. 5.21: ``sin^2(m pi t) = sum_{j=1..m} sin(pi t)
sin((2j - 1) pi t)``. ``"c1"`` stays the thesis's literal Eq. 5.21.

Each coefficient is a D-vector (x, y, z); the three coordinates share one design matrix.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_factor, cho_solve

from pde2cad.errors import FitError, InputError

Kind = Literal["c0", "c1", "c1full"]
#: The deformation bases: Eq. 5.17, Eq. 5.21, and the complete C1 basis (module docstring).
KINDS = ("c0", "c1", "c1full")

_T = TypeVar("_T")

#: Relative Tikhonov weight used automatically when the fit is close to under-determined.
AUTO_RIDGE = 1e-6
#: Candidate M = N of the automatic term count (:func:`select_terms`).
AUTO_TERMS = (6, 8, 10, 12, 14, 16)
#: Share of the points held out to score each candidate, and the largest sample scored.
AUTO_HOLDOUT = 0.25
AUTO_SAMPLE = 20_000
#: Fewest training points per unknown of a candidate.
AUTO_POINTS_PER_TERM = 4
#: The smallest candidate whose held-out RMS error is within this factor of the best wins.
AUTO_SLACK = 1.01
#: Largest ratio of a candidate's deformation anywhere on the patch (a SWING_GRID grid) to
#: its largest at the points (sound fits stay under 1.7, see reconstruct.C1_SWING_RATIO).
AUTO_SWING = 4.0
SWING_GRID = 21


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise InputError(
            f"kind must be 'c0' (Eq. 5.17), 'c1' (Eq. 5.21) or 'c1full' (complete C1 basis), "
            f"got {kind!r}"
        )


def sine_basis(t: ArrayLike, count: int, kind: Kind, order: int = 0) -> NDArray[np.float64]:
    """The 1-D factors of Eq. 5.17 (``kind="c0"``), Eq. 5.21 (``"c1"``) or the complete C1
    basis (``"c1full"``, module docstring) and their derivatives.

    Parameters
    ----------
    t : array_like, any shape
    count : int
        Number of terms (M or N).
    kind : {"c0", "c1", "c1full"}
    order : {0, 1, 2}
        Derivative order in ``t``.

    Returns
    -------
    (*t.shape, count) float
        ``c0``: ``sin(k pi t)``, ``k pi cos(k pi t)``, ``-(k pi)^2 sin(k pi t)``;
        ``c1``: ``sin^2(k pi t)``, ``k pi sin(2 k pi t)``, ``2 (k pi)^2 cos(2 k pi t)``;
        ``c1full``: ``sin(pi t) sin(k pi t) = (cos((k-1) pi t) - cos((k+1) pi t)) / 2`` and
        its derivatives; for k = 1..count.
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
        angle = t[..., None] * (2.0 * freq)  # exact: 2x only shifts the exponent
        if order == 0:
            return 0.5 * (1.0 - np.cos(angle))
        if order == 1:
            return freq * np.sin(angle)
        if order == 2:
            return 2.0 * freq**2 * np.cos(angle)
    elif kind == "c1full":
        lo, hi = freq - np.pi, freq + np.pi  # (k - 1) pi and (k + 1) pi
        a_lo, a_hi = t[..., None] * lo, t[..., None] * hi
        if order == 0:
            return 0.5 * (np.cos(a_lo) - np.cos(a_hi))
        if order == 1:
            return 0.5 * (hi * np.sin(a_hi) - lo * np.sin(a_lo))
        if order == 2:
            return 0.5 * (hi**2 * np.cos(a_hi) - lo**2 * np.cos(a_lo))
    else:
        _check_kind(kind)
    raise InputError(f"derivative order must be 0, 1 or 2, got {order}")


def _basis_jet(t: NDArray[np.float64], count: int, kind: Kind) -> list[NDArray[np.float64]]:
    """:func:`sine_basis` for orders 0, 1, 2 at once, coordinate-major: three (count, n).

    One sine and one cosine per point, then the angle-addition recurrence
    ``sin((k+1)a) = 2 cos(a) sin(ka) - sin((k-1)a)`` (likewise for cos) gives the multiples:
    ``count`` times fewer transcendental calls than evaluating each term directly.
    """
    if kind == "c1full":
        # Multiples 0..count+1 of pi t; term k combines multiples k - 1 and k + 1.
        mult = np.arange(count + 2)[:, None] * np.pi
        cos_all = _cos_multiples(np.cos(np.pi * t), count + 1)
        sin_all = np.vstack(
            [np.zeros((1, t.size)), _sin_multiples(np.sin(np.pi * t), cos_all[1], count + 1)]
        )
        lo, hi = slice(0, count), slice(2, count + 2)
        return [
            0.5 * (cos_all[lo] - cos_all[hi]),
            0.5 * (mult[hi] * sin_all[hi] - mult[lo] * sin_all[lo]),
            0.5 * (mult[hi] ** 2 * cos_all[hi] - mult[lo] ** 2 * cos_all[lo]),
        ]
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
    kind : {"c0", "c1", "c1full"}
    ridge : float
        Relative Tikhonov weight used by the fit (0 when none).
    mean_error, max_error, rms_error : float
        Eq. 5.22 on the fitted residuals, ``|r_i - w(u_i, v_i)|``, and their root mean
        square (NaN if not from a fit).
    """

    coefficients: NDArray[np.float64]
    kind: Kind = "c0"
    ridge: float = 0.0
    mean_error: float = field(default=float("nan"))
    max_error: float = field(default=float("nan"))
    rms_error: float = field(default=float("nan"))

    def __post_init__(self) -> None:
        c = np.array(self.coefficients, dtype=float)
        if c.ndim != 3:
            raise InputError(f"coefficients must have shape (M, N, D), got {c.shape}")
        _check_kind(self.kind)
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
    # Whole arrays first: per-row tests of a million points cost ten times more.
    if not (np.isfinite(r).all() and np.isfinite(p).all()):
        bad = ~(np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(p), axis=1))
        raise InputError(
            f"{int(bad.sum())} of {r.shape[0]} residuals/params contain NaN or inf "
            f"(first at row {int(np.argmax(bad))}); drop those points before fitting"
        )
    if np.any(p < 0.0) or np.any(p > 1.0):
        raise InputError(
            "params must lie in [0, 1]^2; drop the points project_points flags as outside"
        )
    return r, p


#: Points per chunk of the fit: its ~90 rows of temporaries for M = N = 10 (6 MB) stay in
#: cache, while each BLAS product is still large enough to run at full speed (1e6 points:
#: 0.28 s CPU against 0.37 s with chunks of 65,536 and 0.37 s with 2,048).
_CHUNK = 8_192
#: Fewer points than this are fitted on one thread (threads would cost more than they save).
_MIN_SPLIT = 8_192


@contextmanager
def _single_threaded_blas() -> Iterator[None]:
    """Hold BLAS to one thread for the thin products of the fit.

    Products such as (21, 65536) @ (65536, 21) have a tiny output and one long inner
    dimension. A threaded OpenBLAS splits them at barriers that cost more than the arithmetic:
    on a loaded 2-core machine they ran 30-100x slower than on one thread. threadpoolctl is
    optional (FreeCAD's Python lacks it); without it BLAS keeps its own setting.
    """
    controller = _blas_controller()
    if controller is None:  # pragma: no cover - depends on the environment
        yield
        return
    with controller.limit(limits=1, user_api="blas"):
        yield


_CONTROLLER: list[Any] = []  # threadpoolctl is untyped


def _blas_controller() -> Any:
    """One threadpoolctl controller for the process (or None without threadpoolctl).

    Creating one scans every loaded shared library (about 2 ms); the BLAS numpy uses is
    loaded with numpy, so the first scan finds it and later limits reuse it.
    """
    if not _CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - depends on the environment
            _CONTROLLER.append(None)
        else:
            _CONTROLLER.append(ThreadpoolController())
    return _CONTROLLER[0]


def _cos_multiples(cos1: NDArray[np.float64], count: int) -> NDArray[np.float64]:
    """``cos(j a)`` for j = 0..count given ``cos1 = cos(a)`` (n,): shape (count + 1, n).

    Chebyshev recurrence ``cos((j+1)a) = 2 cos(a) cos(ja) - cos((j-1)a)``: one cosine per
    point instead of one per term.
    """
    out = np.empty((count + 1, cos1.size))
    out[0] = 1.0
    if count >= 1:
        out[1] = cos1
    twice = 2.0 * out[min(count, 1)]
    for j in range(2, count + 1):
        np.multiply(twice, out[j - 1], out=out[j])
        out[j] -= out[j - 2]
    return out


def _sin_multiples(
    sin1: NDArray[np.float64], cos1: NDArray[np.float64], count: int
) -> NDArray[np.float64]:
    """``sin(j a)`` for j = 1..count, shape (count, n), given ``sin1 = sin(a)`` and
    ``cos1 = cos(a)``: ``sin((j+1)a) = 2 cos(a) sin(ja) - sin((j-1)a)``."""
    out = np.empty((count, sin1.size))
    out[0] = sin1
    twice = 2.0 * cos1
    if count > 1:
        np.multiply(twice, out[0], out=out[1])
    for j in range(2, count):
        np.multiply(twice, out[j - 1], out=out[j])
        out[j] -= out[j - 2]
    return out


def _top_frequency(count: int, kind: Kind) -> int:
    """Highest multiple of ``theta`` in the products ``f_a f_b`` (see :func:`_product_weights`)."""
    return 2 * count + 2 if kind == "c1full" else 2 * count


def _angle_trig(t: NDArray[np.float64], kind: Kind, out: NDArray[np.float64]) -> None:
    """``cos(theta)`` into ``out[0]`` and, for ``c0``, ``sin(theta)`` into ``out[1]`` at the
    parameters ``t`` (n,); ``theta = 2 pi t`` for ``c1`` and ``pi t`` otherwise (see
    :func:`_product_weights`). The only transcendental calls of a fit: the passes over the
    points share them (:class:`_NormalData`)."""
    angle = (2.0 * np.pi if kind == "c1" else np.pi) * t
    np.cos(angle, out=out[0])
    if kind == "c0":
        np.sin(angle, out=out[1])


def _chunk_basis(
    trig: NDArray[np.float64], count: int, kind: Kind, moments: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The 1-D factors ``f_k(t)``, k = 1..count, and the cosines ``cos(j theta)``,
    j = 0..moments, that their products expand into, from ``trig`` (2, n) of
    :func:`_angle_trig`.

    Returns
    -------
    basis : (count, n) float
    cosines : (at least moments + 1, n) float
    """
    if kind == "c0":
        cosines = _cos_multiples(trig[0], max(moments, 1))
        return _sin_multiples(trig[1], trig[0], count), cosines
    if kind == "c1":
        # sin^2(k pi t) = (1 - cos(k theta)) / 2 with theta = 2 pi t.
        cosines = _cos_multiples(trig[0], max(moments, count))
        return 0.5 * (1.0 - cosines[1 : count + 1]), cosines
    # sin(pi t) sin(k pi t) = (cos((k - 1) theta) - cos((k + 1) theta)) / 2, theta = pi t.
    cosines = _cos_multiples(trig[0], max(moments, count + 1))
    return 0.5 * (cosines[:count] - cosines[2 : count + 2]), cosines


def _product_weights(count: int, kind: Kind) -> NDArray[np.float64]:
    """Weights ``T`` with ``f_a f_b = sum_j T[a, b, j] cos(j theta)``, shape
    (count, count, top + 1) with ``top`` from :func:`_top_frequency`.

    ``c0``: ``sin(a x) sin(b x) = (cos((a-b) x) - cos((a+b) x)) / 2`` with ``theta = x = pi t``.
    ``c1``: ``sin^2(a x) sin^2(b x) = 1/4 - cos(a theta)/4 - cos(b theta)/4
    + cos((a-b) theta)/8 + cos((a+b) theta)/8`` with ``theta = 2 x``.
    ``c1full``: ``f_a = (cos(a_- theta) - cos(a_+ theta)) / 2`` with ``a_-+ = a -+ 1`` and
    ``theta = pi t``; expand the product with ``cos x cos y = (cos(x-y) + cos(x+y)) / 2``.
    So the Gram matrix of the separable basis needs only the 2-D cosine moments of the
    parameters (see :func:`_accumulate`), not the (points, M N) design matrix.
    """
    k = np.arange(1, count + 1)
    a, b = np.meshgrid(k, k, indexing="ij")
    ia, ib = a - 1, b - 1
    weights = np.zeros((count, count, _top_frequency(count, kind) + 1))
    # Each assignment hits every (a, b) once, so += through fancy indexing is safe.
    if kind == "c0":
        weights[ia, ib, np.abs(a - b)] += 0.5
        weights[ia, ib, a + b] -= 0.5
    elif kind == "c1":
        weights[..., 0] += 0.25
        weights[ia, ib, a] -= 0.25
        weights[ia, ib, b] -= 0.25
        weights[ia, ib, np.abs(a - b)] += 0.125
        weights[ia, ib, a + b] += 0.125
    else:
        for da, sa in ((-1, 1.0), (1, -1.0)):
            for db, sb in ((-1, 1.0), (1, -1.0)):
                x, y = a + da, b + db
                weights[ia, ib, np.abs(x - y)] += 0.125 * sa * sb
                weights[ia, ib, x + y] += 0.125 * sa * sb
    return weights


def _project_residuals(
    fu: NDArray[np.float64], fv: NDArray[np.float64], rt: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``A^T r`` for one chunk: ``sum_i f_m(u_i) f_n(v_i) r_i``, shape (M, N, D), from the
    factors ``fu`` (M, c), ``fv`` (N, c) and the residuals coordinate-major, ``rt`` (D, c)."""
    m, n, dim = fu.shape[0], fv.shape[0], rt.shape[0]
    weighted = (fv[:, None, :] * rt[None, :, :]).reshape(n * dim, -1)  # (N D, c)
    return (fu @ weighted.T).reshape(m, n, dim)


@dataclass(frozen=True, eq=False)
class _NormalData:
    """The normal equations (Eq. 5.19) for every ``M <= M_max`` and ``N <= N_max`` at once.

    Attributes
    ----------
    kind : {"c0", "c1", "c1full"}
    moments : (top(M_max) + 1, top(N_max) + 1) float
        ``sum_i cos(k theta(u_i)) cos(l theta(v_i))``, ``top`` from :func:`_top_frequency`.
    rhs : (M_max, N_max, D) float
        ``sum_i f_m(u_i) f_n(v_i) r_i``.
    trig : (4, N_pts) float
        :func:`_angle_trig` of ``u`` (rows 0-1) and ``v`` (rows 2-3) for the residual
        passes over the same points (sines and cosines cost half of a pass).
    """

    kind: Kind
    moments: NDArray[np.float64]
    rhs: NDArray[np.float64]
    trig: NDArray[np.float64] = field(repr=False)

    def system(self, m: int, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Gram matrix (M N, M N) and right-hand side (M N, D), column ``m * N + n``."""
        wu = _product_weights(m, self.kind)
        wv = _product_weights(n, self.kind)
        tu, tv = _top_frequency(m, self.kind), _top_frequency(n, self.kind)
        half = np.einsum("aAk,kl->aAl", wu, self.moments[: tu + 1, : tv + 1])
        gram = np.einsum("aAl,bBl->abAB", half, wv).reshape(m * n, m * n)
        return 0.5 * (gram + gram.T), self.rhs[:m, :n].reshape(m * n, -1)


def _chunk_map(fn: Callable[[slice], _T], n_pts: int) -> list[_T]:
    """``fn`` on every chunk of ``range(n_pts)``, on one thread per core.

    numpy releases the GIL in its array loops and BLAS runs single-threaded here (see
    :func:`_single_threaded_blas`), so chunks proceed in parallel; results keep chunk order.
    """
    cores = os.cpu_count() or 1
    size = _CHUNK
    if cores > 1 and n_pts > _MIN_SPLIT:
        # Equal chunks, a whole number per core: a short last chunk would keep the other
        # cores idle while it runs.
        rounds = -(-n_pts // (cores * _CHUNK))
        size = -(-n_pts // (cores * rounds))
    chunks = [slice(i, min(i + size, n_pts)) for i in range(0, n_pts, size)]
    threads = min(len(chunks), cores)
    if threads <= 1:
        return [fn(part) for part in chunks]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(fn, chunks))


def _accumulate(
    r: NDArray[np.float64], p: NDArray[np.float64], m: int, n: int, kind: Kind
) -> _NormalData:
    """One pass over the points: cosine moments and ``A^T r`` (call under
    :func:`_single_threaded_blas`).

    The Gram matrix ``A^T A`` of the (points, M N) design would cost ``(M N)^2`` per point;
    the moments cost ``(2M + 1)(2N + 1)``, a 20x saving at M = N = 10, and ``A`` is never
    formed: ``A^T r`` comes from the separable factors.
    """
    tu, tv = _top_frequency(m, kind), _top_frequency(n, kind)
    trig = np.empty((4, r.shape[0]))

    def chunk(part: slice) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # Coordinate-major copies per chunk (on its thread): every later operation then
        # runs along contiguous rows.
        pt = np.ascontiguousarray(p[part].T)
        _angle_trig(pt[0], kind, trig[0:2, part])
        _angle_trig(pt[1], kind, trig[2:4, part])
        fu, cu = _chunk_basis(trig[0:2, part], m, kind, tu)
        fv, cv = _chunk_basis(trig[2:4, part], n, kind, tv)
        rt = np.ascontiguousarray(r[part].T)
        return cu[: tu + 1] @ cv[: tv + 1].T, _project_residuals(fu, fv, rt)

    parts = _chunk_map(chunk, r.shape[0])
    moments = np.sum([a for a, _ in parts], axis=0)
    rhs = np.sum([b for _, b in parts], axis=0)
    return _NormalData(kind=kind, moments=moments, rhs=rhs, trig=trig)


def _residual_pass(
    r: NDArray[np.float64],
    coef: NDArray[np.float64],
    kind: Kind,
    trig: NDArray[np.float64],
    normal: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """``|r_i - w(u_i, v_i)|`` (n_pts,) for coefficients ``coef`` (M, N, D) and, with
    ``normal``, ``A^T (r - A a)`` (M, N, D) for iterative refinement; ``trig`` as in
    :class:`_NormalData`."""
    m, n, dim = coef.shape
    norms = np.empty(r.shape[0])
    flat = coef.reshape(m, n * dim).T  # (N D, M)

    def chunk(part: slice) -> NDArray[np.float64] | None:
        fu, _ = _chunk_basis(trig[0:2, part], m, kind)
        fv, _ = _chunk_basis(trig[2:4, part], n, kind)
        inner = (flat @ fu).reshape(n, dim, -1)  # sum_m a_mn f_m(u_i)
        left = r[part].T - np.einsum("nc,ndc->dc", fv, inner)
        norms[part] = np.sqrt(np.einsum("dc,dc->c", left, left))  # disjoint slices
        return _project_residuals(fu, fv, left) if normal else None

    parts = _chunk_map(chunk, r.shape[0])
    back = np.sum([b for b in parts if b is not None], axis=0) if normal else None
    return norms, back


def _flat_top_map(n: int) -> NDArray[np.float64]:
    """(n + 1, n) amplitudes of ``sin(k pi v)``, k = 1..n+1, of the terms
    ``psi_j(v) = sin(j pi v) + j (-1)^j sin(pi v)``, j = 2..n+1: zero at v = 0 and 1 like
    every sine, and also zero slope at v = 1 (``j pi (-1)^j - j (-1)^j pi = 0``)."""
    j = np.arange(2, n + 2)
    out = np.zeros((n + 1, n))
    out[j - 1, j - 2] = 1.0
    out[0] = j * (-1.0) ** j
    return out


def _solve(
    r: NDArray[np.float64],
    data: _NormalData,
    m: int,
    n: int,
    ridge: float | None,
    flat_top: bool = False,
) -> Deformation:
    """Solve the normal equations for ``M = m, N = n`` from ``data`` (call under
    :func:`_single_threaded_blas`); see :func:`fit_deformation` for ``ridge`` and
    ``flat_top`` (which needs ``data`` accumulated for ``n + 1``)."""
    n_pts, dim = r.shape
    unknowns = m * n
    gram, rhs = data.system(m, n + 1 if flat_top else n)
    lift = None
    if flat_top:
        lift = np.kron(np.eye(m), _flat_top_map(n))  # full amplitudes = lift @ reduced ones
        gram, rhs = lift.T @ gram @ lift, lift.T @ rhs
    eig = np.linalg.eigvalsh(gram)
    scale = float(np.trace(gram)) / unknowns
    # eig ratio 1e-12 is a singular-value ratio of 1e-6 for the design itself.
    near_singular = bool(eig[0] <= 1e-12 * eig[-1])
    if ridge is None:
        ridge = AUTO_RIDGE if (n_pts < 2 * unknowns or near_singular) else 0.0
    system = gram + ridge * scale * np.eye(unknowns)

    def solve(b: NDArray[np.float64]) -> NDArray[np.float64]:
        if ridge == 0.0 and near_singular:
            # Only reachable with ridge=0 forced: the minimum-norm answer, not Cholesky noise.
            return np.asarray(np.linalg.lstsq(system, b, rcond=None)[0], dtype=float)
        try:
            return cho_solve(cho_factor(system, check_finite=False), b, check_finite=False)
        except np.linalg.LinAlgError:
            return np.asarray(np.linalg.lstsq(system, b, rcond=None)[0], dtype=float)

    coef = solve(rhs)
    n_full = n + 1 if flat_top else n

    def full(c: NDArray[np.float64]) -> NDArray[np.float64]:
        return (c if lift is None else lift @ c).reshape(m, n_full, dim)

    if eig[0] < 1e-6 * eig[-1]:
        # cond(A) > 1e3: the normal equations square it and lose digits, so refine once.
        _, back = _residual_pass(r, full(coef), data.kind, data.trig, normal=True)
        assert back is not None
        back = back.reshape(m * n_full, dim)
        if lift is not None:
            back = lift.T @ back
        coef = coef + solve(back - ridge * scale * coef)
    coefficients = full(coef)
    err, _ = _residual_pass(r, coefficients, data.kind, data.trig)
    return Deformation(
        coefficients=coefficients,
        kind=data.kind,
        ridge=float(ridge),
        mean_error=float(err.mean()),
        max_error=float(err.max()),
        rms_error=float(np.sqrt(np.mean(err * err))),
    )


def fit_deformation(
    residuals: ArrayLike,
    params: ArrayLike,
    m: int,
    n: int,
    kind: Kind = "c0",
    ridge: float | None = None,
    flat_top: bool = False,
) -> Deformation:
    """Least-squares fit of a deformation to the base-patch residuals (Eqs. 5.18, 5.19).

    Minimizes ``sum_i |r_i - w(u_i, v_i)|^2 + lam sum_mn |a_mn|^2`` over the amplitudes.
    The (M N, M N) normal equations are assembled from 2-D cosine moments of the
    parameters (products of sines are sums of cosines, :func:`_product_weights`), chunk by
    chunk, so a million points need neither a million-by-MN matrix nor ``(M N)^2`` work per
    point; they are solved by Cholesky and refined once when ill conditioned. The sine basis
    is close to orthogonal on spread-out parameters, so squaring its condition number is
    harmless in the usual case.

    Parameters
    ----------
    residuals : (N_pts, D) float
        ``P_i - S_c(u_i, v_i)``.
    params : (N_pts, 2) float
        ``(u_i, v_i)`` in [0, 1]^2.
    m, n : int
        Numbers of terms M, N (Eq. 5.17).
    kind : {"c0", "c1", "c1full"}
        Eq. 5.17, Eq. 5.21, or the complete C1 basis (module docstring).
    ridge : float, optional
        Relative Tikhonov weight: ``lam = ridge * trace(A^T A) / (M N)``. ``None`` (default)
        uses none when the data determine every term, and ``AUTO_RIDGE`` when they nearly do
        not (fewer than 2 M N points, or a design singular-value ratio below 1e-6), which is where
        the thesis's "M N = I gives zero error" turns into oscillation. ``0`` forces none.
    flat_top : bool
        ``kind="c0"`` only: also zero slope across ``v = 1`` (the collapsed side of a
        3-sided patch, where a sine term's slope, different for every u, would make the apex
        a cone). Fitted as N terms ``sin(j pi v) + j (-1)^j sin(pi v)``, j = 2..N+1; the
        result is an ordinary c0 deformation with ``N + 1`` terms in v.

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
    _check_kind(kind)
    m, n = int(m), int(n)
    n_pts = r.shape[0]
    unknowns = m * n
    if ridge is None and n_pts < unknowns:
        raise FitError(
            f"{n_pts} points cannot determine M*N = {unknowns} coefficients; lower M and N "
            f"(M*N <= {n_pts}) or pass ridge=1e-6 to regularize"
        )
    if ridge is not None and ridge < 0:
        raise InputError(f"ridge must be >= 0, got {ridge}")
    if flat_top and kind != "c0":
        raise InputError(f"flat_top applies to kind='c0' (the C1 kinds are flat already), got {kind!r}")
    with _single_threaded_blas():
        data = _accumulate(r, p, m, n + 1 if flat_top else n, kind)
        return _solve(r, data, m, n, ridge, flat_top)


def select_terms(
    residuals: ArrayLike,
    params: ArrayLike,
    kind: Kind = "c0",
    candidates: tuple[int, ...] = AUTO_TERMS,
    seed: int = 0,
    flat_top: bool = False,
) -> int:
    """The term count ``M = N`` that predicts held-out points best (hold-out validation).

    A random ``AUTO_HOLDOUT`` share of (at most ``AUTO_SAMPLE``) points is set aside; each
    candidate is fitted to the rest (one accumulation of the normal equations, then a small
    solve per candidate) and scored by its RMS error on the held-out points. The smallest
    candidate within ``AUTO_SLACK`` of the best score is returned: more terms where the
    shape needs them and the points carry them, fewer where extra terms would only follow
    the noise.

    Parameters
    ----------
    residuals, params, kind
        As in :func:`fit_deformation`.
    candidates : tuple of int
        Increasing ``K`` to try; those with fewer than ``AUTO_POINTS_PER_TERM`` training
        points per unknown are skipped.
    seed : int
        Of the random hold-out split (fixed: the same data give the same choice).
    flat_top : bool
        As in :func:`fit_deformation`.

    Returns
    -------
    int
        ``K``; the smallest candidate when the points are too few to score any.
    """
    r, p = _check_fit_input(residuals, params)
    _check_kind(kind)
    rng = np.random.default_rng(seed)
    pick = rng.permutation(r.shape[0])[: min(r.shape[0], AUTO_SAMPLE)]
    n_test = int(len(pick) * AUTO_HOLDOUT)
    test, train = pick[:n_test], pick[n_test:]
    usable = [int(k) for k in candidates if AUTO_POINTS_PER_TERM * k * k <= len(train)]
    if n_test < 10 or not usable:
        return int(min(candidates))
    top = max(usable)
    r_train, p_train = r[train], p[train]
    scores, swings = [], []
    with _single_threaded_blas():
        data = _accumulate(r_train, p_train, top, top + 1 if flat_top else top, kind)
        for k in usable:
            fit = _solve(r_train, data, k, k, None, flat_top)
            miss = r[test] - fit.evaluate(p[test, 0], p[test, 1])
            scores.append(float(np.sqrt(np.einsum("ij,ij->", miss, miss) / len(test))))
            swings.append(_swing(fit, p_train))
    # Candidates that swing out where no point holds them (a hole in the parameters: a
    # lip's points that project unevenly onto a base off the surface) are not scored by
    # held-out points, which lie where the others are; they go unless all swing.
    calm = [i for i, ratio in enumerate(swings) if ratio <= AUTO_SWING] or [int(np.argmin(swings))]
    best = min(scores[i] for i in calm)
    return next(usable[i] for i in calm if scores[i] <= AUTO_SLACK * best)


def _swing(fit: Deformation, params: NDArray[np.float64]) -> float:
    """A deformation's largest size on a ``SWING_GRID`` grid over the parameter square, over
    its largest at ``params``."""
    g = np.linspace(0.0, 1.0, SWING_GRID)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    grid = np.linalg.norm(fit.evaluate(u, v), axis=1).max()
    at = np.linalg.norm(fit.evaluate(params[:, 0], params[:, 1]), axis=1).max()
    return float(grid / max(float(at), 1e-300))


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
    _check_kind(kind)
    top = int(max_mn) if ridge is not None else min(int(max_mn), int(np.sqrt(r.shape[0])))
    best: Deformation | None = None
    last: Deformation | None = None
    with _single_threaded_blas():
        # One pass gathers the normal equations of every candidate (M, N <= top); each
        # candidate then costs a small solve and one pass for its max error.
        data = _accumulate(r, p, max(top, 1), max(top, 1), kind) if top >= 1 else None
        for k in range(1, top + 1):
            assert data is not None
            last = _solve(r, data, k, k, ridge)
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
                f"tolerance {tolerance:.3g} not reached with M = N <= {max_mn} ({reached}); "
                "raise max_mn, loosen the tolerance, or check the parameterization and "
                "boundaries"
            )
        assert data is not None
        k = best.m
        for m in range(1, k):
            trial = _solve(r, data, m, k, ridge)
            if trial.max_error <= tolerance:
                best = trial
                break
        for n in range(1, k):
            trial = _solve(r, data, best.m, n, ridge)
            if trial.max_error <= tolerance:
                best = trial
                break
    return best
