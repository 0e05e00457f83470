"""Generate the test-image corpus in this folder (binary PNGs, black shapes on white).

Run ``python examples/images/make_images.py`` to (re)write the PNGs next to this script. The
output is deterministic (fixed seeds); glyphs use DejaVu Sans/Serif when found under
/usr/share/fonts, otherwise Pillow's built-in scalable font, so glyph images can differ
between machines: the committed PNGs are the reference.

Analytic shapes are rasterized by sampling pixel centres (pixel (i, j) is foreground when the
point (j + 0.5, i + 0.5) lies inside, even-odd rule), so mirror-symmetric shapes are exactly
symmetric on the pixel grid; rotationally symmetric ones are symmetric up to pixelization.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFilter, ImageFont

HERE = Path(__file__).resolve().parent
Mask = NDArray[np.bool_]
Poly = NDArray[np.float64]  # (N, 2) closed polygon, x right, y down

# ----------------------------------------------------------------------------------------------
# Rasterization helpers
# ----------------------------------------------------------------------------------------------


def fill(polys: list[Poly], width: int, height: int) -> Mask:
    """Even-odd fill of closed polygons, sampled at pixel centres (scanline, numpy only)."""
    mask = np.zeros((height, width), dtype=bool)
    ys = np.arange(height) + 0.5
    xs = np.arange(width) + 0.5
    segs = []
    for p in polys:
        p = np.asarray(p, dtype=float)
        segs.append(np.stack([p, np.roll(p, -1, axis=0)], axis=1))
    if not segs:
        return mask
    s = np.concatenate(segs)  # (E, 2, 2)
    x0, y0, x1, y1 = s[:, 0, 0], s[:, 0, 1], s[:, 1, 0], s[:, 1, 1]
    for i, y in enumerate(ys):
        hit = (y0 <= y) != (y1 <= y)  # half-open rule: each crossing counted once
        if not hit.any():
            continue
        xc = x0[hit] + (y - y0[hit]) * (x1[hit] - x0[hit]) / (y1[hit] - y0[hit])
        count = (xc[None, :] < xs[:, None]).sum(axis=1)
        mask[i] = count % 2 == 1
    return mask


def circle(cx: float, cy: float, r: float, n: int = 720) -> Poly:
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.stack([cx + r * np.cos(th), cy + r * np.sin(th)], axis=1)


def ellipse(cx: float, cy: float, rx: float, ry: float, angle: float = 0.0, n: int = 720) -> Poly:
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    x, y = rx * np.cos(th), ry * np.sin(th)
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([cx + c * x - s * y, cy + s * x + c * y], axis=1)


def disc(w: int, h: int, cx: float, cy: float, r: float) -> Mask:
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    return (xx - cx) ** 2 + (yy - cy) ** 2 < r * r


def rounded_rect(x0: float, y0: float, x1: float, y1: float, r: float, n: int = 64) -> Poly:
    pts = []
    centres = (
        (x1 - r, y0 + r, -90),
        (x1 - r, y1 - r, 0),
        (x0 + r, y1 - r, 90),
        (x0 + r, y0 + r, 180),
    )
    for cx, cy, a0 in centres:
        th = np.radians(np.linspace(a0, a0 + 90, n))
        pts.append(np.stack([cx + r * np.cos(th), cy + r * np.sin(th)], axis=1))
    return np.concatenate(pts)


Radius = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def polar(cx: float, cy: float, radius: Radius, n: int = 2048) -> Poly:
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    r = radius(th)
    return np.stack([cx + r * np.cos(th), cy + r * np.sin(th)], axis=1)


def fourier_blob(
    seed: int, cx: float, cy: float, r0: float, harmonics: int = 5, amp: float = 0.35
) -> Poly:
    """A smooth random star-shaped closed curve (radius = Fourier series of the angle)."""
    rng = np.random.default_rng(seed)
    k = np.arange(1, harmonics + 1)
    a = rng.normal(size=harmonics) * amp / k**1.2
    b = rng.normal(size=harmonics) * amp / k**1.2

    def radius(th: NDArray[np.float64]) -> NDArray[np.float64]:  # exp keeps it simple (r > 0)
        return r0 * np.exp((a * np.cos(np.outer(th, k)) + b * np.sin(np.outer(th, k))).sum(axis=1))

    return polar(cx, cy, radius)


def fit_box(poly: Poly, x0: float, y0: float, x1: float, y1: float) -> Poly:
    """Scale (uniformly) and move a polygon so that its bounding box fits in the given box."""
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    s = min((x1 - x0) / (hi[0] - lo[0]), (y1 - y0) / (hi[1] - lo[1]))
    c_from, c_to = (lo + hi) / 2.0, np.array([x0 + x1, y0 + y1]) / 2.0
    return (poly - c_from) * s + c_to


def mirror_x(mask: Mask) -> Mask:
    """Make a mask exactly mirror-symmetric about its vertical centre line (left half wins)."""
    w = mask.shape[1]
    out = mask.copy()
    out[:, w - w // 2 :] = mask[:, : w // 2][:, ::-1]
    return out


def font(
    size: int, serif: bool = False, bold: bool = True
) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    name = ("DejaVuSerif" if serif else "DejaVuSans") + ("-Bold" if bold else "") + ".ttf"
    for root in (Path("/usr/share/fonts"), Path("/usr/local/share/fonts"), Path.home() / ".fonts"):
        hits = sorted(root.rglob(name)) if root.is_dir() else []
        if hits:
            return ImageFont.truetype(str(hits[0]), size)
    return ImageFont.load_default(size=size)


def text_mask(text: str, size: int, pad: int = 24, serif: bool = False) -> Mask:
    f = font(size, serif=serif)
    probe = ImageDraw.Draw(Image.new("L", (1, 1)))
    x0, y0, x1, y1 = probe.textbbox((0, 0), text, font=f)
    w, h = x1 - x0 + 2 * pad, y1 - y0 + 2 * pad
    im = Image.new("L", (w, h), 255)
    ImageDraw.Draw(im).text((pad - x0, pad - y0), text, font=f, fill=0)
    return np.asarray(im) < 128


# ----------------------------------------------------------------------------------------------
# The shapes
# ----------------------------------------------------------------------------------------------


def airplane() -> Mask:
    w, h = 480, 400
    fuselage = rounded_rect(222, 40, 258, 360, 18)
    wings = np.array([[240, 150], [440, 230], [440, 255], [240, 215], [40, 255], [40, 230]], float)
    tail = np.array([[240, 300], [310, 345], [310, 362], [240, 345], [170, 362], [170, 345]], float)
    m = fill([fuselage], w, h) | fill([wings], w, h) | fill([tail], w, h)
    m |= fill([ellipse(330, 215, 14, 34)], w, h) | fill([ellipse(150, 215, 14, 34)], w, h)
    m &= ~fill([ellipse(240, 80, 9, 16)], w, h)  # cockpit window (a hole)
    return m


def bird() -> Mask:
    w, h = 420, 320
    body = fourier_blob(7, 200, 170, 95, harmonics=6, amp=0.45)
    m = fill([body], w, h) | fill([ellipse(330, 110, 55, 30, angle=-0.5)], w, h)
    beak = np.array([[372, 88], [410, 92], [378, 110]], float)
    return m | fill([beak], w, h)


def heel() -> Mask:
    blob = fourier_blob(2024, 0, 0, 1, harmonics=8, amp=0.3)
    return fill([fit_box(blob, 30, 60, 370, 340)], 400, 400)


def glyph(ch: str, serif: bool = False) -> Mask:
    return text_mask(ch, 300, serif=serif)


def gear(
    w: int, teeth: int, r_root: float, r_tip: float, r_hole: float, flank: float = 0.3
) -> Mask:
    c = w / 2.0

    def radius(th: NDArray[np.float64]) -> NDArray[np.float64]:
        u = (th * teeth / (2.0 * np.pi)) % 1.0  # position within one tooth pitch
        # trapezoidal tooth: rise, top, fall, root
        rise = np.clip((u - 0.0) / flank * 4.0, 0.0, 1.0)
        fall = np.clip((0.5 + flank / 4.0 - u) / flank * 4.0, 0.0, 1.0)
        prof = np.minimum(rise, fall)
        return r_root + (r_tip - r_root) * prof

    m = fill([polar(c, c, radius, n=teeth * 240)], w, w)
    if r_hole > 0:
        m &= ~disc(w, w, c, c, r_hole)
    return m


def star(w: int, k: int, r_out: float, r_in: float, rot: float = -np.pi / 2) -> Mask:
    th = rot + np.arange(2 * k) * np.pi / k
    r = np.where(np.arange(2 * k) % 2 == 0, r_out, r_in)
    return fill([np.stack([w / 2 + r * np.cos(th), w / 2 + r * np.sin(th)], axis=1)], w, w)


def heart() -> Mask:
    w = 400
    t = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    x = 16 * np.sin(t) ** 3
    y = 13 * np.cos(t) - 5 * np.cos(2 * t) - 2 * np.cos(3 * t) - np.cos(4 * t)
    poly = np.stack([w / 2 + 11 * x, 185 - 11 * y], axis=1)
    return mirror_x(fill([poly], w, w))


def ring_with_holes() -> Mask:
    w = 400
    m = disc(w, w, 200, 200, 170) & ~disc(w, w, 200, 200, 70)
    for a in np.arange(6) * np.pi / 3 + 0.2:
        m &= ~disc(w, w, 200 + 120 * np.cos(a), 200 + 120 * np.sin(a), 26)
    return m


def arrow() -> Mask:
    poly = np.array(
        [[30, 130], [260, 130], [260, 60], [420, 170], [260, 280], [260, 210], [30, 210]], float
    )
    return fill([poly], 450, 340)


def yin_yang() -> Mask:
    w = 400
    c, r = 200.0, 180.0
    outer = disc(w, w, c, c, r)
    xx = np.arange(w)[None, :] + 0.5
    right = np.broadcast_to(xx > c, (w, w))
    dark = (outer & right & ~disc(w, w, c, c - r / 2, r / 2)) | disc(w, w, c, c + r / 2, r / 2)
    dark &= ~disc(w, w, c, c + r / 2, r / 7)
    dark |= disc(w, w, c, c - r / 2, r / 7)
    # a thin ring around everything so the light half is outlined too
    ring = disc(w, w, c, c, r + 10) & ~disc(w, w, c, c, r + 2)
    return dark | ring


def scanned_logo() -> Mask:
    w, h = 520, 300
    im = Image.new("L", (w, h), 255)
    d = ImageDraw.Draw(im)
    d.ellipse((20, 20, 280, 280), outline=0, width=22)
    d.text((150, 150), "P2C", font=font(72), fill=0, anchor="mm")
    d.text((300, 150), "CAD", font=font(80, serif=True), fill=0, anchor="lm")
    im = im.filter(ImageFilter.GaussianBlur(1.6))
    rng = np.random.default_rng(11)
    a = np.asarray(im, dtype=float) + rng.normal(0.0, 12.0, size=(h, w))
    im = Image.fromarray(np.clip(a, 0, 255).astype(np.uint8))
    a = np.asarray(im.filter(ImageFilter.GaussianBlur(0.7)))
    return a < 128


def noisy_blob() -> Mask:
    """A smooth blob whose boundary pixels are flipped at random (bumps and notches, no specks)."""
    w = 400
    m = fill([fit_box(fourier_blob(5, 0, 0, 1, harmonics=4, amp=0.3), 40, 40, 360, 360)], w, w)
    p = np.pad(m, 1)
    nb_bg = ~p[:-2, 1:-1] | ~p[2:, 1:-1] | ~p[1:-1, :-2] | ~p[1:-1, 2:]
    nb_fg = p[:-2, 1:-1] | p[2:, 1:-1] | p[1:-1, :-2] | p[1:-1, 2:]
    band = (m & nb_bg) | (~m & nb_fg)  # pixels 4-adjacent to the other class
    rng = np.random.default_rng(3)
    flip = band & (rng.random(m.shape) < 0.12)
    return m ^ flip


def vase() -> Mask:
    w, h = 300, 460
    y = np.linspace(30, 430, 800)
    u = (y - 30) / 400
    belly = 55 * np.sin(np.pi * (u * 1.15 + 0.05)) ** 2
    half = 40 + belly + 25 * np.exp(-(((u - 0.9) / 0.06) ** 2))
    half = np.where(u < 0.06, 62 - 200 * u, half)  # lip
    right = np.stack([w / 2 + half, y], axis=1)
    left = np.stack([w / 2 - half[::-1], y[::-1]], axis=1)
    m = fill([np.concatenate([right, left])], w, h)
    return mirror_x(m)


def propeller() -> Mask:
    w = 440
    c = w / 2
    m = disc(w, w, c, c, 46)
    for k in range(3):
        a = -np.pi / 2 + k * 2 * np.pi / 3
        blade = ellipse(c + 110 * np.cos(a), c + 110 * np.sin(a), 105, 36, angle=a + 0.25)
        m |= fill([blade], w, w)
    return m & ~disc(w, w, c, c, 16)


def nested() -> Mask:
    w = 420
    m = fill([rounded_rect(20, 20, 400, 400, 40)], w, w)
    m &= ~fill([rounded_rect(60, 60, 360, 360, 20)], w, w)
    m |= disc(w, w, 210, 210, 130) & ~disc(w, w, 210, 210, 90)
    # a diamond (with a round hole) inside the ring's hole
    sq = np.array([[210, 150], [270, 210], [210, 270], [150, 210]], float)
    m |= fill([sq], w, w) & ~disc(w, w, 210, 210, 18)
    return m


def target() -> Mask:
    w = 360
    m = np.zeros((w, w), bool)
    for r_out, r_in in ((170, 140), (115, 85), (60, 30)):
        m |= disc(w, w, 180, 180, r_out) & ~disc(w, w, 180, 180, r_in)
    return m | disc(w, w, 180, 180, 10)


def keyhole_plate() -> Mask:
    w, h = 480, 320
    m = fill([rounded_rect(20, 20, 460, 300, 30)], w, h)
    m &= ~disc(w, h, 240, 130, 40)
    m &= ~fill([np.array([[222, 140], [258, 140], [272, 250], [208, 250]], float)], w, h)
    for x in (60, 420):
        for y in (60, 260):
            m &= ~disc(w, h, x, y, 14)
    return m


def border_cropped() -> Mask:
    """A blob and a bar cut off by the image border (the border counts as boundary)."""
    w, h = 360, 300
    m = fill([fourier_blob(17, 40, 250, 130, harmonics=4, amp=0.25)], w, h)
    m |= fill([np.array([[200, -10], [370, -10], [370, 60], [200, 60]], float)], w, h)
    return m


def small_text() -> Mask:
    return text_mask("pde2cad 0.1 ~ tolerance", 36, pad=10, serif=False)


IMAGES: dict[str, Callable[[], Mask]] = {
    "silhouette_airplane": airplane,
    "silhouette_bird": bird,
    "silhouette_heel": heel,
    "glyph_a": lambda: glyph("a"),
    "glyph_g": lambda: glyph("g", serif=True),
    "glyph_B": lambda: glyph("B"),
    "glyph_S": lambda: glyph("S"),
    "glyph_ampersand": lambda: glyph("&", serif=True),
    "glyph_R": lambda: glyph("R", serif=True),
    "symbol_gear12": lambda: gear(400, 12, 150, 185, 50),
    "symbol_ring_holes": ring_with_holes,
    "symbol_arrow": arrow,
    "symbol_yinyang": yin_yang,
    "logo_scanned": scanned_logo,
    "noisy_blob": noisy_blob,
    "sym_mirror_heart": heart,
    "sym_mirror_vase": vase,
    "sym_rot_star5": lambda: star(400, 5, 185, 75),
    "sym_rot_gear6": lambda: gear(360, 6, 110, 160, 40, flank=0.35),
    "sym_rot_propeller3": propeller,
    "holes_nested": nested,
    "holes_target": target,
    "holes_keyhole_plate": keyhole_plate,
    "border_cropped": border_cropped,
    "text_small": small_text,
}


def save(mask: Mask, path: Path) -> None:
    """Write a mask as a 1-bit PNG: foreground black (0), background white (255)."""
    Image.fromarray(np.where(mask, 0, 255).astype(np.uint8)).convert("1").save(path, optimize=True)


def main(argv: list[str] | None = None) -> int:
    out = HERE
    names = argv if argv else list(IMAGES)
    for name in names:
        mask = IMAGES[name]()
        assert mask.shape[0] <= 600 and mask.shape[1] <= 600, name
        save(mask, out / f"{name}.png")
        print(f"{name:24s} {mask.shape[1]:4d}x{mask.shape[0]:<4d} fg={mask.mean():.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
