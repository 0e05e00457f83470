"""SVG export of a :class:`~pde2cad.image.drawing.Drawing`.

One ``<path>`` per shape (outer loop plus its holes) with ``fill-rule="evenodd"``, so holes
render as holes whatever their orientation. Every loop is ``M x0 y0 C ... Z`` with exactly
one cubic ``C`` command per Bézier, so the file holds the fitted curves themselves, not a
flattened copy. Coordinates stay in pixels (the viewBox); a physical scale only changes the
``width``/``height`` attributes (in mm), which keeps the coordinates exact.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pde2cad.errors import ExportError, InputError
from pde2cad.image.drawing import Drawing
from pde2cad.io.atomic import atomic_path

__all__ = ["svg_string", "write_svg", "format_number"]

_DECIMALS = 4


def quoteattr(value: str) -> str:
    """``value`` as a double-quoted XML attribute (``xml.sax.saxutils.quoteattr`` pulls in
    urllib, http and email: a quarter of the CLI's own start-up)."""
    escaped = value.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")
    return f'"{escaped}"'


def format_number(x: float, decimals: int = _DECIMALS) -> str:
    """Fixed-point text with trailing zeros stripped: 12.5000 -> "12.5", -0.00001 -> "0"."""
    s = f"{x:.{decimals}f}".rstrip("0").rstrip(".")
    # Rounding tiny negatives gives "-0"; SVG accepts it but it is noise in diffs.
    return "0" if s in ("-0", "") else s


def _loop_path(curves: NDArray[np.float64], is_line: list[bool] | None = None) -> str:
    """Path data ``M x0 y0 C x1 y1 x2 y2 x3 y3 ... L x3 y3 ... Z`` for a closed chain
    (K, 4, 2); curves flagged in ``is_line`` are written as straight ``L`` segments."""
    f = format_number
    flags = is_line or [False] * len(curves)
    parts = [f"M {f(curves[0, 0, 0])} {f(curves[0, 0, 1])}"]
    for c, straight in zip(curves, flags):
        if straight:
            parts.append(f"L {f(c[3, 0])} {f(c[3, 1])}")
        else:
            parts.append("C " + " ".join(f"{f(x)} {f(y)}" for x, y in c[1:]))
    parts.append("Z")
    return " ".join(parts)


def svg_string(drawing: Drawing, fill: str = "#000000", stroke: str | None = None) -> str:
    """The SVG document for ``drawing`` as text.

    Parameters
    ----------
    drawing : Drawing
        Loops of cubic Béziers ``(K, 4, 2)`` in pixel coordinates (x right, y down).
    fill : str
        Fill colour of the shapes (SVG colour syntax); "none" for outlines only.
    stroke : str or None
        Stroke colour; None (default) draws no stroke. The stroke width is 1 px.

    Returns
    -------
    str
        A complete SVG 1.1 document. ``viewBox="0 0 W H"`` is in pixels; when
        ``drawing.mm_per_px`` is set, ``width``/``height`` are in mm, else in px.
    """
    drawing.validate()
    f = format_number
    w, h = drawing.width, drawing.height
    if drawing.mm_per_px is not None:
        size = f'width="{f(w * drawing.mm_per_px)}mm" height="{f(h * drawing.mm_per_px)}mm"'
    else:
        size = f'width="{w}" height="{h}"'
    style = f"fill={quoteattr(fill)} fill-rule=\"evenodd\" stroke={quoteattr(stroke or 'none')}"
    if stroke is not None:
        style += ' stroke-width="1"'
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" {size} viewBox="0 0 {w} {h}">',
    ]
    for shape in drawing.shapes():
        loops = [lp for lp in shape if lp.n_curves > 0]
        if not loops:
            continue
        d = " ".join(_loop_path(np.asarray(lp.curves, dtype=float), lp.is_line) for lp in loops)
        lines.append(f'  <path d="{d}" {style}/>')
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


def write_svg(
    drawing: Drawing, path: str | Path, fill: str = "#000000", stroke: str | None = None
) -> None:
    """Write ``drawing`` as an SVG file (see :func:`svg_string`).

    The file is written atomically: on any failure ``path`` is left untouched.

    Raises
    ------
    InputError
        The drawing holds NaN coordinates or a bad size/scale.
    ExportError
        The folder does not exist or the file cannot be written.
    """
    text = svg_string(drawing, fill=fill, stroke=stroke)
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except ExportError:
        raise
    except OSError as exc:
        raise ExportError(
            f"cannot write SVG {path}: {exc}; check the path and permissions"
        ) from exc
