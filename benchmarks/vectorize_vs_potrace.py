"""Benchmark pde2cad.vectorize against potrace on the example images.

Usage (from a plain checkout, with the project's venv python)::

    python benchmarks/vectorize_vs_potrace.py                 # all examples/images/*.png
    python benchmarks/vectorize_vs_potrace.py a.png b.png --json out.json
    python benchmarks/vectorize_vs_potrace.py --potrace-only  # no pde2cad.vectorize needed

For every image: pde2cad.vectorize with the default options (symmetry on) and with
``symmetry=False``, and potrace (SVG backend, default options). Segments are Bézier curves
plus lines (each counts one; potrace's corners are two lines). Errors are measured by
:func:`pde2cad.image.evaluate.outline_error` against the ORIGINAL mask: the max over the
exact pixel boundary of the distance to the nearest curve. Times are wall times (potrace:
best of 3 subprocess runs including process start; ours: best of ``--repeat`` calls on the
in-memory mask). Each vectorize call runs in a forked child process and is killed after
``--timeout`` seconds (default 300), so one hanging image does not stop the run.

Checks flagged per row: ``E`` our max error above the tolerance, ``R`` segments above
``--ratio`` (0.55) x potrace's, ``S`` a ``sym_*`` image that does not get cheaper with
symmetry, ``X`` vectorize failed or timed out.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import shutil
import sys
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    import pde2cad  # noqa: F401
except ImportError:  # plain checkout without an installed package
    sys.path.insert(0, str(ROOT / "src"))

from pde2cad.image.evaluate import outline_error, read_mask, run_potrace  # noqa: E402


def load_mask(path: Path) -> np.ndarray:
    """The mask the errors are measured against (the package's reader when available)."""
    try:
        from pde2cad.image.raster import read_image
    except ImportError:
        return read_mask(path)
    return read_image(path)


def despeckled(mask: np.ndarray, area: int) -> np.ndarray:
    """The mask without foreground specks (8-connected) and holes (4-connected) of at most
    ``area`` pixels, computed independently of pde2cad with scipy.ndimage."""
    from scipy import ndimage

    out = mask.copy()
    for fg, structure in ((True, np.ones((3, 3), bool)), (False, None)):
        region = out if fg else ~np.pad(out, 1)
        lab, _ = ndimage.label(region, structure=structure)
        small = np.bincount(lab.ravel()) <= area
        small[0] = False
        hit = small[lab]
        if fg:
            out[hit] = False
        else:
            out[hit[1:-1, 1:-1]] = True
    return out


def get_vectorize() -> Any:
    """pde2cad.vectorize, or None when the package does not provide it (yet)."""
    try:
        import pde2cad
        from pde2cad.image import vectorize as _module  # noqa: F401
    except ImportError:
        return None
    return getattr(pde2cad, "vectorize", None)


def run_ours(
    vectorize: Any, mask: np.ndarray, tolerance: float, repeat: int, **options: Any
) -> dict[str, Any]:
    best = float("inf")
    drawing = None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        drawing = vectorize(mask, tolerance=tolerance, **options)
        best = min(best, time.perf_counter() - t0)
    assert drawing is not None
    curves = [np.asarray(lp.curves, dtype=float) for lp in drawing.loops]
    return {
        "segments": int(sum(len(c) for c in curves)),
        "fitted": int(getattr(drawing, "n_fitted_curves", sum(len(c) for c in curves))),
        "curves": curves,
        "time_s": best,
        "reported_max_error": float(drawing.max_error),
        "symmetry": sorted({lp.symmetry for lp in drawing.loops if lp.symmetry}),
    }


def _child(conn: Any, vectorize: Any, args: tuple[Any, ...], options: dict[str, Any]) -> None:
    try:
        conn.send(("ok", run_ours(vectorize, *args, **options)))
    except BaseException as exc:  # report everything to the parent
        conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
    finally:
        conn.close()


def run_ours_limited(
    vectorize: Any,
    mask: np.ndarray,
    tolerance: float,
    repeat: int,
    timeout: float,
    **options: Any,
) -> dict[str, Any]:
    """:func:`run_ours` in a forked child process, killed after ``timeout`` seconds.

    With ``timeout <= 0`` (or where fork is unavailable) it runs in this process.
    """
    if timeout <= 0 or "fork" not in mp.get_all_start_methods():
        return run_ours(vectorize, mask, tolerance, repeat, **options)
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, vectorize, (mask, tolerance, repeat), options))
    proc.start()
    child.close()
    try:
        if not parent.poll(timeout):
            raise TimeoutError(f"vectorize took more than {timeout:g} s")
        status, payload = parent.recv()
    except EOFError:
        raise RuntimeError("vectorize crashed (child process died)") from None
    finally:
        if proc.is_alive() and not parent.poll(0):
            proc.terminate()
        proc.join()
        parent.close()
    if status != "ok":
        raise RuntimeError(payload)
    return payload


def bench_image(
    path: Path,
    vectorize: Any,
    tolerance: float,
    repeat: int,
    ratio_limit: float,
    timeout: float = 0.0,
    with_nosym: bool = True,
) -> dict[str, Any]:
    mask = load_mask(path)
    row: dict[str, Any] = {"image": path.stem, "width": mask.shape[1], "height": mask.shape[0]}
    pt = run_potrace(mask)
    # Both tools drop specks of up to 2 px by default (potrace's turdsize, our --min-area):
    # distances are measured to the boundary of the mask without them.
    mask = despeckled(mask, 2)
    pe = outline_error(mask, pt["curves"])
    row.update(
        potrace_segments=pt["segments"],
        potrace_max_error=pe["max_boundary_to_curve"],
        potrace_mean_error=pe["mean_boundary_to_curve"],
        potrace_time_s=pt["time_s"],
    )
    if vectorize is None:
        return row
    flags = ""
    try:
        ours = run_ours_limited(vectorize, mask, tolerance, repeat, timeout)
        nosym = run_ours_limited(vectorize, mask, tolerance, 1, timeout, symmetry=False) if with_nosym else ours
    except Exception as exc:  # keep benchmarking the other images
        row["error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        row["traceback"] = f"{exc}\n{traceback.format_exc()}"
        if not isinstance(exc, TimeoutError):
            print(f"{path.name}: {row['traceback']}", file=sys.stderr)
        row["flags"] = "X"
        return row
    oe = outline_error(mask, ours["curves"])
    ne = outline_error(mask, nosym["curves"])
    row.update(
        ours_segments=ours["segments"],
        ratio=ours["segments"] / max(pt["segments"], 1),
        ours_nosym_segments=nosym["segments"],
        ours_fitted=ours["fitted"],
        ours_max_error=oe["max_boundary_to_curve"],
        ours_mean_error=oe["mean_boundary_to_curve"],
        ours_max_curve_to_boundary=oe["max_curve_to_boundary"],
        ours_worst_point=oe["worst_boundary_point"],
        ours_reported_max_error=ours["reported_max_error"],
        ours_nosym_max_error=ne["max_boundary_to_curve"],
        ours_time_s=ours["time_s"],
        ours_nosym_time_s=nosym["time_s"],
        time_ratio=ours["time_s"] / max(pt["time_s"], 1e-9),
        symmetry=ours["symmetry"],
    )
    if max(oe["max_boundary_to_curve"], ne["max_boundary_to_curve"]) > tolerance * (1 + 1e-9):
        flags += "E"
    if row["ratio"] > ratio_limit:
        flags += "R"
    if path.stem.startswith("sym_") and not ours["fitted"] < nosym["segments"]:
        flags += "S"
    row["flags"] = flags
    return row


def table_header(ours: bool) -> str:
    if ours:
        return (
            f"{'image':24s} {'size':>9s} {'potrace':>7s} {'ours':>5s} {'ratio':>5s} {'fit':>4s} {'nosym':>5s}"
            f" {'err ours':>8s} {'err pot':>8s} {'t ours':>7s} {'t pot':>6s} {'t x':>6s} flags"
        )
    return (
        f"{'image':24s} {'size':>9s} {'potrace':>7s} {'err pot':>8s} {'mean pot':>8s}"
        f" {'t pot':>6s}"
    )


def table_row(r: dict[str, Any], ours: bool) -> str:
    size = f"{r['width']}x{r['height']}"
    if not ours:
        return (
            f"{r['image']:24s} {size:>9s} {r['potrace_segments']:7d} {r['potrace_max_error']:8.3f}"
            f" {r['potrace_mean_error']:8.3f} {r['potrace_time_s']:6.3f}"
        )
    if "error" in r:
        return f"{r['image']:24s} {size:>9s} {r['potrace_segments']:7d}  FAILED: {r['error']}"
    return (
        f"{r['image']:24s} {size:>9s} {r['potrace_segments']:7d} {r['ours_segments']:5d}"
        f" {r['ratio']:5.2f} {r['ours_fitted']:4d} {r['ours_nosym_segments']:5d} {r['ours_max_error']:8.3f}"
        f" {r['potrace_max_error']:8.3f} {r['ours_time_s']:7.3f} {r['potrace_time_s']:6.3f}"
        f" {r['time_ratio']:6.1f} {r['flags']}"
    )


def totals(rows: list[dict[str, Any]], ours: bool) -> dict[str, Any]:
    t: dict[str, Any] = {
        "images": len(rows),
        "potrace_segments": int(sum(r["potrace_segments"] for r in rows)),
        "potrace_max_error": max((r["potrace_max_error"] for r in rows), default=0.0),
        "potrace_time_s": float(sum(r["potrace_time_s"] for r in rows)),
    }
    ok = [r for r in rows if "ours_segments" in r]
    if ours and ok:
        pot_ok = sum(r["potrace_segments"] for r in ok)
        t.update(
            failed=len(rows) - len(ok),
            potrace_segments_ok=int(pot_ok),
            ours_segments=int(sum(r["ours_segments"] for r in ok)),
            ours_nosym_segments=int(sum(r["ours_nosym_segments"] for r in ok)),
            ours_fitted=int(sum(r["ours_fitted"] for r in ok)),
            ratio=sum(r["ours_segments"] for r in ok) / max(pot_ok, 1),
            ours_max_error=max(r["ours_max_error"] for r in ok),
            ours_time_s=float(sum(r["ours_time_s"] for r in ok)),
            time_ratio=sum(r["ours_time_s"] for r in ok)
            / max(sum(r["potrace_time_s"] for r in ok), 1e-9),
            flagged=[r["image"] + ":" + r["flags"] for r in rows if r.get("flags")],
        )
    return t


# ---------------------------------------------------------------------------- unseen sets
#: Fonts that Debian (fonts-dejavu, fonts-liberation2) and matplotlib ship; none designed here.
_FONT_DIRS = ("/usr/share/fonts/truetype/dejavu", "/usr/share/fonts/truetype/liberation2")
_FONTS = ("DejaVuSans.ttf", "DejaVuSerif-Bold.ttf", "LiberationSerif-Italic.ttf", "LiberationMono-Regular.ttf")
_GLYPHS = "AgKQRSWx&@%8e3?"


def _find_font(name: str) -> Path | None:
    for d in _FONT_DIRS:
        if (Path(d) / name).exists():
            return Path(d) / name
    try:
        import matplotlib

        p = Path(matplotlib.__file__).parent / "mpl-data" / "fonts" / "ttf" / name
        return p if p.exists() else None
    except ImportError:
        return None


def _glyph(font_path: Path, ch: str, size: int) -> np.ndarray:
    from PIL import Image, ImageDraw, ImageFont

    font = ImageFont.truetype(str(font_path), size)
    im = Image.new("L", (2 * size, 2 * size), 255)
    ImageDraw.Draw(im).text((size // 3, size // 6), ch, font=font, fill=0)
    return np.asarray(im) < 128


def _package_images() -> dict[str, np.ndarray]:
    """Thresholded images that matplotlib ships (a photo, logos, DEMs as contour levels)."""
    out: dict[str, np.ndarray] = {}
    try:
        import matplotlib
    except ImportError:
        return out
    from PIL import Image

    from pde2cad.image.raster import to_mask

    sample = Path(matplotlib.__file__).parent / "mpl-data" / "sample_data"
    for name in ("grace_hopper.jpg", "logo2.png", "Minduka_Present_Blue_Pack.png"):
        if (sample / name).exists():
            out[Path(name).stem] = to_mask(np.asarray(Image.open(sample / name).convert("L")))
    for name, key in (("topobathy.npz", "topo"), ("jacksboro_fault_dem.npz", "elevation")):
        if (sample / name).exists():
            z = np.load(sample / name)[key].astype(float)
            for q in (0.3, 0.5, 0.7):  # contour-map-like level sets
                out[f"{Path(name).stem}_q{int(q * 100)}"] = z > np.quantile(z, q)
    return out


def _skimage_images() -> dict[str, np.ndarray]:
    """The PNG/JPEG images bundled in an installed scikit-image wheel (skimage/data; found
    without importing skimage), greyscale, downscaled to about 128 px and thresholded by Otsu."""
    import importlib.util

    from PIL import Image

    from pde2cad.image.raster import to_mask

    spec = importlib.util.find_spec("skimage")
    if spec is None or not spec.submodule_search_locations:
        return {}
    folder = Path(list(spec.submodule_search_locations)[0]) / "data"
    out: dict[str, np.ndarray] = {}
    for p in sorted([*folder.glob("*.png"), *folder.glob("*.jpg")]):
        im = Image.open(p).convert("L")
        scale = 128 / max(im.size)
        grey = np.asarray(im.resize((max(1, round(im.width * scale)), max(1, round(im.height * scale))), Image.LANCZOS))
        mask = to_mask(grey)
        if 0.02 < mask.mean() < 0.98:
            out[p.stem] = mask
    return out


#: Font Awesome 4.7 (Debian fonts-font-awesome): 675 pictograms, a public clip-art set.
_ICON_FONTS = ("/usr/share/fonts/truetype/font-awesome/fontawesome-webfont.ttf",
               "/usr/share/fonts-font-awesome/fonts/fontawesome-webfont.ttf")
_ICONS = 116


def _icon_images() -> dict[str, np.ndarray]:
    """``_ICONS`` Font Awesome pictograms (every few code points of U+F000..U+F2E0 that
    draw something), each at its own native size of 31-97 px (drawn at that size, as an
    icon is), padded by 4 px."""
    from PIL import Image, ImageDraw, ImageFont

    path = next((Path(p) for p in _ICON_FONTS if Path(p).exists()), None)
    if path is None:
        return {}
    rng = np.random.default_rng(7)
    probe = ImageFont.truetype(str(path), 64)
    codes = [c for c in range(0xF000, 0xF2E1) if probe.getbbox(chr(c))[2] > probe.getbbox(chr(c))[0]]
    picks = [codes[i] for i in np.linspace(0, len(codes) - 1, min(_ICONS, len(codes))).astype(int)]
    out: dict[str, np.ndarray] = {}
    for code in picks:
        size = int(rng.integers(31, 98))
        font = ImageFont.truetype(str(path), size)
        x0, y0, x1, y1 = font.getbbox(chr(code))
        im = Image.new("L", (x1 - x0 + 8, y1 - y0 + 8), 255)
        ImageDraw.Draw(im).text((4 - x0, 4 - y0), chr(code), font=font, fill=0)
        mask = np.asarray(im) < 128
        if mask.any():
            out[f"fa{code:04x}_{size}"] = mask
    return out


def _salt_pepper(mask: np.ndarray, rate: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return mask ^ (rng.random(mask.shape) < rate)


def make_unseen_sets(folder: Path) -> dict[str, list[Path]]:
    """Write the unseen image sets as PNGs into ``folder``; returns set name -> files.

    Sets: ``glyphs`` (15 characters x 4 fonts at 64 px), ``glyphs_4x`` (a third of them
    upscaled 4x by pixel replication: staircase edges), ``icons`` and ``icons_4x`` (116
    Font Awesome pictograms at native sizes of 31-97 px, and the same upscaled 4x: clip-art), ``packages`` (matplotlib's sample
    images thresholded by Otsu, DEM level sets), ``noisy`` (glyphs and package images with
    0.5 % salt-and-pepper pixels).
    """
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    sets: dict[str, list[Path]] = {"glyphs": [], "glyphs_4x": [], "icons": [], "icons_4x": [], "packages": [],
                                   "skimage": [], "noisy": []}

    def save(kind: str, name: str, mask: np.ndarray) -> None:
        p = folder / f"{kind}__{name}.png"
        Image.fromarray(np.where(mask, 0, 255).astype(np.uint8)).save(p)
        sets[kind].append(p)

    glyphs = []
    for font in _FONTS:
        path = _find_font(font)
        if path is None:
            continue
        for ch in _GLYPHS:
            glyphs.append((f"{Path(font).stem}_{ord(ch)}", _glyph(path, ch, 64)))
    for i, (name, m) in enumerate(glyphs):
        save("glyphs", name, m)
        if i % 3 == 0:
            save("glyphs_4x", name, np.kron(m, np.ones((4, 4), bool)))
        if i % 4 == 0:
            save("noisy", name, _salt_pepper(m, 0.005, i))
    for name, m in _icon_images().items():
        save("icons", name, m)
        save("icons_4x", name, np.kron(m, np.ones((4, 4), bool)))
    for i, (name, m) in enumerate(_package_images().items()):
        save("packages", name, m)
        save("noisy", name, _salt_pepper(m, 0.005, 100 + i))
    for name, m in _skimage_images().items():
        save("skimage", name, m)
    return {k: v for k, v in sets.items() if v}


def set_summary(name: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rows if "ours_segments" in r]
    pot = sum(r["potrace_segments"] for r in ok)
    return {
        "set": name,
        "images": len(rows),
        "failed": len(rows) - len(ok),
        "potrace_segments": int(pot),
        "ours_segments": int(sum(r["ours_segments"] for r in ok)),
        "ratio": sum(r["ours_segments"] for r in ok) / max(pot, 1),
        "images_above_potrace": sum(r["ours_segments"] > r["potrace_segments"] for r in ok),
        "ours_max_boundary_to_curve": max((r["ours_max_error"] for r in ok), default=0.0),
        "ours_max_curve_to_boundary": max((r["ours_max_curve_to_boundary"] for r in ok), default=0.0),
        "potrace_max_error": max((r["potrace_max_error"] for r in ok), default=0.0),
        "ours_mean_time_s": float(np.mean([r["ours_time_s"] for r in ok])) if ok else 0.0,
        "potrace_mean_time_s": float(np.mean([r["potrace_time_s"] for r in ok])) if ok else 0.0,
    }


def print_set_summary(s: dict[str, Any]) -> None:
    print(
        f"SET {s['set']:10s} {s['images']:3d} images ({s['failed']} failed): segments ours"
        f" {s['ours_segments']} / potrace {s['potrace_segments']} = {s['ratio']:.3f}"
        f" ({s['images_above_potrace']} images above potrace); max dist boundary->curve"
        f" {s['ours_max_boundary_to_curve']:.3f}, curve->boundary {s['ours_max_curve_to_boundary']:.3f}"
        f" (potrace {s['potrace_max_error']:.3f}) px; mean time ours {s['ours_mean_time_s']:.3f} s,"
        f" potrace {s['potrace_mean_time_s']:.3f} s",
        flush=True,
    )
    if "batch" in s:
        b = s["batch"]
        print(f"    batch ({b['jobs']} workers, start-up included): ours {b['ours_s_per_image']:.3f} s per image,"
              f" potrace loop {b['potrace_s_per_image']:.3f} s per image (x{b['time_ratio']:.1f})", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "images", nargs="*", type=Path, help="image files (default: examples/images/*.png)"
    )
    ap.add_argument("--tolerance", type=float, default=1.0)
    ap.add_argument("--ratio", type=float, default=0.55, help="segment ratio flagged above this")
    ap.add_argument("--repeat", type=int, default=1, help="timed runs of ours (best is kept)")
    ap.add_argument(
        "--timeout",
        type=float,
        default=300.0,
        help="seconds per vectorize call before it is killed and the image marked failed"
        " (runs in a forked child; 0 = in process, no limit)",
    )
    ap.add_argument("--potrace-only", action="store_true")
    ap.add_argument("--unseen", type=Path, metavar="DIR",
                    help="write the unseen image sets (fonts, package images, noisy copies) into"
                    " DIR and report each set")
    ap.add_argument("--no-nosym", action="store_true", help="skip the symmetry=False run (faster)")
    ap.add_argument("--sets", default="", metavar="A,B",
                    help="with --unseen: only these sets (default all), e.g. icons,icons_4x")
    ap.add_argument("--batch-jobs", type=int, default=2, metavar="N",
                    help="with --unseen: also time one batch call per set with N workers (0: skip)")
    ap.add_argument("--json", type=Path, help="write all numbers to this JSON file")
    args = ap.parse_args(argv)

    if shutil.which("potrace") is None:
        print("potrace is not installed (Debian package potrace)", file=sys.stderr)
        return 2
    if args.unseen is not None:
        return run_unseen(args)
    images = args.images or sorted((ROOT / "examples" / "images").glob("*.png"))
    if not images:
        print("no images", file=sys.stderr)
        return 2
    vectorize = None if args.potrace_only else get_vectorize()
    if vectorize is None and not args.potrace_only:
        print("pde2cad.vectorize is not available: potrace only\n", file=sys.stderr)
    ours = vectorize is not None

    head = table_header(ours)
    print(head)
    print("-" * len(head), flush=True)
    rows = []
    for p in images:  # print each row as soon as it is done
        rows.append(bench_image(p, vectorize, args.tolerance, args.repeat, args.ratio, args.timeout))
        print(table_row(rows[-1], ours), flush=True)
    tot = totals(rows, ours)
    print()
    if ours and "ours_segments" in tot:
        print(
            f"TOTAL segments ({len(rows) - tot['failed']} images vectorized):"
            f" potrace {tot['potrace_segments_ok']}, ours {tot['ours_segments']}"
            f" (ratio {tot['ratio']:.3f}), fitted (symmetric parts once) {tot['ours_fitted']},"
            f" ours without symmetry {tot['ours_nosym_segments']}"
        )
        print(
            f"max error: ours {tot['ours_max_error']:.4f} px,"
            f" potrace {tot['potrace_max_error']:.4f} px"
            f" | time: ours {tot['ours_time_s']:.2f} s, potrace {tot['potrace_time_s']:.2f} s"
            f" (x{tot['time_ratio']:.1f})"
        )
        if tot["flagged"] or tot["failed"]:
            print("flagged:", ", ".join(tot["flagged"]))
    else:
        print(
            f"TOTAL potrace segments {tot['potrace_segments']}, max error"
            f" {tot['potrace_max_error']:.4f} px, time {tot['potrace_time_s']:.2f} s"
        )
    if args.json:
        out = {"tolerance": args.tolerance, "rows": rows, "totals": tot}
        args.json.write_text(json.dumps(out, indent=1))
    return 0


def time_batch(paths: list[Path], jobs: int = 2) -> dict[str, float]:
    """Wall time of one ``pde2cad vectorize IMAGES --out-dir --jobs`` call (start-up
    included) beside potrace run on each image in a loop, both per image."""
    import subprocess
    import tempfile

    from pde2cad.image.evaluate import write_pbm

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "pde2cad.cli", "vectorize", *map(str, paths), "--out-dir", tmp,
                        "--jobs", str(jobs)], check=True, capture_output=True)
        ours = time.perf_counter() - t0
        pbms = [Path(tmp) / f"{i}.pbm" for i in range(len(paths))]
        for p, pbm in zip(paths, pbms):
            write_pbm(load_mask(p), pbm)
        t0 = time.perf_counter()
        for pbm in pbms:
            subprocess.run(["potrace", "-s", str(pbm), "-o", str(pbm.with_suffix(".svg"))], check=True)
        theirs = time.perf_counter() - t0
    n = max(len(paths), 1)
    return {"images": len(paths), "jobs": jobs, "ours_s_per_image": ours / n, "potrace_s_per_image": theirs / n,
            "time_ratio": ours / max(theirs, 1e-9)}


def run_unseen(args: argparse.Namespace) -> int:
    """Benchmark every unseen set; print the rows, then one summary line per set."""
    vectorize = get_vectorize()
    sets = make_unseen_sets(args.unseen)
    if args.sets:
        wanted = {n.strip() for n in args.sets.split(",") if n.strip()}
        sets = {k: v for k, v in sets.items() if k in wanted}
    head = table_header(True)
    summaries, all_rows = [], {}
    for name, paths in sets.items():
        print(f"\n== {name} ==\n{head}\n" + "-" * len(head), flush=True)
        rows = []
        for p in paths:
            rows.append(bench_image(p, vectorize, args.tolerance, args.repeat, args.ratio, args.timeout,
                                    with_nosym=not args.no_nosym))
            print(table_row(rows[-1], True), flush=True)
        summaries.append(set_summary(name, rows))
        if args.batch_jobs > 0:
            summaries[-1]["batch"] = time_batch(paths, args.batch_jobs)
        all_rows[name] = rows
    print()
    for s in summaries:
        print_set_summary(s)
    if args.json:
        for rows in all_rows.values():
            for r in rows:
                r.pop("traceback", None)
        args.json.write_text(json.dumps({"tolerance": args.tolerance, "sets": summaries, "rows": all_rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
