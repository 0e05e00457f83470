"""Reading point clouds (and meshes sampled to clouds) with optional per-point segment labels.

Supported inputs of :func:`read_cloud`:

* ``.ply`` and ``.pcd`` point clouds (read by open3d). A ``.ply`` whose header declares
  faces is a mesh and is sampled like ``.stl``/``.obj``.
* ``.xyz``, ``.pts``, ``.txt``, ``.csv``: text, one point per line, the first three columns are
  x, y, z (whitespace or comma separated). Leading lines that do not start with three numbers
  (a header, or the point count PTS files begin with) are skipped.
* ``.npy``: an ``(N, 3)`` array, or ``(N, >= 4)`` whose 4th column is the label when
  ``labels="column4"`` (further columns are ignored).
* ``.stl``, ``.obj`` (and ``.ply`` with faces): triangle meshes, sampled uniformly by area
  with ``sample_points`` points (open3d ``sample_points_uniformly``).

Labels come from a PLY vertex property (open3d drops non-standard properties, so the PLY
header and vertex block are parsed here, for ``ascii`` and both binary byte orders), from
the 4th column of a text or ``.npy`` file, or from a separate ``.npy``/``.txt`` file with one
integer per point. Float labels (CloudCompare writes ``scalar_Label`` as float) are accepted
when every value is integral.

open3d is imported inside the functions that need it, so importing this module is cheap.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pde2cad.errors import InputError

#: Extensions read as text (first three columns x, y, z).
TEXT_SUFFIXES = (".xyz", ".pts", ".txt", ".csv")
#: Extensions read as triangle meshes and sampled.
MESH_SUFFIXES = (".off", ".stl", ".obj")
#: Extensions of separate label files.
LABEL_FILE_SUFFIXES = (".npy", ".txt", ".csv", ".labels")

#: PLY scalar type names -> numpy dtype characters (both the old and the sized spellings).
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
#: Binary PLY formats -> numpy byte-order characters.
_PLY_BYTE_ORDER = {"binary_little_endian": "<", "binary_big_endian": ">"}


def check_cloud_suffix(path: str | Path) -> str:
    """The lower-case suffix of ``path`` when it is a readable cloud/mesh format.

    Raises
    ------
    InputError
        For any other suffix (e.g. ``.las``), naming the formats that are read.
    """
    suffix = Path(path).suffix.lower()
    known = (".ply", ".pcd", ".npy") + TEXT_SUFFIXES + MESH_SUFFIXES
    if suffix not in known:
        names = "/".join(dict.fromkeys(k.lstrip(".").upper() for k in known))
        raise InputError(
            f"unknown point cloud format {suffix or '(no suffix)'!r} of {path}; use {names} "
            "(convert other formats, e.g. LAS/E57, with CloudCompare or PDAL)"
        )
    return suffix


# --------------------------------------------------------------------------- PLY header
def _ply_header(path: Path) -> tuple[str, list[tuple[str, int, list[tuple[str, str]]]], int]:
    """Parse a PLY header.

    Returns
    -------
    format : str
        ``"ascii"``, ``"binary_little_endian"`` or ``"binary_big_endian"``.
    elements : list of (name, count, properties)
        In file order; ``properties`` is a list of ``(name, type)``, where ``type`` is a PLY
        scalar type or ``"list"`` for list properties.
    offset : int
        Byte offset of the data after ``end_header``.
    """
    with open(path, "rb") as handle:
        head = handle.read(1 << 16)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise InputError(
            f"{path} is not a PLY file (no 'ply' magic or 'end_header'); check the file"
        )
    newline = head.find(b"\n", end)
    offset = (newline + 1) if newline >= 0 else len(head)
    fmt = ""
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for number, raw in enumerate(head[:end].decode("ascii", errors="replace").splitlines(), 1):
        words = raw.split()
        if not words:
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
        elif words[0] == "element" and len(words) >= 3:
            if not words[2].isdigit():
                raise InputError(
                    f"{path}: PLY header line {number} {raw.strip()!r} needs a whole, "
                    "non-negative element count; fix or re-export the file"
                )
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if words[1] == "list":
                elements[-1][2].append((words[-1], "list"))
            elif len(words) >= 3:
                elements[-1][2].append((words[2], words[1]))
    return fmt, elements, offset


def _ply_has_faces(path: Path) -> bool:
    """Whether a PLY file declares at least one face (then it is a mesh)."""
    _, elements, _ = _ply_header(path)
    return any(name == "face" and count > 0 for name, count, _ in elements)


def read_ply_property(path: str | Path, name: str) -> NDArray[np.float64]:
    """One scalar vertex property of a PLY file, e.g. ``scalar_Label`` written by CloudCompare.

    See :func:`read_ply_properties`; returns the ``(N,)`` float64 column of ``name``.
    """
    return read_ply_properties(path, (name,))[:, 0]


def read_ply_properties(path: str | Path, names: tuple[str, ...]) -> NDArray[np.float64]:
    """Scalar vertex properties of a PLY file (open3d drops all but the standard ones).

    Parameters
    ----------
    path : str or Path
        An ``ascii``, ``binary_little_endian`` or ``binary_big_endian`` PLY file.
    names : tuple of str
        Vertex property names (exact, case-sensitive).

    Returns
    -------
    (N, len(names)) float
        The properties of every vertex, in vertex order (float64 holds every PLY scalar type
        exactly).

    Raises
    ------
    InputError
        If the file has no vertex element, no such property (the message lists the ones it
        has), an unsupported format, or is truncated.
    """
    path = Path(path)
    fmt, elements, offset = _ply_header(path)
    element_names = [e[0] for e in elements]
    if "vertex" not in element_names:
        raise InputError(f"{path} has no 'vertex' element; it is not a PLY point cloud")
    v = element_names.index("vertex")
    _, count, props = elements[v]
    prop_names = [p[0] for p in props]
    for name in names:
        if name not in prop_names:
            raise InputError(
                f"{path} has no vertex property {name!r}; it has {prop_names}. Pass one of "
                "those as labels=, or a .npy/.txt label file"
            )
    if any(t == "list" for _, t in props):
        raise InputError(f"{path}: list properties in the vertex element are not supported")
    bad = [t for _, t in props if t not in _PLY_TYPES]
    if bad:
        raise InputError(f"{path}: unknown PLY property type(s) {bad}")
    columns = tuple(prop_names.index(name) for name in names)
    if fmt == "ascii":
        # Elements before the vertex block take one line per item (lists included).
        skip = sum(e[1] for e in elements[:v])
        try:
            data = np.loadtxt(
                path, usecols=columns, max_rows=count, ndmin=2,
                dtype=np.float64, skiprows=_ascii_skip(path, offset, skip),
            )  # fmt: skip
        except ValueError as exc:
            raise InputError(f"{path}: cannot read vertex properties {names}: {exc}") from exc
    elif fmt in _PLY_BYTE_ORDER:
        order = _PLY_BYTE_ORDER[fmt]
        if any(any(t == "list" for _, t in e[2]) for e in elements[:v]):
            raise InputError(f"{path}: a list element before 'vertex' is not supported")
        for e in elements[:v]:
            offset += e[1] * int(np.dtype([(p, order + _PLY_TYPES[t]) for p, t in e[2]]).itemsize)
        dtype = np.dtype([(p, order + _PLY_TYPES[t]) for p, t in props])
        raw = np.fromfile(path, dtype=np.uint8, offset=offset)
        if raw.size < count * dtype.itemsize:
            raise InputError(
                f"{path} is truncated: {count} vertices need {count * dtype.itemsize} bytes, "
                f"the file has {raw.size}"
            )
        rec = np.frombuffer(raw[: count * dtype.itemsize].tobytes(), dtype=dtype)
        data = np.stack([rec[name].astype(np.float64) for name in names], axis=1)
    else:
        raise InputError(
            f"{path}: PLY format {fmt!r} is not supported for vertex properties; save it as "
            "ascii, binary_little_endian or binary_big_endian"
        )
    if len(data) != count:
        raise InputError(f"{path} is truncated: {count} vertices declared, {len(data)} read")
    return np.asarray(data, dtype=np.float64).reshape(count, len(names))


def _ascii_skip(path: Path, offset: int, skip: int) -> int:
    """``skiprows`` for :func:`numpy.loadtxt` that jumps the header and ``skip`` data lines."""
    with open(path, "rb") as handle:
        header_lines = handle.read(offset).count(b"\n")
    return header_lines + skip


# --------------------------------------------------------------------------- text / npy
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf)"
_ROW = re.compile(rf"^\s*(?:{_NUMBER})(?:[\s,;]+(?:{_NUMBER})){{2,}}", re.IGNORECASE)


def _read_text(path: Path, columns: int) -> NDArray[np.float64]:
    """The first ``columns`` columns of a text point file, skipping non-numeric header lines."""
    skip = 0
    delimiter: str | None = None
    found = False
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if _ROW.match(line):
                delimiter = "," if "," in line else (";" if ";" in line else None)
                found = True
                break
            skip += 1
            if skip > 1000:
                break
    if not found:
        raise InputError(
            f"{path} has no line starting with three numbers (x y z) in its first 1000 lines; "
            "check the file"
        )
    try:
        data = np.loadtxt(
            path, skiprows=skip, usecols=tuple(range(columns)), delimiter=delimiter,
            comments="#", ndmin=2, dtype=np.float64,
        )  # fmt: skip
    except (ValueError, IndexError) as exc:
        raise InputError(
            f"cannot read {path} as a point list (x y z per line"
            f"{', label 4th' if columns > 3 else ''}): {exc}"
        ) from exc
    return data


# --------------------------------------------------------------------------- labels
def first_of_repeats(points: NDArray[np.float64]) -> NDArray[np.int64] | None:
    """Indices (ascending) of the first of each set of exactly repeated points, or None when
    no point repeats. Scans and meshes read as points repeat samples; a cloud whose every
    point is repeated has no nearest-neighbour spacing."""
    order = np.lexsort(points.T[::-1])
    same = np.all(points[order[1:]] == points[order[:-1]], axis=1)
    if not same.any():
        return None
    return np.sort(order[np.r_[True, ~same]])


def as_labels(values: ArrayLike, count: int, source: str) -> NDArray[np.int64]:
    """Validate per-point labels and cast them to int64.

    Parameters
    ----------
    values : (N,) array_like
        Integer labels, or floats that are all integral (CloudCompare writes floats).
    count : int
        The number of points the labels must match.
    source : str
        Where the labels came from, for the error messages.

    Raises
    ------
    InputError
        On a length mismatch (naming both counts), NaN/inf, or non-integral values.
    """
    lab = np.asarray(values)
    if lab.ndim == 2 and 1 in lab.shape:
        lab = lab.reshape(-1)
    if lab.ndim != 1:
        raise InputError(f"labels from {source} must be one value per point, got shape {lab.shape}")
    if len(lab) != count:
        raise InputError(
            f"labels from {source} have {len(lab)} values but the cloud has {count} points; "
            "they must match one to one"
        )
    if lab.dtype.kind in "iub":
        return lab.astype(np.int64)
    if lab.dtype.kind != "f":
        raise InputError(f"labels from {source} must be numbers, got dtype {lab.dtype}")
    bad = ~np.isfinite(lab)
    if bad.any():
        raise InputError(
            f"labels from {source} contain {int(bad.sum())} NaN/inf values (first at point "
            f"{int(np.flatnonzero(bad)[0])}); every point needs a segment label"
        )
    rounded = np.rint(lab)
    off = np.flatnonzero(np.abs(lab - rounded) > 1e-6 * np.maximum(1.0, np.abs(lab)))
    if off.size:
        raise InputError(
            f"labels from {source} must be integers; point {int(off[0])} has "
            f"{float(lab[off[0]]):g} ({off.size} non-integral values)"
        )
    return rounded.astype(np.int64)


def _label_file(path: Path) -> NDArray[np.float64]:
    """Labels from a separate ``.npy`` or text file (one number per point)."""
    if not path.is_file():
        raise InputError(f"label file {path} does not exist; check the path")
    try:
        if path.suffix.lower() == ".npy":
            return np.load(path, allow_pickle=False)
        return np.loadtxt(path, ndmin=1, comments="#", dtype=np.float64)
    except (ValueError, OSError) as exc:
        raise InputError(f"cannot read label file {path}: {exc}") from exc


# --------------------------------------------------------------------------- main reader
def _check_points(points: NDArray[np.float64], path: Path) -> NDArray[np.float64]:
    if points.ndim != 2 or points.shape[1] < 3:
        raise InputError(f"{path} must hold (N, 3) coordinates, got shape {points.shape}")
    points = np.ascontiguousarray(points[:, :3], dtype=np.float64)
    if len(points) == 0:
        raise InputError(f"{path} holds no points (empty or unreadable); check the file")
    bad = int((~np.isfinite(points)).any(axis=1).sum())
    if bad:
        raise InputError(
            f"{path} has NaN or inf coordinates in {bad} of {len(points)} rows; remove those "
            "rows first"
        )
    return points


def _sample_mesh(path: Path, sample_points: int) -> NDArray[np.float64]:
    import open3d as o3d

    # open3d 0.20's stubs say os.PathLike, but its binding (and open3d 0.18's) takes str.
    mesh = o3d.io.read_triangle_mesh(str(path))  # type: ignore[arg-type]
    if len(mesh.triangles) == 0:
        raise InputError(f"{path} holds no triangles (empty or unreadable mesh); check the file")
    if sample_points < 1:
        raise InputError(f"sample_points must be >= 1, got {sample_points}")
    pcd = mesh.sample_points_uniformly(number_of_points=int(sample_points))
    return np.asarray(pcd.points, dtype=np.float64)


def read_cloud(
    path: str | Path,
    *,
    labels: str | Path | None = None,
    sample_points: int = 200_000,
) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """Read a point cloud (or sample a mesh) and optionally its per-point segment labels.

    Parameters
    ----------
    path : str or Path
        ``.ply``, ``.pcd``, ``.xyz``, ``.pts``, ``.txt``, ``.csv``, ``.npy``, ``.stl``, ``.obj``
        (see the module docstring for each format).
    labels : str or Path, optional
        ``None``: no labels. ``"column4"``: the 4th column of a ``.npy`` or text file. A
        :class:`~pathlib.Path` or a string ending in ``.npy``/``.txt``/``.csv``/``.labels``: a
        separate file with one integer per point. Any other string: the name of a PLY vertex
        property (e.g. ``"scalar_Label"``, ``"label"``).
    sample_points : int
        Points sampled from a mesh input (uniformly by area). Ignored for point clouds.

    Returns
    -------
    points : (N, 3) float64
    labels : (N,) int64 or None

    Raises
    ------
    InputError
        Missing file, unknown extension, empty or unreadable file, NaN/inf coordinates
        (with the number of rows), labels that do not match the points one to one, NaN or
        non-integral labels, or labels requested from a mesh (sampled points have no labels).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"point cloud file {path} does not exist; check the path")
    suffix = check_cloud_suffix(path)
    label_kind = _label_kind(labels)
    if label_kind == "column4" and suffix not in (".npy",) + TEXT_SUFFIXES:
        raise InputError(
            f'labels="column4" needs a .npy or text file, not {suffix}; for PLY pass the '
            "vertex property name, otherwise a label file"
        )

    raw_labels: ArrayLike | None = None
    is_mesh = suffix in MESH_SUFFIXES or (suffix == ".ply" and _ply_has_faces(path))
    if is_mesh:
        if labels is not None:
            raise InputError(
                f"{path} is a mesh, sampled to new points that carry no labels; pass a labelled "
                "point cloud instead"
            )
        points = _sample_mesh(path, sample_points)
    elif suffix == ".ply" and _ply_header(path)[0] in ("ascii", *_PLY_BYTE_ORDER):
        # Parsed here, not by open3d: open3d returns garbage (not an error) for some
        # unreadable files, and this parser needs the header anyway for the labels.
        points = read_ply_properties(path, ("x", "y", "z"))
        if label_kind == "property":
            raw_labels = read_ply_property(path, str(labels))
    elif suffix in (".ply", ".pcd"):
        import open3d as o3d

        # open3d 0.20's stubs say os.PathLike, but its binding (and open3d 0.18's) takes str.
        cloud = o3d.io.read_point_cloud(str(path))  # type: ignore[arg-type]
        points = np.asarray(cloud.points, dtype=np.float64)
        if label_kind == "property":
            if suffix != ".ply":
                raise InputError(
                    f"labels={labels!r} names a PLY vertex property but {path} is {suffix}; "
                    "pass a label file instead"
                )
            raw_labels = read_ply_property(path, str(labels))
    elif suffix == ".npy":
        try:
            data = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise InputError(f"cannot read {path} as a numpy array: {exc}") from exc
        data = np.asarray(data)
        if data.ndim != 2 or data.shape[1] < 3:
            raise InputError(f"{path} must hold an (N, 3) or (N, >=4) array, got {data.shape}")
        if label_kind == "column4":
            if data.shape[1] < 4:
                raise InputError(f'labels="column4" but {path} has only {data.shape[1]} columns')
            raw_labels = data[:, 3]
        points = data[:, :3].astype(np.float64)
    else:
        data = _read_text(path, 4 if label_kind == "column4" else 3)
        if label_kind == "column4":
            raw_labels = data[:, 3]
        points = data[:, :3]

    points = _check_points(points, path)
    if label_kind == "property" and suffix != ".ply":
        raise InputError(
            f"labels={labels!r} names a PLY vertex property but {path} is {suffix}; pass "
            '"column4" or a label file'
        )
    if label_kind == "file":
        raw_labels = _label_file(Path(labels))  # type: ignore[arg-type]
    if raw_labels is None:
        return points, None
    return points, as_labels(raw_labels, len(points), f"{labels}")


def _label_kind(labels: str | Path | None) -> str | None:
    """``None``, ``"column4"``, ``"file"`` or ``"property"``."""
    if labels is None:
        return None
    if isinstance(labels, Path) or str(labels).lower().endswith(LABEL_FILE_SUFFIXES):
        return "file"
    if not isinstance(labels, str) or not labels:
        raise InputError(
            "labels must be None, 'column4', a file path or a PLY property name, "
            f"got {labels!r}"
        )
    return "column4" if labels == "column4" else "property"


# --------------------------------------------------------------------------- preprocessing
def preprocess(
    points: ArrayLike,
    labels: ArrayLike | None = None,
    *,
    outlier_nb: int | None = 20,
    outlier_std: float = 2.0,
    voxel: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """Remove statistical outliers and optionally voxel-downsample, keeping labels.

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int, optional
    outlier_nb : int or None
        Neighbours of open3d's statistical outlier removal (a point is dropped when its mean
        distance to them exceeds the global mean by ``outlier_std`` standard deviations).
        ``None`` or 0 skips it.
    outlier_std : float
    voxel : float, optional
        Voxel edge length. Every occupied voxel becomes one point.

    Returns
    -------
    points : (M, 3) float64
    labels : (M,) int64 or None

    Notes
    -----
    Voxel downsampling is done here with numpy, not open3d, so labels survive: each voxel takes
    the label held by most of its points (ties go to the smallest label) and its point is the
    centroid of the points *with that label* only. Averaging across a segment border would put
    a point of one label on the other side of the border.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise InputError(f"points must have shape (N, 3) with N >= 1, got {pts.shape}")
    bad = int((~np.isfinite(pts)).any(axis=1).sum())
    if bad:
        raise InputError(f"points contain NaN or inf in {bad} rows; remove those rows first")
    lab = None if labels is None else as_labels(labels, len(pts), "the labels argument")
    if outlier_nb:
        if outlier_std <= 0:
            raise InputError(f"outlier_std must be > 0, got {outlier_std}")
        import open3d as o3d

        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        _, kept = pcd.remove_statistical_outlier(
            nb_neighbors=int(outlier_nb), std_ratio=float(outlier_std)
        )
        keep = np.asarray(kept, dtype=np.int64)
        pts = pts[keep]
        lab = None if lab is None else lab[keep]
    if voxel is not None:
        if not voxel > 0:
            raise InputError(f"voxel must be a positive length, got {voxel}")
        pts, lab = _voxel_down(pts, lab, float(voxel))
    return pts, lab


def _voxel_down(
    pts: NDArray[np.float64], lab: NDArray[np.int64] | None, voxel: float
) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """Voxel downsampling with a majority label per voxel (see :func:`preprocess`)."""
    keys = np.floor((pts - pts.min(axis=0)) / voxel).astype(np.int64)
    _, cell = np.unique(keys, axis=0, return_inverse=True)
    cell = cell.reshape(-1)
    if lab is None:
        group = cell
    else:
        # Groups are (voxel, label) pairs; per voxel keep the most populated group.
        _, group = np.unique(np.stack([cell, lab], axis=1), axis=0, return_inverse=True)
        group = group.reshape(-1)
    n_group = int(group.max()) + 1
    counts = np.bincount(group, minlength=n_group)
    sums = np.stack([np.bincount(group, pts[:, d], minlength=n_group) for d in range(3)], axis=1)
    first = np.full(n_group, len(pts), dtype=np.int64)
    np.minimum.at(first, group, np.arange(len(pts)))
    g_cell = cell[first]
    if lab is None:
        return sums / counts[:, None], None
    g_lab = lab[first]
    # Sort groups by voxel, then count descending, then label ascending: first per voxel wins.
    order = np.lexsort((g_lab, -counts, g_cell))
    winner = order[np.r_[True, np.diff(g_cell[order]) != 0]]
    return sums[winner] / counts[winner, None], g_lab[winner].astype(np.int64)
