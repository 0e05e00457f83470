"""pde2cad: measured data to manufacturable CAD.

Binary images become outlines of cubic Béziers (SVG, DXF); point clouds become PDE surface
patches (STEP, IGES). ``import pde2cad`` stays light: heavy libraries (OCP, open3d, ezdxf,
matplotlib) are imported only by the functions that use them.

A labelled cloud to a build123d solid, and to STEP::

    import pde2cad
    rec = pde2cad.reconstruct(points, labels, continuity="c1")  # sewn OCP shape
    solid = rec.to_build123d()          # build123d Solid (closed) or Shell (open)
    rec.write_step("part.step")

Without a CAD kernel (e.g. inside FreeCAD's Python), ``pde2cad.fit_surfaces(points, labels)``
gives the kernel-neutral B-spline surfaces (a :class:`~pde2cad.reconstruct.SurfaceModel`).
"""

from __future__ import annotations

import sys
import types
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Union

from pde2cad.errors import ExportError, FitError, InputError, Pde2CadError

if TYPE_CHECKING:
    from collections.abc import Callable

    import build123d
    import cadquery
    from numpy.typing import ArrayLike

    from pde2cad.reconstruct import Reconstruction, SurfaceModel

__version__ = "0.1.0"

__all__ = [
    "ExportError",
    "FitError",
    "InputError",
    "Pde2CadError",
    "__version__",
    "export_iges",
    "export_step",
    "fit_patch",
    "fit_pde_surface",
    "fit_surfaces",
    "reconstruct",
    "to_build123d",
    "to_cadquery",
    "vectorize",
]


def vectorize(image_or_path, tolerance: float = 1.0, **options):  # noqa: ANN001, ANN201
    """Vectorize a binary image; see :func:`pde2cad.image.vectorize.vectorize`."""
    from pde2cad.image.vectorize import vectorize as _vectorize

    return _vectorize(image_or_path, tolerance=tolerance, **options)


def fit_patch(points, **options):  # noqa: ANN001, ANN201
    """Fit one Coons + PDE-deformation patch to a region's points; see
    :func:`pde2cad.surfaces.patch.fit_patch`."""
    from pde2cad.surfaces.patch import fit_patch as _fit_patch

    return _fit_patch(points, **options)


def fit_pde_surface(points, params=None, **options):  # noqa: ANN001, ANN201
    """Fit a closed-form 4th-order PDE patch (Chapter 4); see
    :func:`pde2cad.surfaces.pde_closed_form.fit_pde_surface`."""
    from pde2cad.surfaces.pde_closed_form import fit_pde_surface as _fit

    return _fit(points, params, **options)


def fit_surfaces(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    m: Union[int, Literal["auto"]] = "auto",
    n: Union[int, Literal["auto"]] = "auto",
    continuity: Literal["c0", "c1"] = "c0",
    tolerance: float | None = None,
    cad_tolerance: float | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> SurfaceModel:
    """Fit kernel-neutral B-spline surfaces to a segmented point cloud (no CAD kernel needed);
    see :func:`pde2cad.reconstruct.fit_surfaces`."""
    from pde2cad.reconstruct import fit_surfaces as _fit_surfaces

    return _fit_surfaces(
        points, labels, m=m, n=n, continuity=continuity, tolerance=tolerance,
        cad_tolerance=cad_tolerance, progress=progress,
    )


def reconstruct(
    points: ArrayLike,
    labels: ArrayLike,
    *,
    m: Union[int, Literal["auto"]] = "auto",
    n: Union[int, Literal["auto"]] = "auto",
    continuity: Literal["c0", "c1"] = "c0",
    tolerance: float | None = None,
    cad_tolerance: float | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> Reconstruction:
    """Reconstruct a segmented point cloud as sewn B-spline patches (an OCP shape; needs
    ``pde2cad[cad]``); see :func:`pde2cad.reconstruct.reconstruct`."""
    from pde2cad.reconstruct import reconstruct as _reconstruct

    return _reconstruct(
        points, labels, m=m, n=n, continuity=continuity, tolerance=tolerance,
        cad_tolerance=cad_tolerance, progress=progress,
    )


def export_step(
    shape: object,
    path: str | Path,
    *,
    schema: str = "AP214",
    units: str = "MM",
    name: str | None = None,
    author: str | None = None,
    organization: str | None = None,
    face_names: Sequence[str] | None = None,
) -> Path:
    """Write a shape to STEP: a ``TopoDS_Shape``, a build123d / CadQuery shape or
    ``Workplane``, a list of shapes, or a :func:`reconstruct` result (faces named after their
    segments). ``name`` (default: the file name), ``author`` and ``organization`` go into the
    header; see :func:`pde2cad.occ.export.export_step`. Needs OCP (``pde2cad[cad]``)."""
    from pde2cad.occ.export import export_step as _export

    return _export(
        shape, path, schema=schema, units=units, name=name, author=author,
        organization=organization, face_names=face_names,
    )


def export_iges(
    shape: object,
    path: str | Path,
    *,
    units: str = "MM",
    name: str | None = None,
    author: str | None = None,
    organization: str | None = None,
    face_names: Sequence[str] | None = None,
) -> Path:
    """Write a shape to IGES 5.3 (BRep solids/shells); takes what :func:`export_step` takes."""
    from pde2cad.occ.export import export_iges as _export

    return _export(
        shape, path, units=units, name=name, author=author, organization=organization,
        face_names=face_names,
    )


def to_build123d(shape: object) -> build123d.Shape:
    """A shape, a list of shapes or a :func:`reconstruct` result as a build123d object
    (``Solid`` for a closed reconstruction, ``Shell`` for an open one)."""
    from pde2cad.occ.shape import to_build123d as _convert

    return _convert(shape)


def to_cadquery(shape: object) -> cadquery.Shape:
    """A shape, a list of shapes or a :func:`reconstruct` result as a CadQuery ``Shape``."""
    from pde2cad.occ.shape import to_cadquery as _convert

    return _convert(shape)


class _CallableModule(types.ModuleType):
    """The submodule :mod:`pde2cad.reconstruct`, callable as its ``reconstruct`` function."""

    def __call__(self, points, labels, **options):  # noqa: ANN001, ANN204
        return self.reconstruct(points, labels, **options)


class _Package(types.ModuleType):
    """The package module: ``pde2cad.reconstruct`` stays callable once its submodule loads.

    ``pde2cad.reconstruct`` names both the lazy function above and the submodule; importing
    the submodule rebinds the package attribute to the module, and
    ``pde2cad.reconstruct(points, labels)`` would then fail depending on import order. The
    module is made callable instead (calling its ``reconstruct``), so the function call, the
    submodule's attributes, ``import pde2cad.reconstruct as m`` and dotted-path patching
    (``mock.patch("pde2cad.reconstruct.reconstruct")``) all keep working.
    """

    def __setattr__(self, name: str, value: object) -> None:
        if name == "reconstruct" and type(value) is types.ModuleType:
            value.__class__ = _CallableModule
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
