"""Point clouds inside FreeCAD: a ``Points`` object, a ``Mesh`` object or a cloud file, with
segment labels from a property, a file or an array.

Files are read by :func:`pde2cad.io.clouds.read_cloud` (PLY/XYZ/NPY/text need no open3d);
a mesh file (STL/OBJ/PLY with faces) is read by FreeCAD's Mesh module instead and sampled
here, so open3d is never needed inside FreeCAD.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pde2cad.errors import InputError
from pde2cad.io.clouds import MESH_SUFFIXES, _label_file, as_labels, read_cloud

#: ``Labels`` value that takes labels from the mesh's segments (one label per facet).
MESH_SEGMENTS = "segments"
#: Seed of the area sampling of meshes (a recompute gives the same points).
SEED = 0


def is_points(obj: Any) -> bool:
    return hasattr(obj, "isDerivedFrom") and obj.isDerivedFrom("Points::Feature")


def is_mesh(obj: Any) -> bool:
    return hasattr(obj, "isDerivedFrom") and obj.isDerivedFrom("Mesh::Feature")


def _mesh_arrays(mesh: Any) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    vertices, facets = mesh.Topology
    return (np.array([[p.x, p.y, p.z] for p in vertices], dtype=float),
            np.array(facets, dtype=np.int64).reshape(-1, 3))


def _facet_segments(mesh: Any, n_facets: int) -> NDArray[np.int64]:
    """The segment index of each facet (``Mesh.getSegment``); facets in none get -1."""
    labels = np.full(n_facets, -1, dtype=np.int64)
    for k in range(mesh.countSegments()):
        labels[np.asarray(mesh.getSegment(k), dtype=np.int64)] = k
    return labels


def sample_mesh(
    mesh: Any, count: int, with_segments: bool
) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """``count`` points uniformly by area on a ``Mesh.Mesh`` (seeded), with their facets'
    segment labels when ``with_segments``.

    1. Facets drawn with probability proportional to their area.
    2. A uniform barycentric point in each drawn facet.
    """
    verts, facets = _mesh_arrays(mesh)
    if len(facets) == 0:
        raise InputError("the mesh has no facets to sample")
    tri = verts[facets]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    rng = np.random.default_rng(SEED)
    pick = rng.choice(len(facets), size=int(count), p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(int(count))), rng.random(int(count))
    t = tri[pick]
    pts = (1 - r1)[:, None] * t[:, 0] + (r1 * (1 - r2))[:, None] * t[:, 1] + (r1 * r2)[:, None] * t[:, 2]
    if not with_segments:
        return pts, None
    seg = _facet_segments(mesh, len(facets))[pick]
    if (seg < 0).any():
        raise InputError(
            f"{int((seg < 0).sum())} sampled points lie on facets in no mesh segment; "
            "segment the whole mesh (Mesh > Segmentation) or give a label file"
        )
    return pts, seg


def object_points(obj: Any, samples: int, labels: str) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """Points of a Points object (its points) or a Mesh object (its vertices, or ``samples``
    area samples when ``samples > 0``), and labels when ``labels`` is ``"segments"``."""
    if is_points(obj):
        pts = np.array([[p.x, p.y, p.z] for p in obj.Points.Points], dtype=float)
        return pts.reshape(-1, 3), None
    if is_mesh(obj):
        if samples > 0 or labels == MESH_SEGMENTS:
            return sample_mesh(obj.Mesh, samples if samples > 0 else 20000, labels == MESH_SEGMENTS)
        return _mesh_arrays(obj.Mesh)[0], None
    kind = getattr(obj, "TypeId", type(obj).__name__)
    raise InputError(f"{getattr(obj, 'Label', obj)} is a {kind}; select a Points or Mesh object")


def _property_labels(obj: Any, name: str, count: int) -> NDArray[np.int64]:
    if obj is None or name not in obj.PropertiesList:
        where = getattr(obj, "Label", "the source")
        raise InputError(
            f"{where} has no property {name!r} with segment labels; add one (an integer list, "
            "one label per point) or give a label file"
        )
    return as_labels(np.asarray(getattr(obj, name), dtype=float), count, f"property {name}")


def mesh_file_points(path: Path, samples: int) -> NDArray[np.float64]:
    """Area samples of a mesh file read with FreeCAD's Mesh module (no open3d)."""
    import Mesh

    try:
        mesh = Mesh.Mesh(str(path))
    except Exception as exc:  # noqa: BLE001 - Mesh raises Base.FreeCADError
        raise InputError(f"FreeCAD cannot read the mesh {path}: {exc}") from exc
    return sample_mesh(mesh, samples if samples > 0 else 20000, False)[0]


def file_points(path: str, labels: str) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """Points (and labels from a PLY property or ``"column4"``) of a cloud file."""
    file = Path(path)
    if file.suffix.lower() in MESH_SUFFIXES:
        return mesh_file_points(file, 0), None
    return read_cloud(file, labels=labels or None)


def read_source(feature: Any) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The labelled cloud a surface feature's properties describe.

    1. Points: the linked ``Source`` object, else ``SourceFile``.
    2. Labels, first found: ``LabelValues`` (an array the API stored), ``LabelsFile``,
       ``Labels`` (a property of the source object, a PLY vertex property, ``"column4"``,
       or ``"segments"`` of a mesh).

    Raises
    ------
    InputError
        No source, wrong object type, unreadable file, or no labels.
    """
    name = feature.Labels.strip()
    if feature.Source is not None:
        own = name if name == MESH_SEGMENTS else ""
        pts, lab = object_points(feature.Source, int(feature.SamplePoints), own)
    elif feature.SourceFile:
        prop = "" if feature.LabelValues or feature.LabelsFile else name
        pts, lab = file_points(feature.SourceFile, prop)
    else:
        raise InputError("no point source: link a Points or Mesh object or set SourceFile")
    if feature.LabelValues:
        lab = as_labels(np.asarray(feature.LabelValues), len(pts), "LabelValues")
    elif feature.LabelsFile:
        # The label-file reader of read_cloud (one number per point, .npy or text).
        lab = as_labels(_label_file(Path(feature.LabelsFile)), len(pts), feature.LabelsFile)
    elif lab is None and name and feature.Source is not None:
        lab = _property_labels(feature.Source, name, len(pts))
    if lab is None:
        raise InputError(
            "the cloud has no segment labels: set Labels (a property name), LabelsFile, "
            "or pass labels= to api.make_surface"
        )
    return pts, lab
