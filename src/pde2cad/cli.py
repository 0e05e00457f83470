"""The ``pde2cad`` command line: one entry point, one sub-command per job.

Exit codes: 0 success, 2 bad input (the message says what to fix), 3 an output file could not
be written, 1 any other pde2cad error. Nothing is ever half-written: every output goes through
a temporary file that is renamed at the end.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from pde2cad import __version__
from pde2cad.errors import ExportError, InputError, Pde2CadError

EXIT_OK, EXIT_ERROR, EXIT_INPUT, EXIT_EXPORT = 0, 1, 2, 3


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def _add_vectorize(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "vectorize",
        help="binary image -> cubic Bézier outlines (SVG, DXF)",
        description="Trace the boundary of a binary image with the fewest cubic Béziers "
        "within a tolerance, and write SVG and/or DXF.",
    )
    p.add_argument("image", help="PNG, BMP, PBM/PGM, JPEG or TIFF image")
    p.add_argument("-o", "--output", action="append", default=[], metavar="OUT",
                   help="output file, .svg or .dxf (repeat for both); default IMAGE.svg")
    p.add_argument("-t", "--tolerance", type=_positive, default=1.0,
                   help="max distance from the pixel boundary to the curves, px (default 1.0)")
    p.add_argument("--threshold", type=float, default=None,
                   help="grey level 0..255 below which pixels are foreground (default Otsu)")
    p.add_argument("--invert", action="store_true", help="light pixels are the foreground")
    p.add_argument("--no-symmetry", action="store_true", help="do not use mirror/rotational symmetry")
    p.add_argument("--c0", action="store_true", help="plain C0 joins (the thesis); default G1")
    p.add_argument("--parameterization", default="optimal",
                   choices=["optimal", "chord", "centripetal", "uniform", "foley"],
                   help="per-segment parameterization (default optimal: best per segment)")
    p.add_argument("--corner-angle", type=float, default=50.0,
                   help="minimum turn in degrees (over 4 px) for a sharp corner (default 50)")
    unit = p.add_mutually_exclusive_group()
    unit.add_argument("--dpi", type=_positive, help="image resolution; outputs in mm")
    unit.add_argument("--scale", type=_positive, metavar="MM_PER_PX", help="mm per pixel; outputs in mm")
    p.add_argument("--dxf-curves", choices=["spline", "polyline", "arcs"], default="spline",
                   help="DXF entities: exact SPLINEs (default), or polylines/arcs for controllers "
                   "without spline support")
    p.add_argument("--report", metavar="JSON", help="write loops, curves, errors and timing as JSON")
    p.set_defaults(run=_run_vectorize)


def _run_vectorize(args: argparse.Namespace) -> int:
    from pde2cad.image.vectorize import vectorize
    from pde2cad.io.atomic import atomic_path

    outputs = [Path(o) for o in args.output] or [Path(args.image).with_suffix(".svg")]
    for out in outputs:
        if out.suffix.lower() not in (".svg", ".dxf"):
            raise InputError(f"output {out} must end in .svg or .dxf")
    approximate = args.dxf_curves != "spline" and any(o.suffix.lower() == ".dxf" for o in outputs)
    # Arcs and polylines approximate the Béziers within 10 % of the fit tolerance (the DXF
    # writer's default): fitting to 90 % keeps the written file within the user's tolerance.
    fit_tolerance = args.tolerance * (0.9 if approximate else 1.0)
    drawing = vectorize(
        args.image,
        tolerance=fit_tolerance,
        threshold=args.threshold,
        invert=args.invert,
        symmetry=not args.no_symmetry,
        g1=not args.c0,
        parameterization=args.parameterization,
        corner_angle=args.corner_angle,
        dpi=args.dpi,
        scale=args.scale,
    )
    for out in outputs:
        if out.suffix.lower() == ".svg":
            drawing.write_svg(out)
        else:
            drawing.write_dxf(out, curves=args.dxf_curves)
    if args.report:
        with atomic_path(args.report) as tmp:
            tmp.write_text(json.dumps(drawing.report(), indent=2))
    symmetric = sum(1 for lp in drawing.loops if lp.symmetry)
    print(
        f"vectorize: {len(drawing.shapes())} shapes, {len(drawing.loops)} loops, "
        f"{drawing.n_curves} curves ({drawing.n_fitted_curves} independent), "
        f"max error {drawing.max_error:.3f} px "
        f"(tolerance {args.tolerance:g}), {symmetric} symmetric loops, "
        f"{drawing.time_s:.2f} s -> {', '.join(map(str, outputs))}"
    )
    return EXIT_OK


# --------------------------------------------------------------------------- reconstruct
#: Output suffixes per option of ``reconstruct`` (checked before any work is done).
_RECONSTRUCT_SUFFIXES = {
    "output": (".step", ".stp"),
    "iges": (".igs", ".iges"),
    "report": (".json",),
    "preview": (".png", ".svg", ".pdf"),
    "labels_out": (".npy", ".txt"),
}
#: PLY vertex properties tried, in order, when ``--labels`` is not given.
_LABEL_PROPERTIES = (
    "label", "labels", "scalar_label", "scalar_Label", "scalar_labels", "scalar_Labels",
    "segment", "segment_id", "scalar_segment", "scalar_Segment", "class", "scalar_class",
)  # fmt: skip
#: Deformation terms above this are far beyond anything a patch needs (and slow).
_MAX_TERMS = 40


def _terms(text: str) -> int | str:
    if text == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number or 'auto'") from None
    if not 1 <= value <= _MAX_TERMS:
        raise argparse.ArgumentTypeError(f"must be a whole number from 1 to {_MAX_TERMS}, got {text}")
    return value


def _add_reconstruct(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct",
        help="labelled point cloud -> sewn PDE/B-spline patches (STEP, IGES)",
        description="Fit one 3- or 4-sided PDE patch per segment of a labelled point cloud, "
        "join neighbours on shared edge curves, sew the faces into a shell (a solid when "
        "closed) and write STEP (and IGES). The written STEP is read back and its seams "
        "measured for the summary and the report.",
    )
    p.add_argument("cloud", help="point cloud (.ply, .pcd, .xyz, .pts, .txt, .csv, .npy) or mesh "
                   "(.off, .stl, .obj, .ply with faces)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.step",
                   help="STEP file to write (.step or .stp)")
    p.add_argument("--labels", metavar="NAME|FILE",
                   help="segment labels: a PLY vertex property name, 'column4' (4th column of a "
                   ".npy/text cloud) or a .npy/.txt file with one integer per point; default: "
                   "a PLY property such as 'label' or 'scalar_Label'")
    p.add_argument("--continuity", choices=["c0", "c1"], default="c0",
                   help="join across shared edges: c0 (position) or c1 (tangent plane); default c0")
    p.add_argument("--terms", type=_terms, default="auto", metavar="M",
                   help="deformation terms per patch direction, M = N, or 'auto' (default): "
                   "per patch, the count from 6 to 16 that best predicts held-out points")
    p.add_argument("--tolerance", type=_positive, metavar="T",
                   help="edge-curve fit tolerance in point units (default: from the noise)")
    p.add_argument("--cad-tolerance", type=_positive, metavar="T",
                   help="patch -> B-spline conversion tolerance in point units "
                   "(default 1e-4 x bounding-box diagonal)")
    p.add_argument("--units", type=str.upper, choices=["MM", "M", "IN"], default="MM",
                   help="length unit of the point coordinates, declared in the files (default MM)")
    p.add_argument("--schema", type=str.upper, choices=["AP214", "AP242"], default="AP214",
                   help="STEP application protocol (default AP214)")
    p.add_argument("--iges", metavar="OUT.igs", help="also write IGES (.igs or .iges)")
    p.add_argument("--report", metavar="R.json",
                   help="write settings, per-edge gaps and angles, per-patch errors and timings")
    p.add_argument("--preview", metavar="P.png",
                   help="picture of the patches by label with their edges, and the fit errors")
    p.add_argument("--outliers", action="store_true",
                   help="remove statistical outliers first (20 neighbours, 2 standard deviations)")
    p.add_argument("--voxel", type=_positive, metavar="SIZE",
                   help="voxel-downsample to one point per SIZE cube first (labels kept)")
    p.add_argument("--freecad-check", action="store_true",
                   help="also read the STEP with FreeCAD 0.20 (its own process) and report its "
                   "validity, solids, free edges, gaps and normal angles")
    p.add_argument("--layout", choices=["labels", "auto"],
                   help="patch layout: 'labels' (from --labels or the PLY's label property) or "
                   "'auto' (a coarse quad remesh of the surface; the default for meshes and "
                   "clouds without labels)")
    p.add_argument("--crease-angle", type=_positive, default=30.0, metavar="DEG",
                   help="auto layout: dihedral angle above which an edge is a crease (default 30)")
    p.add_argument("--patches", type=int, metavar="N",
                   help="auto layout: about N patches (default: from curvature and point count)")
    p.add_argument("--patch-size", type=_positive, metavar="L",
                   help="auto layout: about this patch side length in point units")
    p.add_argument("--labels-out", metavar="FILE.npy",
                   help="auto layout: write the labels (.npy/.txt; for a mesh input x, y, z, "
                   "label rows to rerun with --labels column4), to edit and rerun")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress and no summary")
    p.set_defaults(run=_run_reconstruct)


def _check_outputs(args: argparse.Namespace) -> dict[str, Path]:
    """Requested outputs by option, checked before any work: suffix, distinct, folder."""
    import os

    outputs = {key: Path(getattr(args, key)) for key in _RECONSTRUCT_SUFFIXES if getattr(args, key)}
    for key, path in outputs.items():
        allowed = _RECONSTRUCT_SUFFIXES[key]
        if path.suffix.lower() not in allowed:
            flag = "-o" if key == "output" else f"--{key}"
            raise InputError(f"{flag} {path} must end in {' or '.join(allowed)}")
    resolved = [p.resolve() for p in outputs.values()]
    if Path(args.cloud).resolve() in resolved:
        raise InputError(f"an output would overwrite the input cloud {args.cloud}; pick another name")
    if len(set(resolved)) != len(resolved):
        raise InputError("two outputs name the same file; give each output its own name")
    for path in outputs.values():
        parent = path.parent if str(path.parent) else Path(".")
        if not parent.is_dir():
            raise ExportError(f"cannot write {path}: folder {parent} does not exist; create it first")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise ExportError(f"cannot write {path}: folder {parent} is not writable; pick another")
    return outputs


def _label_property(path: Path) -> str:
    """The label property of a PLY cloud when ``--labels`` is not given."""
    from pde2cad.io.clouds import _ply_header

    _, elements, _ = _ply_header(path)
    props = [name for e in elements if e[0] == "vertex" for name, kind in e[2] if kind != "list"]
    for name in _LABEL_PROPERTIES:
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


def _wants_auto(args: argparse.Namespace) -> bool:
    """Whether to lay the patches out automatically: asked for, or no labels to be had."""
    from pde2cad.io.clouds import _ply_has_faces, _ply_header

    if args.layout is not None:
        return args.layout == "auto"
    if args.labels is not None:
        return False
    path = Path(args.cloud)
    if path.suffix.lower() != ".ply" or not path.is_file() or path.stat().st_size == 0:
        return path.is_file() and path.stat().st_size > 0
    if _ply_has_faces(path):
        return True
    _, elements, _ = _ply_header(path)
    props = [n for e in elements if e[0] == "vertex" for n, kind in e[2] if kind != "list"]
    # CloudCompare stores each scalar field as scalar_<name>: one of them may be the labels.
    return not any("label" in n.lower() or "segment" in n.lower() or n.startswith("scalar_")
                   or n in _LABEL_PROPERTIES for n in props)


def _auto_reconstruct(args: argparse.Namespace, kwargs: dict[str, Any],
                      progress: Any) -> tuple[Any, Any, Any]:
    """Read a mesh or unlabelled cloud, lay it out, reconstruct: (rec, points, layout)."""
    from pde2cad.io.meshes import read_surface, reconstruct_auto

    surface = read_surface(args.cloud)
    progress.message(f"read {len(surface.points)} points ({surface.source}); automatic layout")
    rec, layout = reconstruct_auto(surface, patches=args.patches, patch_size=args.patch_size,
                                   crease_angle=args.crease_angle, **kwargs)
    return rec, surface, layout


def _read_labelled(args: argparse.Namespace) -> tuple[Any, Any, str]:
    """Points, labels and where the labels came from."""
    from pde2cad.io.clouds import read_cloud

    path = Path(args.cloud)
    if not path.is_file():
        raise InputError(f"point cloud file {path} does not exist; check the path")
    if path.stat().st_size == 0:
        raise InputError(f"point cloud file {path} is empty; check the file")
    source = args.labels
    if source is None:
        if path.suffix.lower() != ".ply":
            raise InputError(
                f"{path} carries no labels by itself: pass --labels column4 (the 4th column of "
                "a .npy or text cloud) or --labels FILE (a .npy/.txt file, one label per point)"
            )
        source = _label_property(path)
    points, labels = read_cloud(path, labels=source)
    if labels is None:  # read_cloud returns labels whenever a source is named
        raise InputError(f"no labels could be read from {source}; check --labels")
    return points, labels, str(source)


class _Progress:
    """Stage progress on stderr: a tqdm bar (or a ``\\r`` counter) on a terminal, one line
    per finished stage otherwise (logs stay readable), nothing when quiet."""

    def __init__(self, quiet: bool, stream: Any = None) -> None:
        import time

        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.bar: Any = None
        self.stage: str | None = None
        self.total = 0
        self.clock = time.perf_counter
        self.start = self.clock()

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.quiet:
            return
        if stage != self.stage:
            # A stage may report only its start; the next stage's first call ends it.
            self._finish()
            self.stage, self.total, self.start = stage, total, self.clock()
            if self.tty and total > 1:
                try:
                    from tqdm import tqdm
                except ImportError:
                    self.bar = None
                else:
                    self.bar = tqdm(total=total, desc=stage, file=self.stream, leave=False,
                                    unit="", dynamic_ncols=True)
        self.total = total
        if self.bar is not None:
            self.bar.update(done - self.bar.n)
        elif self.tty and total > 1:
            print(f"\r{stage} {done}/{total}", end="", file=self.stream, flush=True)
        if done >= total:
            self._finish()

    def message(self, text: str) -> None:
        if not self.quiet:
            self._finish()
            print(text, file=self.stream, flush=True)

    def _finish(self) -> None:
        """Close the bar and print one line for the current stage, if one is open."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        if self.stage is None:
            return
        count = f" {self.total}/{self.total}" if self.total > 1 else ""
        line = f"{self.stage}:{count} done in {self.clock() - self.start:.1f} s"
        # Pad over what a \r counter left on the line.
        print(f"\r{line:<40}" if self.tty else line, file=self.stream, flush=True)
        self.stage = None


class _Staging:
    """Outputs written to temporary files beside their targets and renamed together at the
    end: a failure anywhere (a later output, the read-back check) leaves no output of this
    run behind."""

    def __init__(self) -> None:
        self.pending: dict[Path, Path] = {}

    def path(self, target: Path) -> Path:
        import os
        import tempfile

        parent = target.parent if str(target.parent) else Path(".")
        try:
            fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=parent)
        except OSError as exc:
            raise ExportError(f"cannot write {target}: {exc.strerror or exc}") from exc
        os.close(fd)
        self.pending[target] = Path(name)
        return Path(name)

    def commit(self) -> None:
        import os

        # mkstemp creates 0600 files; give the outputs the usual permissions (umask applied).
        umask = os.umask(0o022)
        os.umask(umask)
        done: list[Path] = []
        try:
            for target, tmp in self.pending.items():
                os.chmod(tmp, 0o666 & ~umask)
                os.replace(tmp, target)
                done.append(target)
        except OSError as exc:
            for target in done:  # this run's outputs only; never anything older
                target.unlink(missing_ok=True)
            raise ExportError(f"cannot write {target}: {exc.strerror or exc}") from exc
        finally:
            self.discard()

    def discard(self) -> None:
        for tmp in self.pending.values():
            tmp.unlink(missing_ok=True)
        self.pending.clear()


def _quiet_occt() -> Callable[[], None]:
    """Silence OCCT's transfer statistics (printed on stdout); returns the undo."""
    try:
        from OCP.Message import Message, Message_Gravity
    except ImportError:
        return lambda: None
    printers = list(Message.DefaultMessenger_s().Printers())
    levels = [p.GetTraceLevel() for p in printers]
    for p in printers:
        p.SetTraceLevel(Message_Gravity.Message_Fail)

    def undo() -> None:
        for p, level in zip(printers, levels, strict=True):
            p.SetTraceLevel(level)

    return undo


def _reconstruct_kwargs(reconstruct: Callable[..., Any], args: argparse.Namespace,
                        progress: Callable[[str, int, int], None]) -> dict[str, Any]:
    """Keyword arguments for ``reconstruct``: options left at their default are not passed,
    so the command works with versions of ``reconstruct`` that lack them."""
    import inspect

    params = inspect.signature(reconstruct).parameters
    takes_all = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())

    def accepts(name: str) -> bool:
        return takes_all or name in params

    kwargs: dict[str, Any] = {"m": args.terms, "n": args.terms}
    if args.continuity != "c0":
        if not accepts("continuity"):
            raise InputError(
                f"--continuity {args.continuity} is not supported by this version of pde2cad; "
                "use --continuity c0"
            )
        kwargs["continuity"] = args.continuity
    if args.tolerance is not None:
        kwargs["tolerance"] = args.tolerance
    if args.cad_tolerance is not None:
        kwargs["cad_tolerance"] = args.cad_tolerance
    if accepts("progress"):
        kwargs["progress"] = progress
    return kwargs


def _run_reconstruct(args: argparse.Namespace) -> int:
    import importlib.util
    import time

    start = time.perf_counter()
    outputs = _check_outputs(args)
    if importlib.util.find_spec("OCP") is None:
        raise Pde2CadError("reconstruct needs OCP (OpenCASCADE); install it with: "
                           "pip install 'pde2cad[cad]'")
    if args.preview and importlib.util.find_spec("matplotlib") is None:
        raise InputError("--preview needs matplotlib; install it with: pip install "
                         "'pde2cad[plots]', or leave out --preview")
    progress = _Progress(args.quiet)
    timings: dict[str, float] = {}

    auto = _wants_auto(args)
    if not auto and (args.patches or args.patch_size or args.labels_out):
        raise InputError("--patches, --patch-size and --labels-out need the automatic layout; "
                         "add --layout auto")
    t0 = time.perf_counter()
    if not auto:
        points, labels, source = _read_labelled(args)
        n_read = len(points)
        if args.outliers or args.voxel:
            from pde2cad.io.clouds import preprocess

            points, labels = preprocess(points, labels, outlier_nb=20 if args.outliers else None,
                                        voxel=args.voxel)
        timings["read"] = time.perf_counter() - t0
        n_segments = len(set(labels.tolist()))
        progress.message(f"read {n_read} points ({len(points)} used), {n_segments} segments "
                         f"(labels from {source})")

    from pde2cad.reconstruct import reconstruct

    undo = _quiet_occt()
    staging = _Staging()
    layout = None
    try:
        t0 = time.perf_counter()
        kwargs = _reconstruct_kwargs(reconstruct, args, progress)
        try:
            if auto:
                rec, surface, layout = _auto_reconstruct(args, kwargs, progress)
                points, source, n_read = surface.points, "auto layout", len(surface.points)
            else:
                rec = reconstruct(points, labels, **kwargs)
        except (Pde2CadError, MemoryError, KeyboardInterrupt):
            raise
        except Exception as exc:  # noqa: BLE001 - a numeric or OCCT failure is still a message
            raise Pde2CadError(
                f"reconstruction failed ({type(exc).__name__}: {exc}); check that every "
                "segment is one connected 3- or 4-sided region"
            ) from exc
        timings["reconstruct"] = time.perf_counter() - t0
        report = _write_outputs(args, rec, outputs, staging, progress, timings, source, n_read,
                                len(points))
        if layout is not None:
            report["layout"] = layout.summary
            if "labels_out" in outputs:
                _write_labels(staging.path(outputs["labels_out"]), points, layout.labels,
                              surface.source == "mesh")
        timings["total"] = time.perf_counter() - start
        report["timings"].update(timings)
        if "report" in outputs:
            _write_json(staging, outputs["report"], report)
        staging.commit()
    finally:
        staging.discard()
        undo()
    if not report["summary"]["valid"]:
        print(f"pde2cad reconstruct: warning: OpenCASCADE reports the shape in {outputs['output']} "
              "as invalid; check it before use", file=sys.stderr)
    if not args.quiet:
        print(f"reconstruct: {args.cloud} -> {', '.join(map(str, outputs.values()))}")
        for line in _summary(report):
            print(f"  {line}")
        print(f"  time {timings['total']:.1f} s")
    return EXIT_OK


def _write_labels(path: Path, points: Any, labels: Any, with_points: bool) -> None:
    """Automatic labels, one per point (with x, y, z first for a mesh's sampled points)."""
    import numpy as np

    data = np.column_stack([points, labels]) if with_points else np.asarray(labels)
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "wb") as fh:
                np.save(fh, data)
        else:
            np.savetxt(path, data, fmt="%.9g" if with_points else "%d")
    except OSError as exc:
        raise ExportError(f"cannot write {path}: {exc.strerror or exc}") from exc


def _layout_line(layout: dict[str, Any]) -> str:
    valence = ", ".join(f"{c} of valence {v}" for v, c in layout["corner_valence"].items())
    creases = "" if layout.get("creases") is None else f", {layout['creases']} crease edges in input"
    return (f"layout: auto, {layout['patches']} patches ({layout['faces']['quads']} quads, "
            f"{layout['faces']['triangles']} triangles), irregular corners: {valence or 'none'}, "
            f"{layout['components']} component(s){creases}")


def _summary(report: dict[str, Any]) -> list[str]:
    from pde2cad.report import summary_lines

    lines = summary_lines(report)
    if report.get("layout"):
        lines.insert(0, _layout_line(report["layout"]))
    fc = report.get("freecad")
    if fc:
        diagonal = report["summary"].get("diagonal") or 1.0
        shape = f"{fc['n_solids']} solid(s)" if fc["n_solids"] else f"{fc['n_shells']} shell(s)"
        lines.append(
            f"{fc['reader']}: {'valid' if fc['valid'] else 'INVALID'}, {fc['n_faces']} faces, "
            f"{shape}, {fc['free_edges']} free edges, max gap "
            f"{fc['max_gap'] / diagonal:.1e} x diagonal, max normal angle "
            f"{fc['max_angle_deg']:.3g} deg"
        )
    return lines


def _write_json(staging: _Staging, target: Path, report: dict[str, Any]) -> None:
    from pde2cad.report import json_safe

    tmp = staging.path(target)
    try:
        tmp.write_text(json.dumps(json_safe(report), indent=2, allow_nan=False))
    except OSError as exc:
        raise ExportError(f"cannot write {target}: {exc.strerror or exc}") from exc


def _write_outputs(args: argparse.Namespace, rec: Any, outputs: dict[str, Path],
                   staging: _Staging, progress: _Progress, timings: dict[str, float],
                   source: str, n_read: int, n_used: int) -> dict[str, Any]:
    """STEP, IGES and preview to staging files, and the report from the staged STEP."""
    import time

    from pde2cad.occ import write_iges, write_step
    from pde2cad.report import build_report

    t0 = time.perf_counter()
    step = staging.path(outputs["output"])
    write_step(rec.shape, step, schema=args.schema, units=args.units)
    if "iges" in outputs:
        write_iges(rec.shape, staging.path(outputs["iges"]), units=args.units)
    timings["write"] = time.perf_counter() - t0
    progress.message("written; reading the STEP back to measure the seams")

    t0 = time.perf_counter()
    report = build_report(
        rec, step, units=args.units,
        input_info={"file": str(args.cloud), "points": n_read, "points_used": n_used,
                    "segments": len(rec.labels), "labels_from": source},
        settings={"continuity": args.continuity, "terms": args.terms,
                  "tolerance": args.tolerance, "cad_tolerance": args.cad_tolerance,
                  "units": args.units, "schema": args.schema, "outliers": args.outliers,
                  "voxel": args.voxel},
        # The orthogonal errors cost one more projection of every point; only the JSON
        # report shows them.
        orthogonal="report" in outputs,
    )  # fmt: skip
    report["outputs"] = {
        ("step" if key == "output" else key): str(path) for key, path in outputs.items()
    }
    timings["check"] = time.perf_counter() - t0

    if args.freecad_check:
        from pde2cad.fc import read_back

        progress.message("reading the STEP with FreeCAD")
        t0 = time.perf_counter()
        report["freecad"] = read_back(step)
        timings["freecad_check"] = time.perf_counter() - t0

    if "preview" in outputs:
        from pde2cad.plots.preview import reconstruction_preview

        t0 = time.perf_counter()
        reconstruction_preview(rec, staging.path(outputs["preview"]),
                               title=f"{Path(args.cloud).name}: {len(rec.labels)} patches")
        timings["preview"] = time.perf_counter() - t0
    return report


COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_vectorize, _add_reconstruct]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pde2cad",
        description="Measured data to manufacturable CAD: binary images to Bézier outlines "
        "(SVG/DXF), point clouds to PDE surface patches (STEP/IGES).",
    )
    parser.add_argument("--version", action="version", version=f"pde2cad {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add in COMMANDS:
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return EXIT_INPUT
    try:
        return int(args.run(args))
    except InputError as exc:
        print(f"pde2cad {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except ExportError as exc:
        print(f"pde2cad {args.command}: cannot write output: {exc}", file=sys.stderr)
        return EXIT_EXPORT
    except Pde2CadError as exc:
        print(f"pde2cad {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except MemoryError:
        print(f"pde2cad {args.command}: out of memory; try a smaller image or region", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"pde2cad {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
