"""Reading images for textures and environment maps through OpenImageIO, with Mitsuba 3's colour rules.

Mitsuba 3 treats the pixels of 8- and 16-bit integer formats (PNG, JPEG, ...) as sRGB-encoded unless
told otherwise (`raw`), and those of float formats (EXR, HDR, float TIFF) as linear. volcl decodes
them into linear float32 once, on load, so the kernels only ever see linear values.
"""
from __future__ import annotations

import os

import numpy as np

from ..errors import VolclError

_FLOAT_TYPES = ("half", "float", "double")


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted: encoded values in [0, 1] to linear."""
    x = np.asarray(encoded, np.float64)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def read_image(path: str, raw: bool = False, where=None) -> np.ndarray:
    """Linear float32 pixels (h, w, c) of an image file, rows top to bottom as stored; c is the file's
    channel count (alpha kept, colours as stored, not multiplied by it). Integer formats are sRGB-decoded unless `raw` (linear data such as
    roughness or normal maps); float formats are read as they are. `where` is a callable turning a
    message into the VolclError to raise (naming file, line, element), so every error says where
    the image was asked for and the path tried."""
    def fail(message: str) -> VolclError:
        return where(message) if where is not None else VolclError(message, file=path)

    if not os.path.isfile(path):
        raise fail(f"image file not found (or not a regular file): {path}")
    import OpenImageIO as oiio
    # the stored colours, not multiplied by alpha: OpenImageIO associates the alpha of PNG and other
    # unassociated-alpha formats unless told not to, while Mitsuba drops alpha as it is stored
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise fail(f"cannot read image {path}: {oiio.geterror() or 'unknown format'}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    finally:
        inp.close()
    if pixels is None or spec.width <= 0 or spec.height <= 0:
        raise fail(f"cannot read the pixels of image {path}: {oiio.geterror() or 'empty image'}")
    data = np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    bad = ~np.isfinite(data) | (data < 0)
    if bad.any():
        y, x, c = (int(v) for v in np.argwhere(bad)[0])
        raise fail(f"image {path} has a {'negative' if data[y, x, c] < 0 else 'non-finite'} texel "
                   f"{float(data[y, x, c])!r} at x={x} y={y} channel={c}; textures and environment maps need "
                   f"finite, non-negative values")
    is_float = str(spec.format) in _FLOAT_TYPES
    if not raw and not is_float:
        colour = min(spec.nchannels, 3) if spec.nchannels != 2 else 1   # grey + alpha: decode grey only
        data[..., :colour] = srgb_decode(data[..., :colour])
    return data
