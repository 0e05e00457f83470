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
    p.add_argument("images", nargs="+", metavar="IMAGE",
                   help="PNG, BMP, PBM/PGM, JPEG or TIFF image(s); several need --out-dir")
    p.add_argument("-o", "--output", action="append", default=[], metavar="OUT",
                   help="output file, .svg or .dxf (repeat for both); default IMAGE.svg")
    p.add_argument("--out-dir", metavar="DIR",
                   help="batch mode: write IMAGE_STEM.svg/.dxf for every image into DIR")
    p.add_argument("--format", default="svg", metavar="svg,dxf",
                   help="batch mode: comma-separated output formats (default svg)")
    p.add_argument("-j", "--jobs", type=int, default=0,
                   help="batch mode: parallel worker processes (default: one per core)")
    p.add_argument("--min-area", type=int, default=2, metavar="PX",
                   help="drop specks and fill holes of at most PX pixels (potrace's turdsize, "
                   "default 2; 0 keeps everything)")
    p.add_argument("--max-seconds", type=_positive, default=600.0, metavar="S",
                   help="stop with an error (exit 1, no output) when an image takes longer "
                   "than S seconds (default 600)")
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
    p.add_argument("--dxf-version", type=str.upper, choices=["R12", "R2000", "R2010"],
                   default="R2010", help="DXF version (default R2010); R12 writes POLYLINEs of "
                   "lines and arcs (bulges) for old laser/CNC software")
    p.add_argument("--offset", type=float, default=0.0, metavar="MM",
                   help="kerf compensation in DXF units (mm with --dpi/--scale, else px): outer "
                   "loops grow, holes shrink by this distance (negative: the reverse); written as "
                   "lines and arcs. Loops the offset closes up are left out (and named)")
    p.add_argument("--report", metavar="JSON", help="write loops, curves, errors and timing as JSON")
    p.set_defaults(run=_dispatch_vectorize)


def _dispatch_vectorize(args: argparse.Namespace) -> int:
    """One image: :func:`_run_vectorize`; several, or ``--out-dir``: :func:`_run_vectorize_batch`."""
    import os

    if args.min_area < 0:
        raise InputError(f"--min-area must be >= 0 pixels, got {args.min_area}")
    # The fits are many tiny matrices: a BLAS thread pool only costs its start (~80 ms of
    # CPU on 2 cores) and, in batch mode, oversubscribes the workers. numpy is not imported
    # yet at this point, so the limit takes effect.
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    if args.out_dir is not None or len(args.images) > 1:
        if args.output:
            raise InputError("-o/--output names one file; with several images use --out-dir DIR")
        if args.out_dir is None:
            raise InputError(f"{len(args.images)} images given: add --out-dir DIR for their outputs")
        return _run_vectorize_batch(args)
    args.image = args.images[0]
    return _run_vectorize(args)


def vectorize_options(args: argparse.Namespace, tolerance: float) -> dict[str, Any]:
    """Keyword arguments of :func:`pde2cad.image.vectorize.vectorize` from the parsed flags."""
    return dict(
        tolerance=tolerance, threshold=args.threshold, invert=args.invert,
        symmetry=not args.no_symmetry, g1=not args.c0, parameterization=args.parameterization,
        corner_angle=args.corner_angle, dpi=args.dpi, scale=args.scale,
        min_area=args.min_area, max_seconds=args.max_seconds,
    )


def _run_vectorize(args: argparse.Namespace) -> int:
    from pde2cad.image.vectorize import vectorize
    from pde2cad.io.staging import OutputSet, check_paths

    outputs = [Path(o) for o in args.output] or [Path(args.image).with_suffix(".svg")]
    for out in outputs:
        if out.suffix.lower() not in (".svg", ".dxf"):
            raise InputError(f"output {out} must end in .svg or .dxf")
    report = Path(args.report) if args.report else None
    check_paths([args.image], [*outputs, report])
    if args.offset and not any(o.suffix.lower() == ".dxf" for o in outputs):
        raise InputError("--offset applies to DXF output only; add -o NAME.dxf")
    approximate = (args.dxf_curves != "spline" or args.dxf_version == "R12" or args.offset) and any(
        o.suffix.lower() == ".dxf" for o in outputs
    )
    # Arcs and polylines approximate the Béziers within 10 % of the fit tolerance (the DXF
    # writer's default): fitting to 90 % keeps the written file within the user's tolerance.
    fit_tolerance = args.tolerance * (0.9 if approximate else 1.0)
    with OutputSet() as staged:
        # Reserved before the fit: a missing or read-only folder fails at once, not after it.
        tmps = {out: staged.path(out) for out in [*outputs, *([report] if report else [])]}
        drawing = vectorize(args.image, **vectorize_options(args, fit_tolerance))
        for out in outputs:
            _write_drawing(drawing, out, tmps[out], args)
        if report is not None:
            _write_text(tmps[report], report, json.dumps(drawing.report(), indent=2))
        staged.commit()
    symmetric = sum(1 for lp in drawing.loops if lp.symmetry)
    return _print_summary(
        f"vectorize: {len(drawing.shapes())} shapes, {len(drawing.loops)} loops, "
        f"{drawing.n_curves} curves ({drawing.n_fitted_curves} independent), "
        f"max error {drawing.max_error:.3f} px "
        f"(tolerance {args.tolerance:g}), {symmetric} symmetric loops, "
        f"{drawing.specks} specks dropped, "
        f"{drawing.time_s:.2f} s -> {', '.join(map(str, outputs))}"
    )


def _write_drawing(drawing: Any, target: Path, tmp: Path, args: argparse.Namespace) -> None:
    """One SVG or DXF output of ``vectorize`` into its staged file ``tmp``."""
    if target.suffix.lower() == ".svg":
        from pde2cad.io.svg import svg_string

        _write_text(tmp, target, svg_string(drawing))
        return
    from pde2cad.io.dxf import dxf_document

    notes: list[str] = []
    doc = dxf_document(drawing, curves=args.dxf_curves, version=args.dxf_version,
                       offset=args.offset, notes=notes)
    for note in notes:
        print(f"pde2cad vectorize: warning: {target}: {note}", file=sys.stderr)
    try:
        doc.saveas(tmp)
    except OSError as exc:
        raise ExportError(f"cannot write {target}: {exc.strerror or exc}") from exc


def _write_text(tmp: Path, target: Path, text: str) -> None:
    try:
        tmp.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise ExportError(f"cannot write {target}: {exc.strerror or exc}") from exc


def _print_summary(text: str) -> int:
    """Print the summary line; the outputs are written already, so a closed pipe (``| head``)
    still ends in exit 0, while a stdout that cannot take it (``> /dev/full``) ends in exit 3
    with a message on stderr. Never a traceback, neither now nor at interpreter exit."""
    import os

    try:
        print(text, flush=True)
    except OSError as exc:
        # Point stdout at /dev/null so the interpreter's final flush has nowhere to fail.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        if isinstance(exc, BrokenPipeError):
            return EXIT_OK
        print(f"pde2cad: outputs written, but the summary could not be printed: "
              f"{exc.strerror or exc}", file=sys.stderr)
        return EXIT_EXPORT
    return EXIT_OK


def _run_vectorize_batch(args: argparse.Namespace) -> int:
    """Batch mode: every image into ``--out-dir``, ``--jobs`` worker processes, one line
    per image and a total.

    Steps: 1. check the formats and the folder before any work; 2. import the fitter once
    (forked workers inherit it, so start-up is paid once); 3. vectorize and write each
    image in a worker (each output atomically: a failed image leaves no file); 4. print
    the lines in input order and return the first failure's exit code (0 when all pass).
    """
    import os
    import time

    # Imported before forking, so that every worker inherits them instead of importing them.
    from pde2cad.image import crossings, symmetry  # noqa: F401
    from pde2cad.image import vectorize as _fitter  # noqa: F401
    from pde2cad.io import svg  # noqa: F401

    started = time.perf_counter()
    formats = [f.strip().lower().lstrip(".") for f in args.format.split(",") if f.strip()]
    if not formats or any(f not in ("svg", "dxf") for f in formats):
        raise InputError(f"--format must list svg and/or dxf (comma-separated), got {args.format!r}")
    out_dir = Path(args.out_dir)
    if not out_dir.is_dir():
        raise ExportError(f"--out-dir {out_dir} is not a folder; create it first")
    stems = [Path(i).stem for i in args.images]
    if len(set(stems)) < len(stems):
        raise InputError("two images share a file name; their outputs would overwrite each other")
    from pde2cad.io.staging import check_paths

    targets = {img: [out_dir / f"{Path(img).stem}.{f}" for f in dict.fromkeys(formats)]
               for img in args.images}
    # An image named x.svg in the output folder would be overwritten by its own SVG.
    check_paths(args.images, [out for outs in targets.values() for out in outs])
    # The same DXF settings as one image: R12 and kerf offsets are lines and arcs, fitted
    # to 90 % so the written file stays within the tolerance.
    approximate = "dxf" in formats and (
        args.dxf_curves != "spline" or args.dxf_version == "R12" or bool(args.offset))
    options = vectorize_options(args, args.tolerance * (0.9 if approximate else 1.0))
    dxf = {"curves": args.dxf_curves, "version": args.dxf_version, "offset": args.offset}
    jobs = [(img, outs, options, dxf) for img, outs in targets.items()]
    workers = min(args.jobs if args.jobs > 0 else (os.cpu_count() or 1), len(jobs))
    if workers > 1:
        import multiprocessing as mp

        with mp.get_context("fork").Pool(workers) as pool:
            results = pool.imap(_batch_one, jobs)
            code, curves, failed = _batch_lines(results)
    else:
        code, curves, failed = _batch_lines(map(_batch_one, jobs))
    wall = time.perf_counter() - started
    print(f"vectorize: {len(jobs)} images, {failed} failed, {curves} curves, {wall:.2f} s "
          f"({wall / len(jobs):.3f} s per image, {workers} workers) -> {out_dir}")
    return code


def _batch_lines(results) -> tuple[int, int, int]:
    """Print one line per result; returns (first failure's exit code or 0, curves, failures)."""
    code, curves, failed = EXIT_OK, 0, 0
    for r in results:
        if "error" in r:
            failed += 1
            code = code or r["code"]
            print(f"{r['image']}: error: {r['error']}", flush=True)
            continue
        curves += r["curves"]
        print(f"{r['image']}: {r['curves']} curves, max error {r['max_error']:.3f} px, "
              f"{r['specks']} specks dropped, {r['time_s']:.2f} s -> {', '.join(r['outputs'])}", flush=True)
    return code, curves, failed


def _batch_one(job: tuple[str, list[Path], dict[str, Any], dict[str, Any]]) -> dict[str, Any]:
    """Vectorize and write one image of a batch; errors come back as a result, not raised."""
    from pde2cad.image.vectorize import vectorize

    image, outputs, options, dxf = job
    try:
        drawing = vectorize(image, **options)
        for out in outputs:
            if out.suffix == ".svg":
                drawing.write_svg(out)
            else:
                from pde2cad.io.dxf import write_dxf  # only when asked: it imports ezdxf

                for note in write_dxf(drawing, out, **dxf):
                    print(f"pde2cad vectorize: warning: {out}: {note}", file=sys.stderr)
    except InputError as exc:
        return {"image": image, "error": str(exc), "code": EXIT_INPUT}
    except ExportError as exc:
        return {"image": image, "error": f"cannot write output: {exc}", "code": EXIT_EXPORT}
    except (Pde2CadError, MemoryError) as exc:
        return {"image": image, "error": str(exc) or type(exc).__name__, "code": EXIT_ERROR}
    return {"image": image, "curves": drawing.n_curves, "max_error": drawing.max_error,
            "specks": drawing.specks, "time_s": drawing.time_s, "outputs": [str(o) for o in outputs]}


# --------------------------------------------------------------------------- reconstruct
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
    p.add_argument("--name", help="product name in the STEP/IGES files (default: the writer's)")
    p.add_argument("--author", help="author recorded in the STEP/IGES header")
    p.add_argument("--organization", help="organization recorded in the STEP/IGES header")
    p.add_argument("--layout", choices=["labels", "auto"],
                   help="patch layout: 'labels' (from --labels or the PLY's label property) or "
                   "'auto' (a coarse quad remesh of the surface; the default for meshes and "
                   "clouds without labels)")
    p.add_argument("--crease-angle", type=_positive, default=30.0, metavar="DEG",
                   help="auto layout: an edge is a crease when its dihedral exceeds what the "
                   "surface around it bends per edge by more than DEG (default 30)")
    p.add_argument("--patches", type=int, metavar="N",
                   help="auto layout: about N patches (default: from curvature and point count)")
    p.add_argument("--patch-size", type=_positive, metavar="L",
                   help="auto layout: about this patch side length in point units")
    p.add_argument("--labels-out", metavar="FILE.npy",
                   help="auto layout: write the labels (.npy/.txt; for a mesh input x, y, z, "
                   "label rows to rerun with --labels column4), to edit and rerun")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress and no summary")
    p.set_defaults(run=_run_reconstruct)


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


def _run_reconstruct(args: argparse.Namespace) -> int:
    from pde2cad.reconstruct_job import ReconstructJob, run_reconstruct

    progress = _Progress(args.quiet)
    result = run_reconstruct(ReconstructJob.from_options(args), progress=progress,
                             message=progress.message)
    report, outputs = result.report, result.outputs
    if not report["summary"]["valid"]:
        print(f"pde2cad reconstruct: warning: OpenCASCADE reports the shape in {outputs['output']} "
              "as invalid; check it before use", file=sys.stderr)
    if not args.quiet:
        lines = [f"reconstruct: {args.cloud} -> {', '.join(map(str, outputs.values()))}",
                 *(f"  {line}" for line in _summary(report)),
                 f"  time {result.timings['total']:.1f} s"]
        try:
            print("\n".join(lines), flush=True)
        except OSError as exc:  # a full disk or a closed pipe behind stdout
            raise ExportError(f"the outputs were written, but the summary could not be "
                              f"printed ({exc.strerror or exc})") from exc
    return EXIT_OK


def _layout_line(layout: dict[str, Any]) -> str:
    valence = ", ".join(f"{c} of valence {v}" for v, c in layout["corner_valence"].items())
    creases = "" if layout.get("creases") is None else f", {layout['creases']} crease edges in input"
    if layout.get("kind") == "crease regions":
        told = layout.get("crease_angle_told")
        if told is not None:  # a cloud: its noise may hide the gentler creases
            creases += (f", creases of {told:g} deg or more told (point noise "
                        f"{layout.get('noise', 0.0):.2g})")
        return (f"layout: auto, the {layout['patches']} crease-bounded regions as segments "
                f"(split into 3/4-sided patches below), {layout['components']} component(s){creases}")
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
