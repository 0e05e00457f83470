"""A centred, normalised working frame, and the maps of fitted geometry back to the caller's.

Scans sit far from the origin (plant or survey coordinates, 1e6..1e7) and come in any unit
(1e-6..1e6): fitted in place, both cost digits and meet absolute thresholds inside the fit.
:func:`~pde2cad.reconstruct.fit_surfaces` therefore fits ``(p - centre) / scale`` (the bounding
box centre and diagonal, so the cloud spans a unit diagonal at the origin) and maps the result
back with this module. Points map affinely (``x * scale + centre``), derivative vectors and
lengths by ``scale`` alone, unit normals and parameters not at all.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.bspline.data import BSplineSurface
from pde2cad.errors import InputError
from pde2cad.layout import Layout
from pde2cad.layout.edges import EdgeNetwork
from pde2cad.surfaces.boundary import PiecewiseBezier
from pde2cad.surfaces.coons import BicubicCoons, BilinearCoons, Ribbons
from pde2cad.surfaces.deformation import Deformation
from pde2cad.surfaces.patch import Patch

#: Error keys that are counts, not lengths (not scaled).
_COUNT_KEYS = frozenset({"outside"})


@dataclass(frozen=True)
class Frame:
    """``local = (world - centre) / scale``.

    Attributes
    ----------
    centre : (3,) float
        Centre of the cloud's bounding box.
    scale : float
        The bounding-box diagonal.
    """

    centre: NDArray[np.float64]
    scale: float

    @classmethod
    def of(cls, points: NDArray[np.float64]) -> Frame:
        """The frame that centres ``points`` (N, 3) and gives them a unit diagonal."""
        lo, hi = points.min(axis=0), points.max(axis=0)
        scale = float(np.linalg.norm(hi - lo))
        if not scale > 0 or not np.isfinite(scale):
            raise InputError("the points all coincide (zero extent); a surface needs a spread")
        return cls(centre=0.5 * (lo + hi), scale=scale)

    def to_local(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        return (points - self.centre) / self.scale

    def length_to_local(self, value: float | None) -> float | None:
        return None if value is None else float(value) / self.scale

    def point(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Local points (..., 3) in world coordinates."""
        return x * self.scale + self.centre

    def vector(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Local derivative vectors (..., 3) in world coordinates."""
        return x * self.scale

    def curve(self, c: PiecewiseBezier, *, vector: bool = False) -> PiecewiseBezier:
        """A point curve (or, ``vector=True``, a derivative curve such as a ribbon)."""
        ctrl = self.vector(c.ctrl) if vector else self.point(c.ctrl)
        return dataclasses.replace(c, ctrl=ctrl, breaks=c.breaks)

    def lengths(self, values: dict[Any, float]) -> dict[Any, float]:
        """A dict of lengths (errors) in world units (count entries kept)."""
        return {k: v if k in _COUNT_KEYS else float(v) * self.scale for k, v in values.items()}

    def surface(self, s: BSplineSurface) -> BSplineSurface:
        """B-splines are affinely invariant: map the poles."""
        return dataclasses.replace(s, poles=self.point(np.asarray(s.poles, dtype=float)))

    def network(self, net: EdgeNetwork) -> EdgeNetwork:
        return dataclasses.replace(
            net,
            corners=self.point(net.corners),
            curves={k: self.curve(c) for k, c in net.curves.items()},
            errors=self.lengths(net.errors),
            rms=self.lengths(net.rms),
        )

    def layout(self, lay: Layout) -> Layout:
        """Borders, corners and spacings in world units; the KD-tree (of the working-frame
        points) is dropped."""
        return dataclasses.replace(
            lay,
            borders={k: self.point(b) for k, b in lay.borders.items()},
            corners=self.point(lay.corners),
            open_boundary={k: self.point(b) for k, b in lay.open_boundary.items()},
            spacing=lay.spacing * self.scale, radius=lay.radius * self.scale, tree=None,
        )

    def ribbons(self, r: Ribbons | None) -> Ribbons | None:
        if r is None:
            return None
        vec = self.vector
        return Ribbons(d_bottom=self.curve(r.d_bottom, vector=True),
                       d_right=self.curve(r.d_right, vector=True),
                       d_top=self.curve(r.d_top, vector=True),
                       d_left=self.curve(r.d_left, vector=True), twists=vec(r.twists))

    def base(self, b: BilinearCoons | BicubicCoons) -> BilinearCoons | BicubicCoons:
        """The Coons base rebuilt on mapped sides (and ribbons and twists for C1)."""
        bottom, right, top, left = (self.curve(c) for c in (b.bottom, b.right, b.top, b.left))
        if isinstance(b, BicubicCoons):
            d_bottom, d_right, d_top, d_left = (
                self.curve(c, vector=True) for c in (b.d_bottom, b.d_right, b.d_top, b.d_left)
            )
            return BicubicCoons(bottom, right, top, left, d_bottom, d_right, d_top, d_left,
                                twists=self.vector(b.twists))
        return BilinearCoons(bottom, right, top, left)

    def deformation(self, d: Deformation) -> Deformation:
        return dataclasses.replace(
            d, coefficients=self.vector(d.coefficients), mean_error=d.mean_error * self.scale,
            max_error=d.max_error * self.scale, rms_error=d.rms_error * self.scale,
        )

    def patch(self, p: Patch, points: NDArray[np.float64]) -> FramedPatch:
        """The patch in world coordinates; ``points`` are the caller's own rows of it."""
        return FramedPatch(
            base=self.base(p.base), deformation=self.deformation(p.deformation),
            boundary=p.boundary, sides=tuple(self.curve(c) for c in p.sides),
            continuity=p.continuity, ribbons=self.ribbons(p.ribbons), params=p.params,
            outside=p.outside, points=points, _fit_errors=self.lengths(p.fit_errors),
            local=p, frame=self,
        )


@dataclass(frozen=True, eq=False)
class FramedPatch(Patch):
    """A :class:`~pde2cad.surfaces.patch.Patch` mapped back from the working frame.

    It evaluates in world coordinates like any patch; its :attr:`errors` come from the
    fitted ``local`` patch (projected in the working frame, then scaled), so they do not
    depend on where the cloud sits. ``boundary`` (when set) stays in the working frame.
    """

    local: Patch | None = field(default=None, repr=False)
    frame: Frame | None = field(default=None, repr=False)

    @cached_property
    def errors(self) -> dict[str, float]:
        if self.local is None or self.frame is None:
            return Patch.errors.func(self)  # type: ignore[attr-defined]
        return self.frame.lengths(self.local.errors)


__all__ = ["Frame", "FramedPatch"]
