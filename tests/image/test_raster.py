"""Tests of pde2cad.image.raster: reading files, luminance, Otsu and fixed thresholds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from PIL import Image

from pde2cad.errors import InputError
from pde2cad.image import raster
from pde2cad.image.raster import otsu_threshold, read_image, to_mask


def _bimodal(seed: int = 0) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """A noisy dark disc (ink, ~60) on light paper (~200), and the true ink mask."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:80, :100]
    ink = (x - 50) ** 2 + (y - 40) ** 2 < 25**2
    grey = np.where(ink, 60.0, 200.0) + rng.normal(0.0, 12.0, ink.shape)
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8), ink


def test_otsu_separates_bimodal_image() -> None:
    grey, ink = _bimodal()
    hist = np.bincount(grey.ravel(), minlength=256)
    t = otsu_threshold(hist)
    assert t is not None and 100 < t < 160
    mask = to_mask(grey)
    assert mask.dtype == np.bool_ and mask.shape == ink.shape
    np.testing.assert_array_equal(mask, ink)


def test_otsu_two_levels_cuts_in_the_middle() -> None:
    hist = np.zeros(256)
    hist[[0, 255]] = [10, 30]
    assert otsu_threshold(hist) == 128
    assert otsu_threshold(np.bincount([7, 7, 7], minlength=256)) is None


def test_invert_is_the_complement() -> None:
    grey, ink = _bimodal(1)
    np.testing.assert_array_equal(to_mask(grey, invert=True), ~ink)
    np.testing.assert_array_equal(to_mask(grey, threshold=130, invert=True), ~ink)


def test_fixed_threshold_uint8_and_float() -> None:
    grey = np.array([[0, 99, 100, 101, 255]], dtype=np.uint8)
    np.testing.assert_array_equal(to_mask(grey, threshold=100), [[1, 1, 0, 0, 0]])
    np.testing.assert_array_equal(to_mask(grey, threshold=100.5), [[1, 1, 1, 0, 0]])
    f = np.array([[0.0, 0.3, 0.5, 0.7, 1.0]])
    np.testing.assert_array_equal(to_mask(f, threshold=0.5), [[1, 1, 0, 0, 0]])
    np.testing.assert_array_equal(to_mask(f, threshold=0.5, invert=True), [[0, 0, 1, 1, 1]])
    # Float Otsu: same answer as the 8-bit image.
    grey2, ink = _bimodal(2)
    np.testing.assert_array_equal(to_mask(grey2 / 255.0), ink)


def test_bool_array_passes_through() -> None:
    m = np.array([[True, False], [False, False]])
    np.testing.assert_array_equal(to_mask(m), m)
    np.testing.assert_array_equal(to_mask(m, invert=True), ~m)


def test_sixteen_bit_array() -> None:
    grey, ink = _bimodal(3)
    np.testing.assert_array_equal(to_mask(grey.astype(np.uint16) * 257), ink)


def test_constant_image_uses_mid_grey() -> None:
    assert to_mask(np.full((4, 5), 40, dtype=np.uint8)).all()
    assert not to_mask(np.full((4, 5), 200, dtype=np.uint8)).any()
    assert not to_mask(np.full((4, 5), 40, dtype=np.uint8), invert=True).any()


def test_colour_png_round_trip(tmp_path: Path) -> None:
    _, ink = _bimodal()
    rgb = np.zeros(ink.shape + (3,), dtype=np.uint8)
    rgb[~ink] = (250, 240, 200)  # cream paper
    rgb[ink] = (20, 40, 160)  # blue ink
    path = tmp_path / "colour.png"
    Image.fromarray(rgb, "RGB").save(path)
    np.testing.assert_array_equal(read_image(path), ink)
    np.testing.assert_array_equal(read_image(str(path), invert=True), ~ink)
    # The array path gives the same mask as Pillow's luminance.
    np.testing.assert_array_equal(to_mask(rgb), ink)


def test_transparent_pixels_are_background(tmp_path: Path) -> None:
    rgba = np.zeros((10, 12, 4), dtype=np.uint8)  # fully transparent black
    rgba[3:6, 4:9] = (0, 0, 0, 255)  # opaque black ink
    rgba[0, 0] = (255, 255, 255, 255)  # one opaque white pixel so the image is not flat
    expected = np.zeros((10, 12), dtype=bool)
    expected[3:6, 4:9] = True
    path = tmp_path / "alpha.png"
    Image.fromarray(rgba, "RGBA").save(path)
    np.testing.assert_array_equal(read_image(path), expected)
    np.testing.assert_array_equal(to_mask(rgba), expected)
    # Inverted (white on dark): transparent pixels stay background.
    rgba2 = rgba.copy()
    rgba2[3:6, 4:9] = (255, 255, 255, 255)
    rgba2[0, 0] = (0, 0, 0, 255)
    Image.fromarray(rgba2, "RGBA").save(path)
    np.testing.assert_array_equal(read_image(path, invert=True), expected)


def test_one_bit_pbm(tmp_path: Path) -> None:
    ink = np.zeros((7, 9), dtype=bool)
    ink[1:4, 2:8] = True
    ink[5, 0] = True
    path = tmp_path / "ink.pbm"
    Image.fromarray(~ink).convert("1").save(path)  # mode "1": white = True
    with Image.open(path) as im:
        assert im.mode == "1"
    np.testing.assert_array_equal(read_image(path), ink)
    np.testing.assert_array_equal(read_image(path, invert=True), ~ink)


def test_pgm_bmp_tiff(tmp_path: Path) -> None:
    grey, ink = _bimodal(4)
    for name in ("g.pgm", "g.bmp", "g.tif"):
        Image.fromarray(grey, "L").save(tmp_path / name)
        np.testing.assert_array_equal(read_image(tmp_path / name), ink)


def test_jpeg(tmp_path: Path) -> None:
    grey, ink = _bimodal(5)
    path = tmp_path / "scan.jpg"
    Image.fromarray(grey, "L").convert("RGB").save(path, quality=90)
    mask = read_image(path)
    # Lossy: allow a few flipped pixels along the edge of the disc.
    assert np.count_nonzero(mask != ink) <= 0.01 * ink.size


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file; check the path"):
        read_image(tmp_path / "nope.png")


def test_text_file_is_not_an_image(tmp_path: Path) -> None:
    path = tmp_path / "notes.png"
    path.write_text("not an image\n")
    with pytest.raises(InputError, match="is not an image Pillow can read"):
        read_image(path)


def test_folder_is_not_an_image(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="folder"):
        read_image(tmp_path)


def test_bad_thresholds() -> None:
    grey = np.zeros((3, 3), dtype=np.uint8)
    with pytest.raises(InputError, match="out of range 0..255"):
        to_mask(grey, threshold=300)
    with pytest.raises(InputError, match="out of range 0..255"):
        to_mask(grey, threshold=-1)
    with pytest.raises(InputError, match="out of range 0..1"):
        to_mask(grey / 255.0, threshold=128)
    with pytest.raises(InputError, match="threshold must be a number"):
        to_mask(grey, threshold="dark")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="out of range"):
        to_mask(grey, threshold=float("nan"))


def test_bad_arrays() -> None:
    with pytest.raises(InputError, match="NaN"):
        to_mask(np.array([[0.0, np.nan]]))
    with pytest.raises(InputError, match="2-D"):
        to_mask(np.zeros(5))
    with pytest.raises(InputError, match="channels"):
        to_mask(np.zeros((4, 4, 5), dtype=np.uint8))
    with pytest.raises(InputError, match="0..1"):
        to_mask(np.array([[0.0, 2.0]]))
    with pytest.raises(InputError, match="empty"):
        to_mask(np.zeros((0, 3), dtype=np.uint8))
    with pytest.raises(InputError, match="0..65535"):
        to_mask(np.array([[-1, 3]]))


def test_too_large_image_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "big.png"
    Image.new("L", (40, 30), 255).save(path)
    limit_before = Image.MAX_IMAGE_PIXELS
    monkeypatch.setattr(raster, "MAX_PIXELS", 1000)
    with pytest.raises(InputError, match="downscale"):
        read_image(path)
    assert Image.MAX_IMAGE_PIXELS == limit_before  # the global limit is restored


@pytest.mark.slow
def test_ten_thousand_square_png_loads(tmp_path: Path) -> None:
    """Above Pillow's default decompression-bomb limit (~89 M pixels), below ours."""
    n = 10_000
    im = Image.new("1", (n, n), 1)
    im.paste(0, (1000, 2000, 3000, 2500))
    path = tmp_path / "big.png"
    im.save(path)
    del im
    mask = read_image(path)
    assert mask.shape == (n, n)
    assert mask.sum() == 2000 * 500
