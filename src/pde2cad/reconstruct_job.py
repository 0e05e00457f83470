"""The whole ``reconstruct`` job as one library call: labelled cloud file -> STEP (+ IGES,
report, preview), checked on the written file.

The command line (``pde2cad reconstruct``), scripts and the FreeCAD workbench call the same
:func:`run_reconstruct`; the CLI only parses arguments and prints.

1. :func:`check_outputs`: suffixes, folders, and no output equal to an input or to another
   output -- before any work.
2. :func:`read_labelled`: points and labels from the cloud file (and a label file).
3. :func:`pde2cad.reconstruct.reconstruct`.
4. Every output is written to a staging file beside its target (:class:`Staging`); the STEP
   is read back and measured for the report (:func:`pde2cad.report.build_report`).
5. All outputs are renamed into place together, or none are.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Union

import numpy as np
from numpy.typing import NDArray

from pde2cad.errors import ExportError, InputError, Pde2CadError
from pde2cad.io.staging import OutputSet

#: Output suffixes per option (checked before any work is done).
OUTPUT_SUFFIXES = {
    "output": (".step", ".stp"),
    "iges": (".igs", ".iges"),
    "report": (".json",),
    "preview": (".png", ".svg", ".pdf"),
    "labels_out": (".npy", ".txt"),
}
#: How each output option is spelled on the command line, for the messages.
OUTPUT_FLAGS = {"output": "-o", "iges": "--iges", "report": "--report", "preview": "--preview",
                "labels_out": "--labels-out"}
#: PLY vertex properties tried, in order, when no label source is given.
LABEL_PROPERTIES = (
    "label", "labels", "scalar_label", "scalar_Label", "scalar_labels", "scalar_Labels",
    "segment", "segment_id", "scalar_segment", "scalar_Segment", "class", "scalar_class",
)  # fmt: skip

Progress = Callable[[str, int, int], None]
Message = Callable[[str], None]


@dataclass
class ReconstructJob:
    """What to reconstruct and where to write it (the ``pde2cad reconstruct`` options).

    Attributes
    ----------
    cloud : path
        Point cloud file (``.ply``, ``.pcd``, ``.xyz``, ``.pts``, ``.txt``, ``.csv``, ``.npy``).
    output : path
        STEP file to write.
    labels : str, optional
        A PLY vertex property name, ``"column4"`` or a label file; default: a PLY label
        property found by name (:data:`LABEL_PROPERTIES`).
    continuity, terms, tolerance, cad_tolerance
        Passed to :func:`pde2cad.reconstruct.reconstruct` (``terms`` as ``m = n``).
    units, schema : str
        Length unit declared in the files; STEP application protocol.
    iges, report, preview : path, optional
        Further outputs: IGES, the JSON report, a picture of the patches.
    outliers : bool
        Remove statistical outliers first (20 neighbours, 2 standard deviations).
    voxel : float, optional
        Voxel-downsample to one point per cube of this size first.
    freecad_check : bool
        Also read the STEP with FreeCAD (its own process) for the report.
    name, author, organization : str, optional
        Product name and header fields of the STEP/IGES files (writer defaults when None).
    layout : {"labels", "auto"}, optional
        Where the patches come from: the labels, or an automatic layout of a mesh or an
        unlabelled cloud (:func:`pde2cad.io.meshes.reconstruct_auto`). Default: ``"auto"``
        for meshes and clouds that carry no labels, else ``"labels"``.
    crease_angle, patches, patch_size : optional
        Automatic layout: crease dihedral angle (degrees), about how many patches, or about
        what patch side length.
    labels_out : path, optional
        Automatic layout: write its labels (``.npy``/``.txt``) to edit and rerun.
    """

    cloud: str | Path
    output: str | Path
    labels: str | None = None
    continuity: Literal["c0", "c1"] = "c0"
    terms: Union[int, Literal["auto"]] = "auto"
    tolerance: float | None = None
    cad_tolerance: float | None = None
    units: str = "MM"
    schema: str = "AP214"
    iges: str | Path | None = None
    report: str | Path | None = None
    preview: str | Path | None = None
    outliers: bool = False
    voxel: float | None = None
    freecad_check: bool = False
    name: str | None = None
    author: str | None = None
    organization: str | None = None
    layout: Literal["labels", "auto"] | None = None
    crease_angle: float = 30.0
    patches: int | None = None
    patch_size: float | None = None
    labels_out: str | Path | None = None

    @classmethod
    def from_options(cls, options: Any) -> ReconstructJob:
        """The job from any object with these attributes (e.g. an ``argparse.Namespace``)."""
        return cls(**{f.name: getattr(options, f.name) for f in dataclasses.fields(cls)
                      if hasattr(options, f.name)})


@dataclass
class JobResult:
    """What :func:`run_reconstruct` made.

    Attributes
    ----------
    reconstruction : Reconstruction
    report : dict
        The report (as written to ``--report``), measured on the written STEP.
    outputs : dict[str, Path]
        Written files by option (``"output"``, ``"iges"``, ``"report"``, ``"preview"``).
    timings : dict[str, float]
        Seconds per job stage (read, reconstruct, write, check, ..., total).
    """

    reconstruction: Any
    report: dict[str, Any]
    outputs: dict[str, Path]
    timings: dict[str, float] = field(default_factory=dict)


# --------------------------------------------------------------------------- 1. paths
def _same_file(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def input_paths(job: ReconstructJob) -> list[Path]:
    """The files the job reads: the cloud, and the label file when labels come from one."""
    paths = [Path(job.cloud)]
    if job.labels is not None and job.labels != "column4" and Path(job.labels).suffix:
        paths.append(Path(job.labels))
    return paths


def check_outputs(job: ReconstructJob) -> dict[str, Path]:
    """Requested outputs by option, checked before any work.

    1. Each output's suffix fits its option.
    2. No output is a folder, an input (the cloud, a label file) or another output (also
       through symbolic or hard links).
    3. Each output's folder exists and is writable.

    Raises
    ------
    InputError
        A wrong suffix or a path clash (the CLI exits 2).
    ExportError
        A missing or read-only folder (the CLI exits 3).
    """
    outputs = {key: Path(getattr(job, key)) for key in OUTPUT_SUFFIXES if getattr(job, key)}
    for key, path in outputs.items():
        allowed = OUTPUT_SUFFIXES[key]
        if path.suffix.lower() not in allowed:
            raise InputError(f"{OUTPUT_FLAGS[key]} {path} must end in {' or '.join(allowed)}")
    for key, path in outputs.items():
        for source in input_paths(job):
            if _same_file(path, source):
                raise InputError(f"{OUTPUT_FLAGS[key]} {path} would overwrite the input "
                                 f"{source}; pick another name")
    keys = list(outputs)
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            if _same_file(outputs[a], outputs[b]):
                raise InputError(f"{OUTPUT_FLAGS[a]} and {OUTPUT_FLAGS[b]} name the same file "
                                 f"{outputs[a]}; give each output its own name")
    for key, path in outputs.items():
        if path.is_dir():
            raise InputError(f"{OUTPUT_FLAGS[key]} {path} is a folder; name a file in it")
    for path in outputs.values():
        parent = path.parent if str(path.parent) else Path(".")
        if not parent.is_dir():
            raise ExportError(f"cannot write {path}: folder {parent} does not exist; create it first")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise ExportError(f"cannot write {path}: folder {parent} is not writable; pick another")
    return outputs


# --------------------------------------------------------------------------- 2. input
def label_property(path: Path) -> str:
    """The label property of a PLY cloud when no label source is given."""
    from pde2cad.io.clouds import _ply_header

    _, elements, _ = _ply_header(path)
    props = [name for e in elements if e[0] == "vertex" for name, kind in e[2] if kind != "list"]
    for name in LABEL_PROPERTIES:
        if name in props:
            return name
    for name in props:
        if "label" in name.lower() or "segment" in name.lower():
            return name
    scalars = [name for name in props if name.startswith("scalar_")]
    if len(scalars) == 1:  # CloudCompare names every scalar field scalar_<name>
        return scalars[0]
    raise InputError(
        f"{path} has no label property (vertex properties: {', '.join(props) or 'none'}); "
        "name it with --labels NAME or pass a label file with --labels FILE.npy"
    )


def read_labelled(job: ReconstructJob) -> tuple[NDArray[np.float64], NDArray[np.int64], str]:
    """Points, labels and where the labels came from."""
    from pde2cad.io.clouds import check_cloud_suffix, read_cloud

    path = Path(job.cloud)
    if not path.is_file():
        raise InputError(f"point cloud file {path} does not exist; check the path")
    if path.stat().st_size == 0:
        raise InputError(f"point cloud file {path} is empty; check the file")
    check_cloud_suffix(path)  # "unknown format" before any "no labels" advice
    source = job.labels
    if source is None:
        if path.suffix.lower() != ".ply":
            raise InputError(
                f"{path} carries no labels by itself: pass --labels column4 (the 4th column of "
                "a .npy or text cloud) or --labels FILE (a .npy/.txt file, one label per point)"
            )
        source = label_property(path)
    points, labels = read_cloud(path, labels=source)
    if labels is None:  # read_cloud returns labels whenever a source is named
        raise InputError(f"no labels could be read from {source}; check --labels")
    return points, labels, str(source)


# --------------------------------------------------------------------------- 4-5. staging
#: The job's outputs are staged by the project's all-or-nothing output set (temporary files
#: with short names, backups that put earlier results back on a failed commit, SIGTERM/SIGINT
#: clean-up, stale temporaries of killed runs removed).
Staging = OutputSet


# --------------------------------------------------------------------------- 3. the fit
def reconstruct_kwargs(reconstruct: Callable[..., Any], job: ReconstructJob,
                       progress: Progress | None) -> dict[str, Any]:
    """Keyword arguments for ``reconstruct``: options left at their default are not passed,
    so the job works with versions of ``reconstruct`` that lack them."""
    import inspect

    params = inspect.signature(reconstruct).parameters
    takes_all = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())

    def accepts(name: str) -> bool:
        return takes_all or name in params

    kwargs: dict[str, Any] = {"m": job.terms, "n": job.terms}
    if job.continuity != "c0":
        if not accepts("continuity"):
            raise InputError(
                f"--continuity {job.continuity} is not supported by this version of pde2cad; "
                "use --continuity c0"
            )
        kwargs["continuity"] = job.continuity
    if job.tolerance is not None:
        kwargs["tolerance"] = job.tolerance
    if job.cad_tolerance is not None:
        kwargs["cad_tolerance"] = job.cad_tolerance
    if progress is not None and accepts("progress"):
        kwargs["progress"] = progress
    return kwargs


def _fit(job: ReconstructJob, points: NDArray[np.float64], labels: NDArray[np.int64],
         progress: Progress | None) -> Any:
    """Step 3: :func:`pde2cad.reconstruct.reconstruct`, any crash turned into a message."""
    from pde2cad.reconstruct import reconstruct

    kwargs = reconstruct_kwargs(reconstruct, job, progress)
    try:
        return reconstruct(points, labels, **kwargs)
    except (Pde2CadError, MemoryError, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 - a numeric or OCCT failure is still a message
        raise Pde2CadError(
            f"reconstruction failed ({type(exc).__name__}: {exc}); check that every "
            "segment is one connected 3- or 4-sided region"
        ) from exc


def _check_environment(job: ReconstructJob) -> None:
    if importlib.util.find_spec("OCP") is None:
        raise Pde2CadError("reconstruct needs OCP (OpenCASCADE); install it with: "
                           "pip install 'pde2cad[cad]'")
    if job.preview and importlib.util.find_spec("matplotlib") is None:
        raise InputError("--preview needs matplotlib; install it with: pip install "
                         "'pde2cad[plots]', or leave out --preview")


def _write_cad(job: ReconstructJob, rec: Any, outputs: dict[str, Path],
               staging: Staging) -> Path:
    """STEP (and IGES) to staging files; returns the staged STEP.

    The product/file name defaults to the TARGET's stem (the staged file has a temporary
    name); faces are named after their segments.
    """
    from pde2cad.occ.export import export_iges, export_step

    target = outputs["output"]
    name = job.name if job.name is not None else target.stem
    step = staging.path(target)
    export_step(rec, step, schema=job.schema, units=job.units, name=name, author=job.author,
                organization=job.organization)
    if "iges" in outputs:
        iges_name = job.name if job.name is not None else outputs["iges"].stem
        export_iges(rec, staging.path(outputs["iges"]), units=job.units, name=iges_name,
                    author=job.author, organization=job.organization)
    return step


def _measure(job: ReconstructJob, rec: Any, step: Path, outputs: dict[str, Path],
             info: dict[str, Any]) -> dict[str, Any]:
    """The report, measured on the staged STEP read back."""
    from pde2cad.report import build_report

    report = build_report(
        rec, step, units=job.units,
        input_info={**info, "segments": len(rec.labels)},
        settings={"continuity": job.continuity, "terms": job.terms,
                  "tolerance": job.tolerance, "cad_tolerance": job.cad_tolerance,
                  "units": job.units, "schema": job.schema, "outliers": job.outliers,
                  "voxel": job.voxel},
        # The orthogonal errors cost one more projection of every point; only the JSON
        # report shows them.
        orthogonal="report" in outputs,
    )  # fmt: skip
    report["outputs"] = {
        ("step" if key == "output" else key): str(path) for key, path in outputs.items()
    }
    return report


def _write_json(staging: Staging, target: Path, report: dict[str, Any]) -> None:
    from pde2cad.report import json_safe

    tmp = staging.path(target)
    try:
        tmp.write_text(json.dumps(json_safe(report), indent=2, allow_nan=False))
    except OSError as exc:
        raise ExportError(f"cannot write {target}: {exc.strerror or exc}") from exc


@contextmanager
def _stage(name: str, timings: dict[str, float]) -> Iterator[None]:
    t0 = time.perf_counter()
    yield
    timings[name] = time.perf_counter() - t0


def _write_outputs(job: ReconstructJob, rec: Any, outputs: dict[str, Path], staging: Staging,
                   message: Message, timings: dict[str, float],
                   info: dict[str, Any]) -> dict[str, Any]:
    """Step 4: STEP, IGES, the report from the staged STEP, the preview."""
    with _stage("write", timings):
        step = _write_cad(job, rec, outputs, staging)
    message("written; reading the STEP back to measure the seams")
    with _stage("check", timings):
        report = _measure(job, rec, step, outputs, info)
    if job.freecad_check:
        from pde2cad.fc import read_back

        message("reading the STEP with FreeCAD")
        with _stage("freecad_check", timings):
            report["freecad"] = read_back(step)
    if "preview" in outputs:
        from pde2cad.plots.preview import reconstruction_preview

        with _stage("preview", timings):
            reconstruction_preview(rec, staging.path(outputs["preview"]),
                                   title=f"{Path(job.cloud).name}: {len(rec.labels)} patches")
    return report


def _read(job: ReconstructJob, message: Message,
          timings: dict[str, float]) -> tuple[NDArray[np.float64], NDArray[np.int64], dict[str, Any]]:
    """Step 2: the labelled cloud, optionally cleaned and thinned."""
    with _stage("read", timings):
        points, labels, source = read_labelled(job)
        n_read = len(points)
        if job.outliers or job.voxel:
            from pde2cad.io.clouds import preprocess

            points, kept = preprocess(points, labels, outlier_nb=20 if job.outliers else None,
                                      voxel=job.voxel)
            labels = labels if kept is None else kept  # preprocess keeps the labels it is given
    message(f"read {n_read} points ({len(points)} used), {len(set(labels.tolist()))} segments "
            f"(labels from {source})")
    info = {"file": str(job.cloud), "points": n_read, "points_used": len(points),
            "labels_from": source}
    return points, labels, info


def wants_auto(job: ReconstructJob) -> bool:
    """Whether the patches are laid out automatically: asked for, or no labels to be had
    (a mesh, a cloud format without labels, a PLY with neither faces nor a label-like
    property)."""
    from pde2cad.io.clouds import _ply_has_faces, _ply_header

    if job.layout is not None:
        return job.layout == "auto"
    if job.labels is not None:
        return False
    path = Path(job.cloud)
    if not path.is_file() or path.stat().st_size == 0:
        return False  # read_labelled names the problem
    if path.suffix.lower() != ".ply":
        return True
    if _ply_has_faces(path):
        return True
    _, elements, _ = _ply_header(path)
    props = [n for e in elements if e[0] == "vertex" for n, kind in e[2] if kind != "list"]
    # CloudCompare stores each scalar field as scalar_<name>: one of them may be the labels.
    return not any("label" in n.lower() or "segment" in n.lower() or n.startswith("scalar_")
                   or n in LABEL_PROPERTIES for n in props)


def _fit_auto(job: ReconstructJob, message: Message, progress: Progress | None,
              timings: dict[str, float]) -> tuple[Any, Any, Any, dict[str, Any]]:
    """Steps 2-3 without labels: read the mesh or cloud, lay it out, reconstruct."""
    from pde2cad.io.clouds import check_cloud_suffix
    from pde2cad.io.meshes import FIT_POINTS, read_surface, reconstruct_auto
    from pde2cad.reconstruct import reconstruct

    path = Path(job.cloud)
    if not path.is_file():
        raise InputError(f"point cloud file {path} does not exist; check the path")
    check_cloud_suffix(path)
    with _stage("read", timings):
        surface = read_surface(path)
    message(f"read {len(surface.points)} points ({surface.source}); automatic layout")
    kwargs = reconstruct_kwargs(reconstruct, job, progress)
    with _stage("reconstruct", timings):
        rec, layout = reconstruct_auto(surface, patches=job.patches, patch_size=job.patch_size,
                                       crease_angle=job.crease_angle, message=message,
                                       **kwargs)
    info = {"file": str(job.cloud), "points": len(surface.points),
            "points_used": min(len(surface.points), FIT_POINTS), "labels_from": "auto layout"}
    return rec, surface, layout, info


def _write_labels(path: Path, points: Any, labels: Any, with_points: bool) -> None:
    """Automatic labels, one per point (with x, y, z first for a mesh's sampled points)."""
    data = np.column_stack([points, labels]) if with_points else np.asarray(labels)
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "wb") as fh:
                np.save(fh, data)
        else:
            np.savetxt(path, data, fmt="%.9g" if with_points else "%d")
    except OSError as exc:
        raise ExportError(f"cannot write {path}: {exc.strerror or exc}") from exc


def run_reconstruct(job: ReconstructJob, *, progress: Progress | None = None,
                    message: Message | None = None) -> JobResult:
    """Run a whole reconstruct job: read, fit, write, measure, commit (steps 1-5 above).

    Parameters
    ----------
    job : ReconstructJob
    progress : callable, optional
        ``progress(stage, done, total)`` during the fit.
    message : callable, optional
        Called with a line of text at each job stage.

    Returns
    -------
    JobResult

    Raises
    ------
    InputError
        Bad input or options (nothing written).
    ExportError
        An output cannot be written (nothing of this run written; earlier files kept).
    Pde2CadError
        The fit failed.
    """
    from pde2cad.occ.build import quiet_messages

    start = time.perf_counter()
    say: Message = message or (lambda text: None)
    outputs = check_outputs(job)
    _check_environment(job)
    timings: dict[str, float] = {}
    auto = wants_auto(job)
    if not auto and (job.patches or job.patch_size or job.labels_out):
        raise InputError("--patches, --patch-size and --labels-out need the automatic layout; "
                         "add --layout auto")
    if not auto:
        points, labels, info = _read(job, say, timings)
    staging = Staging()
    try:
        with quiet_messages():
            if auto:
                rec, surface, layout, info = _fit_auto(job, say, progress, timings)
            else:
                with _stage("reconstruct", timings):
                    rec = _fit(job, points, labels, progress)
            report = _write_outputs(job, rec, outputs, staging, say, timings, info)
            if auto:
                report["layout"] = layout.summary
                if "labels_out" in outputs:
                    _write_labels(staging.path(outputs["labels_out"]), surface.points,
                                  layout.labels, surface.source == "mesh")
        timings["total"] = time.perf_counter() - start
        report["timings"].update(timings)
        if "report" in outputs:
            _write_json(staging, outputs["report"], report)
        staging.commit()
    finally:
        staging.discard()
    return JobResult(reconstruction=rec, report=report, outputs=outputs, timings=timings)


__all__ = [
    "JobResult",
    "ReconstructJob",
    "Staging",
    "check_outputs",
    "input_paths",
    "label_property",
    "read_labelled",
    "reconstruct_kwargs",
    "run_reconstruct",
    "wants_auto",
]
