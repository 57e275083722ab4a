"""volcl/scene/images.py: linear pixels from image files with Mitsuba's colour rules."""
import numpy as np
import OpenImageIO as oiio
import pytest

from volcl.errors import VolclError
from volcl.scene.images import read_image, srgb_decode


def _write(path, pixels, fmt):
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()


def test_png_is_srgb_decoded_unless_raw(tmp_path):
    codes = np.arange(0, 256, 17, dtype=np.uint8)[:12].reshape(2, 2, 3)
    _write(tmp_path / "a.png", codes, oiio.UINT8)
    expected = srgb_decode(codes / 255.0)
    np.testing.assert_allclose(read_image(str(tmp_path / "a.png")), expected, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(read_image(str(tmp_path / "a.png"), raw=True), codes / 255.0, rtol=1e-6)


def test_srgb_decode_known_values():
    # the two branches of the sRGB curve and their meeting point
    np.testing.assert_allclose(srgb_decode([0.0, 0.04045, 0.5, 1.0]),
                               [0.0, 0.04045 / 12.92, 0.21404114, 1.0], rtol=1e-6)


def test_exr_is_linear(tmp_path):
    pixels = np.random.default_rng(1).random((3, 6, 3)).astype(np.float32) * 40
    _write(tmp_path / "a.exr", pixels, oiio.FLOAT)
    np.testing.assert_array_equal(read_image(str(tmp_path / "a.exr")), pixels)


@pytest.mark.parametrize("value, word", [(-0.5, "negative"), (np.nan, "non-finite"), (np.inf, "non-finite")])
def test_bad_texel_is_named(tmp_path, value, word):
    pixels = np.ones((2, 4, 3), np.float32)
    pixels[1, 3, 2] = value
    _write(tmp_path / "bad.exr", pixels, oiio.FLOAT)
    with pytest.raises(VolclError, match=f"{word} texel .* at x=3 y=1 channel=2"):
        read_image(str(tmp_path / "bad.exr"))


def test_missing_and_unreadable_files_name_the_path(tmp_path):
    with pytest.raises(VolclError, match="not found.*nope.png"):
        read_image(str(tmp_path / "nope.png"))
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    with pytest.raises(VolclError, match="cannot read image .*junk.png"):
        read_image(str(tmp_path / "junk.png"))
