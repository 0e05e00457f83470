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


COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_vectorize]


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
