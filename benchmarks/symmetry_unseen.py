"""Does symmetry find symmetric shapes it never saw, and does it pay for itself?

Usage (from a plain checkout, with the project's venv python)::

    python benchmarks/symmetry_unseen.py              # every shape class
    python benchmarks/symmetry_unseen.py --only gear  # names containing "gear"

Shapes are generated here, thresholded at pixel centres (no anti-aliasing), at several
sizes, rotations and off-grid centres: analytic hearts, n-fold stars, florettes and gears
(polar curves), six-armed snowflakes (thick segments), and DejaVu glyphs (symmetric H V X
O A W M; non-symmetric controls F G R P). Per shape: the symmetry found on the largest
loop, independent curves with and without symmetry, the written curves, the symmetric
distance max(boundary -> curves, curves -> boundary) measured from the mask by
:func:`pde2cad.image.evaluate.outline_error`, and the time symmetry adds.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import pde2cad  # noqa: E402
from pde2cad.image.evaluate import outline_error  # noqa: E402

Mask = NDArray[np.bool_]
FONT_DIR = Path("/usr/share/fonts/truetype/dejavu")


def _polar(size: int, turn: float, centre: tuple[float, float], radius: Callable) -> Mask:
    """Pixels whose centre lies inside ``r <= radius(theta)`` about an off-grid centre."""
    y, x = np.mgrid[0:size, 0:size] + 0.5
    dx, dy = x - centre[0] * size, y - centre[1] * size
    return np.hypot(dx, dy) <= radius(np.arctan2(dy, dx) - turn)


def heart(size: int, turn: float) -> Mask:
    y, x = np.mgrid[0:size, 0:size] + 0.5
    c, s = np.cos(turn), np.sin(turn)
    dx, dy = x - 0.493 * size, y - 0.527 * size
    u, v = (dx * c + dy * s) / (0.3 * size), -(-dx * s + dy * c) / (0.3 * size)
    return (u * u + v * v - 1.0) ** 3 - u * u * v**3 <= 0.0


def star(n: int) -> Callable[[int, float], Mask]:
    return lambda size, turn: _polar(size, turn, (0.503, 0.496), lambda t: size * (0.28 + 0.12 * np.cos(n * t)))


def florette(n: int) -> Callable[[int, float], Mask]:
    return lambda size, turn: _polar(
        size, turn, (0.497, 0.508), lambda t: size * (0.18 + 0.22 * np.abs(np.cos(n * t / 2.0)) ** 0.7))


def gear(n: int) -> Callable[[int, float], Mask]:
    return lambda size, turn: _polar(
        size, turn, (0.506, 0.493), lambda t: size * (0.33 + 0.05 * np.tanh(3.0 * np.sin(n * t))))


def snowflake(size: int, turn: float) -> Mask:
    """Six arms, each with two side branches: a union of thick segments."""
    y, x = np.mgrid[0:size, 0:size] + 0.5
    cx, cy = 0.502 * size, 0.497 * size
    pts = np.stack([x - cx, y - cy], axis=-1)
    out = np.zeros((size, size), bool)
    arm, width = 0.42 * size, 0.035 * size
    for k in range(6):
        a = turn + k * np.pi / 3.0
        d = np.array([np.cos(a), np.sin(a)])
        segs = [(np.zeros(2), arm * d)]
        for f, side in ((0.55, 1), (0.55, -1)):
            base = f * arm * d
            b = a + side * np.pi / 4.0
            segs.append((base, base + 0.18 * size * np.array([np.cos(b), np.sin(b)])))
        for p, q in segs:
            v = q - p
            t = np.clip(((pts - p) @ v) / (v @ v), 0.0, 1.0)
            out |= np.linalg.norm(pts - p - t[..., None] * v, axis=-1) <= width
    return out


def glyph(font: str, ch: str) -> Callable[[int, float], Mask]:
    def make(size: int, turn: float) -> Mask:
        from PIL import Image, ImageDraw, ImageFont

        im = Image.new("L", (2 * size, 2 * size), 255)
        ImageDraw.Draw(im).text((size // 2, size // 4), ch, font=ImageFont.truetype(str(FONT_DIR / font), size), fill=0)
        im = im.rotate(np.degrees(turn), resample=Image.NEAREST, fillcolor=255)
        return np.asarray(im) < 128
    return make


def cases() -> Iterator[tuple[str, str, Callable[[int, float], Mask], int, float]]:
    """(class, name, maker, size, rotation) for every benchmark shape."""
    shapes: list[tuple[str, str, Callable]] = [("heart", "heart", heart), ("snowflake", "snowflake6", snowflake)]
    shapes += [("star", f"star{n}", star(n)) for n in (5, 7)]
    shapes += [("florette", f"florette{n}", florette(n)) for n in (6, 9)]
    shapes += [("gear", f"gear{n}", gear(n)) for n in (12, 20)]
    for ch in "HVXOAWM":
        shapes.append(("glyph", f"Sans-{ch}", glyph("DejaVuSans.ttf", ch)))
    shapes.append(("glyph", "SerifBold-H", glyph("DejaVuSerif-Bold.ttf", "H")))
    for ch in "FGRP":
        shapes.append(("control", f"Sans-{ch}", glyph("DejaVuSans.ttf", ch)))
    for cls, name, make in shapes:
        sizes = (90, 160) if cls in ("glyph", "control") else (120, 260)
        for size in sizes:
            for turn in (0.0, 0.37):
                yield cls, name, make, size, turn


def measure(mask: Mask) -> dict:
    """Both fits of one mask and their independent distances."""
    t0 = time.perf_counter()
    plain = pde2cad.vectorize(mask, 1.0, symmetry=False)
    t1 = time.perf_counter()
    sym = pde2cad.vectorize(mask, 1.0)
    t2 = time.perf_counter()
    err = outline_error(mask, [lp.curves for lp in sym.loops])
    outer = max(sym.loops, key=lambda lp: len(lp.curves))
    return {
        "symmetry": outer.symmetry or "-",
        "loops_sym": sum(lp.symmetry is not None for lp in sym.loops),
        "fitted": sym.n_fitted_curves,
        "plain": plain.n_curves,
        "written": sym.n_curves,
        "dist": max(err["max_boundary_to_curve"], err["max_curve_to_boundary"]),
        "extra_ms": 1e3 * ((t2 - t1) - (t1 - t0)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run only shapes whose name contains this")
    args = ap.parse_args()
    print(f"{'class':9} {'shape':12} {'size':>4} {'rot':>4} {'symmetry':11} {'nsym':>4} "
          f"{'fitted':>6} {'plain':>5} {'written':>7} {'dist':>6} {'+ms':>6}")
    summary: dict[str, list[int]] = {}
    for cls, name, make, size, turn in cases():
        if args.only not in name:
            continue
        r = measure(make(size, turn))
        ok = r["dist"] <= 1.05
        gain = r["fitted"] < r["plain"]
        s = summary.setdefault(cls, [0, 0, 0])
        s[0] += 1
        s[1] += int(gain if cls != "control" else r["symmetry"] == "-")
        s[2] += int(ok)
        flag = ("" if ok else " E") + ("" if (gain or cls == "control") else " S")
        print(f"{cls:9} {name:12} {size:4d} {turn:4.2f} {r['symmetry']:11} {r['loops_sym']:4d} {r['fitted']:6d} "
              f"{r['plain']:5d} {r['written']:7d} {r['dist']:6.3f} {r['extra_ms']:6.0f}{flag}", flush=True)
    print("\nclass      cases  gained(controls: none found)  within 1.05 px")
    for cls, (n, g, ok) in summary.items():
        print(f"{cls:9} {n:6d} {g:6d} {ok:6d}")


if __name__ == "__main__":
    main()
