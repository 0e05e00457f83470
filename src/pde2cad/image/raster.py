"""Reading images and thresholding them into a boolean foreground mask.

The mask is ``True`` where the drawing is: by default the DARK pixels (ink on paper, the
potrace convention). Greyscale and colour images are reduced to 8-bit luminance (ITU-R 601,
the weights Pillow uses for mode "L") and thresholded, by Otsu's method unless the caller
gives a threshold. Transparent pixels are background: they are composited on white (or on
black when ``invert=True``, so that they stay background).

Memory stays bounded for images of 10^8 pixels: work is done on uint8 data in row blocks,
the histogram is a blocked ``bincount``, and no float64 copy of a whole image is made.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageOps, UnidentifiedImageError

from pde2cad.errors import InputError

__all__ = ["MAX_PIXELS", "otsu_threshold", "read_image", "to_mask"]

#: Largest image (width * height) :func:`read_image` accepts: a 20000 x 20000 drawing.
MAX_PIXELS = 400_000_000

# Pixels handled per block: 4 Mi pixels keep int32/float64 temporaries at ~32 MB.
_BLOCK_PIXELS = 1 << 22

_FORMATS = "PNG, BMP, PBM/PGM/PPM, JPEG, TIFF"


def read_image(
    path: str | Path, threshold: float | None = None, invert: bool = False
) -> NDArray[np.bool_]:
    """Read an image file and return its foreground mask.

    Parameters
    ----------
    path : str or Path
        A PNG, BMP, PBM/PGM/PPM, JPEG or TIFF file (anything Pillow reads). Multi-frame
        files use their first frame; an EXIF orientation tag is applied.
    threshold : float, optional
        Luminance cut in 0..255: pixels darker than ``threshold`` are foreground. Default:
        Otsu's threshold (see :func:`otsu_threshold`). Ignored for 1-bit images.
    invert : bool
        Make the LIGHT pixels foreground (white drawing on a dark background).

    Returns
    -------
    mask : (H, W) bool
        ``mask[i, j]`` is True when pixel row i, column j is foreground.

    Raises
    ------
    InputError
        Missing file, a file Pillow cannot read, an image larger than :data:`MAX_PIXELS`,
        or a threshold out of range.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file; check the path")
    if p.is_dir():
        raise InputError(f"{p} is a folder, not an image file; give the path of an image")
    old_limit = Image.MAX_IMAGE_PIXELS
    # Pillow refuses images above ~89 M pixels as possible decompression bombs; a
    # 10000 x 10000 scan is a legitimate input, so raise the limit for this call only and
    # do the size check ourselves (with a message that says what to do).
    Image.MAX_IMAGE_PIXELS = MAX_PIXELS
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            try:
                im = Image.open(p)
            except UnidentifiedImageError:
                raise InputError(
                    f"{p} is not an image Pillow can read ({_FORMATS}); "
                    "convert it to PNG first"
                ) from None
            except Image.DecompressionBombError:
                raise _too_large(p, None) from None
            except OSError as exc:
                raise InputError(f"{p}: cannot open ({exc}); check the file permissions") from None
            with im:
                width, height = im.size
                if width * height > MAX_PIXELS:
                    raise _too_large(p, (width, height))
                try:
                    im.load()
                    return _mask_from_pil(_apply_exif_orientation(im), threshold, invert)
                except (OSError, SyntaxError) as exc:
                    # Truncated or corrupt data surfaces from the decoders as OSError.
                    raise InputError(
                        f"{p} is truncated or corrupt ({exc}); re-export the image"
                    ) from None
    finally:
        Image.MAX_IMAGE_PIXELS = old_limit


def to_mask(
    image: NDArray[Any] | Image.Image, threshold: float | None = None, invert: bool = False
) -> NDArray[np.bool_]:
    """Turn an image array (or a Pillow image) into a foreground mask.

    Parameters
    ----------
    image : (H, W), (H, W, C) array or PIL.Image.Image
        - bool (H, W): already a mask (True = foreground); only ``invert`` applies.
        - integer: 0..255 (8-bit); uint16 arrays, and other integer arrays with values
          above 255, are 16-bit (0..65535) and are scaled to 8 bits first.
        - float: 0..1.
        C is 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA). Alpha 0 is transparent.
    threshold : float, optional
        Luminance cut: pixels with luminance < ``threshold`` are foreground (with
        ``invert``, pixels with luminance >= ``threshold``). In 0..255 for integer and PIL
        images, in 0..1 for float arrays. Default: Otsu's threshold; for a constant image,
        where Otsu is undefined, 128 (0.5 for floats).
    invert : bool
        Light pixels are foreground. Exactly the complement of the default mask, except
        that transparent pixels stay background.

    Returns
    -------
    mask : (H, W) bool
        True where the image is foreground.

    Raises
    ------
    InputError
        Wrong number of dimensions or channels, empty image, NaN or infinite values,
        values out of range, or a threshold out of range.
    """
    if isinstance(image, Image.Image):
        return _mask_from_pil(image, threshold, invert)
    arr = np.asarray(image)
    return _mask_from_array(arr, threshold, invert)


def otsu_threshold(histogram: NDArray[np.integer[Any]] | NDArray[np.floating[Any]]) -> int | None:
    """Otsu's threshold of a 256-bin luminance histogram.

    Parameters
    ----------
    histogram : (256,) int or float
        Pixel counts per luminance level 0..255.

    Returns
    -------
    t : int or None
        The cut maximising the between-class variance, as the first level of the light
        class: dark pixels (foreground by default) are those with luminance < ``t``,
        1 <= t <= 255. None when the image has a single grey level (Otsu is undefined).
    """
    h = np.asarray(histogram, dtype=np.float64)
    if h.shape != (256,):
        raise InputError(f"histogram must have 256 bins, got shape {h.shape}")
    total = h.sum()
    if total <= 0:
        return None
    p = h / total
    omega = np.cumsum(p)  # weight of the dark class {0..k}
    mu = np.cumsum(p * np.arange(256))  # its (unnormalised) mean
    mu_t = mu[-1]
    denom = omega * (1.0 - omega)
    # Cuts with an empty class are not cuts; 1e-12 guards rounding in 1 - omega.
    valid = denom > 1e-12
    if not np.any(valid):
        return None
    sigma_b = np.zeros(256)
    sigma_b[valid] = (mu_t * omega[valid] - mu[valid]) ** 2 / denom[valid]
    best = sigma_b.max()
    # Between two occupied levels the variance is flat; take the middle of the plateau so
    # that the cut sits halfway between the two modes rather than hugging the dark one.
    ks = np.flatnonzero(valid & (sigma_b >= best * (1.0 - 1e-12)))
    k = int(ks[0] + (ks[-1] - ks[0]) // 2) if np.all(np.diff(ks) == 1) else int(ks[0])
    return k + 1


# --------------------------------------------------------------------------------------
# Internals
# --------------------------------------------------------------------------------------


def _too_large(path: Path, size: tuple[int, int] | None) -> InputError:
    what = f"{size[0]} x {size[1]} pixels" if size else "too many pixels"
    return InputError(
        f"{path} has {what}, more than the limit of {MAX_PIXELS:,} pixels; "
        "downscale the image first"
    )


def _apply_exif_orientation(im: Image.Image) -> Image.Image:
    """Rotate a camera JPEG upright; a no-op (no copy) for images without the tag."""
    try:
        orientation = im.getexif().get(0x0112, 1)
    except Exception:  # noqa: BLE001 - a broken EXIF block must not stop the trace
        return im
    if orientation in (None, 1):
        return im
    return ImageOps.exif_transpose(im)


def _mask_from_pil(im: Image.Image, threshold: float | None, invert: bool) -> NDArray[np.bool_]:
    """Foreground mask of a Pillow image; see :func:`to_mask`."""
    _check_threshold(threshold, 255.0)
    if im.width * im.height == 0:
        raise InputError("the image is empty (0 pixels); give an image with content")
    mode = im.mode
    if mode == "1":
        # A bilevel image is already a mask: black (0) is ink. No thresholding.
        white = np.asarray(im, dtype=bool)
        return white.copy() if invert else ~white
    has_alpha = "A" in im.getbands() or "a" in im.getbands() or "transparency" in im.info
    if has_alpha:
        if mode not in ("LA", "La"):
            im = im.convert("RGBA")
        # "LA" keeps alpha beside the ITU-R 601 luminance; the composite onto the
        # background is done in numpy blocks (luminance is linear, so the order of
        # luminance and compositing does not matter).
        arr = np.asarray(im.convert("LA") if im.mode != "LA" else im)
        return _mask_from_array(arr, threshold, invert)
    if mode in ("I", "I;16", "I;16B", "I;16L", "I;16N"):
        return _mask_from_array(np.asarray(im), threshold, invert)
    if mode == "F":
        arr32 = np.asarray(im, dtype=np.float32)
        if not np.all(np.isfinite(arr32)):
            raise InputError("the float image contains NaN or infinite values; fix the file")
        # Float TIFFs come as 0..1 or as 0..255 / 0..65535 counts; map them to 8 bits.
        top = float(arr32.max())
        scale = 1.0 if top <= 1.0 else (255.0 if top <= 255.0 else 65535.0)
        return _mask_from_array(_float_to_u8(arr32, scale), threshold, invert)
    # convert("L") on an "L" image would be a needless full copy.
    grey = im if mode == "L" else im.convert("L")
    return _mask_from_array(np.asarray(grey), threshold, invert)


def _check_threshold(threshold: float | None, top: float) -> None:
    if threshold is None:
        return
    if isinstance(threshold, (bool, np.bool_)) or not isinstance(
        threshold, (int, float, np.integer, np.floating)
    ):
        raise InputError(f"threshold must be a number in 0..{top:g}, got {threshold!r}")
    if not math.isfinite(float(threshold)) or not 0.0 <= float(threshold) <= top:
        hint = " (float images use 0..1)" if top == 1.0 else " (8-bit luminance)"
        raise InputError(
            f"threshold {threshold!r} is out of range 0..{top:g}{hint}; "
            f"give a value between 0 and {top:g}"
        )


def _row_blocks(height: int, width: int) -> Iterator[slice]:
    rows = max(1, _BLOCK_PIXELS // max(width, 1))
    for r0 in range(0, height, rows):
        yield slice(r0, min(height, r0 + rows))


def _float_to_u8(arr: NDArray[np.floating[Any]], scale: float) -> NDArray[np.uint8]:
    """Quantize ``arr / scale`` (in 0..1) to uint8 levels, block by block."""
    out = np.empty(arr.shape, dtype=np.uint8)
    for sl in _row_blocks(arr.shape[0], int(np.prod(arr.shape[1:], dtype=np.int64))):
        out[sl] = np.rint(np.clip(arr[sl] * (255.0 / scale), 0.0, 255.0))
    return out


def _mask_from_array(
    arr: NDArray[Any], threshold: float | None, invert: bool
) -> NDArray[np.bool_]:
    """Foreground mask of an (H, W) or (H, W, C) array; see :func:`to_mask`."""
    if arr.ndim not in (2, 3):
        raise InputError(
            f"an image array must be 2-D (H, W) or 3-D (H, W, C), got {arr.ndim}-D with "
            f"shape {arr.shape}; select one image or channel"
        )
    if arr.ndim == 3 and arr.shape[2] not in (1, 2, 3, 4):
        raise InputError(
            f"an image array must have 1 (grey), 2 (grey+alpha), 3 (RGB) or 4 (RGBA) "
            f"channels in its last axis, got shape {arr.shape}"
        )
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InputError(f"the image is empty (shape {arr.shape}); give an image with content")
    kind = arr.dtype.kind
    if kind == "b":
        if arr.ndim == 3 and arr.shape[2] == 1:
            arr = arr[:, :, 0]
        if arr.ndim != 2:
            raise InputError(
                f"a boolean mask must be 2-D (H, W), got shape {arr.shape}; "
                "combine the channels first"
            )
        return ~arr if invert else arr.copy()
    if kind == "f":
        _check_threshold(threshold, 1.0)
        for sl in _row_blocks(arr.shape[0], int(np.prod(arr.shape[1:], dtype=np.int64))):
            if not np.all(np.isfinite(arr[sl])):
                raise InputError(
                    "the image contains NaN or infinite values; replace them (np.nan_to_num) "
                    "or mask them out first"
                )
        lo, hi = float(arr.min()), float(arr.max())
        if lo < 0.0 or hi > 1.0:
            raise InputError(
                f"float images must have values in 0..1, got {lo:g}..{hi:g}; "
                "divide by 255 (8-bit) or by the maximum"
            )
        if threshold is not None:
            # Compare in float so that a user threshold is applied exactly, not after
            # quantization to 256 levels.
            return _threshold_float(arr, float(threshold), invert)
        return _threshold_u8(_float_to_u8(arr, 1.0), None, invert)
    if kind in "ui":
        _check_threshold(threshold, 255.0)
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0 or hi > 65535:
            raise InputError(
                f"integer images must have values in 0..255 (8-bit) or 0..65535 (16-bit), "
                f"got {lo}..{hi}; rescale the data first"
            )
        if arr.dtype != np.uint8:
            arr = _int_to_u8(arr, sixteen_bit=hi > 255 or arr.dtype == np.uint16)
        return _threshold_u8(arr, threshold, invert)
    raise InputError(
        f"unsupported image dtype {arr.dtype}; use bool, integer (0..255) or float (0..1)"
    )


def _int_to_u8(arr: NDArray[np.integer[Any]], sixteen_bit: bool) -> NDArray[np.uint8]:
    """Integer levels to uint8 (16-bit data scaled by 255/65535, rounded), block by block."""
    out = np.empty(arr.shape, dtype=np.uint8)
    for sl in _row_blocks(arr.shape[0], int(np.prod(arr.shape[1:], dtype=np.int64))):
        block = arr[sl].astype(np.int64)
        out[sl] = (block * 255 + 32767) // 65535 if sixteen_bit else block
    return out


def _luminance_u8(arr: NDArray[np.uint8], sl: slice, invert: bool) -> NDArray[np.uint8]:
    """8-bit luminance of rows ``sl``, with alpha composited onto white (black if inverted)."""
    block = arr[sl]
    if block.ndim == 2:
        return block
    c = block.shape[2]
    if c in (1, 2):
        lum = block[:, :, 0].astype(np.int32)
    else:
        # ITU-R 601-2 weights in integer per-mille, rounded: what Pillow's convert("L") does.
        lum = (
            block[:, :, 0].astype(np.int32) * 299
            + block[:, :, 1].astype(np.int32) * 587
            + block[:, :, 2].astype(np.int32) * 114
            + 500
        ) // 1000
    if c in (2, 4):
        alpha = block[:, :, c - 1].astype(np.int32)
        backdrop = 0 if invert else 255
        lum = (lum * alpha + backdrop * (255 - alpha) + 127) // 255
    return lum.astype(np.uint8)


def _threshold_u8(
    arr: NDArray[np.uint8], threshold: float | None, invert: bool
) -> NDArray[np.bool_]:
    """Threshold uint8 (H, W) or (H, W, C) data, computing luminance per row block."""
    h, w = arr.shape[:2]
    simple = arr.ndim == 2
    lum: NDArray[np.uint8]
    if simple:
        lum = arr
    else:
        # One uint8 luminance image (H*W bytes) is cheaper than computing it twice.
        lum = np.empty((h, w), dtype=np.uint8)
        for sl in _row_blocks(h, w * arr.shape[2]):
            lum[sl] = _luminance_u8(arr, sl, invert)
    if threshold is None:
        hist = np.zeros(256, dtype=np.int64)
        flat = lum.reshape(-1)
        for i0 in range(0, flat.size, _BLOCK_PIXELS):
            hist += np.bincount(flat[i0 : i0 + _BLOCK_PIXELS], minlength=256)
        t = otsu_threshold(hist)
        # A constant image has no Otsu cut: call it dark (ink) iff darker than mid-grey.
        cut = 128.0 if t is None else float(t)
    else:
        cut = float(threshold)
    mask = np.empty((h, w), dtype=bool)
    for sl in _row_blocks(h, w):
        # uint8 vs float compare would upcast the block; compare with an integer instead
        # (luminance < cut  <=>  luminance < ceil(cut) for integer luminance).
        icut = math.ceil(cut)
        block = lum[sl]
        if icut > 255:
            mask[sl] = not invert
        else:
            mask[sl] = block >= np.uint8(icut) if invert else block < np.uint8(icut)
    return mask


def _threshold_float(arr: NDArray[np.floating[Any]], cut: float, invert: bool) -> NDArray[np.bool_]:
    """Threshold float data in 0..1 exactly (luminance and alpha composite in float)."""
    h, w = arr.shape[:2]
    mask = np.empty((h, w), dtype=bool)
    for sl in _row_blocks(h, w * (arr.shape[2] if arr.ndim == 3 else 1)):
        block = np.asarray(arr[sl], dtype=np.float64)
        if block.ndim == 2:
            lum = block
        else:
            c = block.shape[2]
            if c in (1, 2):
                lum = block[:, :, 0]
            else:
                lum = 0.299 * block[:, :, 0] + 0.587 * block[:, :, 1] + 0.114 * block[:, :, 2]
            if c in (2, 4):
                alpha = block[:, :, c - 1]
                lum = lum * alpha + (0.0 if invert else 1.0) * (1.0 - alpha)
        mask[sl] = lum >= cut if invert else lum < cut
    return mask
