"""Writing images through OpenImageIO: EXR as linear float32, PNG as clamped sRGB.

Files are written under a temporary name beside the target and renamed into place, so a crash or
an interrupt never leaves half a file where a finished one is expected.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from .errors import VolclError

FLOAT_FORMATS = {".exr"}
BYTE_FORMATS = {".png"}


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    x = np.clip(np.nan_to_num(linear, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def new_file_mode() -> int:
    """The mode open() would give a new file (mkstemp's temporary files are 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def check_writable(path) -> Path:
    """Raise VolclError now, not after an hour of rendering, if `path` cannot be written."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in FLOAT_FORMATS | BYTE_FORMATS:
        raise VolclError(f"cannot write {path}: unsupported extension {ext!r}; use .exr or .png")
    if not path.parent.is_dir():
        raise VolclError(f"cannot write {path}: folder {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK):
        raise VolclError(f"cannot write {path}: folder {path.parent} is not writable")
    return path


def write_image(path, image: np.ndarray, metadata: dict | None = None, layers: dict | None = None) -> Path:
    """Write `image` (h, w, 3) linear radiance. `layers` adds named float channels to EXR files
    (e.g. {"variance": (h, w, 3)}); `metadata` becomes header attributes."""
    path = check_writable(path)
    ext = path.suffix.lower()
    h, w = image.shape[:2]
    names = ["R", "G", "B"]
    pixels = np.asarray(image, np.float32)[..., :3]
    if ext in FLOAT_FORMATS:
        for layer, data in (layers or {}).items():
            data = np.asarray(data, np.float32).reshape(h, w, -1)
            names += [f"{layer}.{c}" for c in "RGB"[:data.shape[2]]]
            pixels = np.concatenate([pixels, data], axis=2)
        spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
        data = pixels
    else:
        spec = oiio.ImageSpec(w, h, 3, oiio.UINT8)
        data = np.round(srgb_encode(pixels) * 255).astype(np.uint8)
    spec.channelnames = tuple(names)
    for key, value in (metadata or {}).items():
        spec.attribute(f"volcl:{key}", value if isinstance(value, (int, float)) else str(value))
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=ext, dir=path.parent)
    os.close(fd)
    try:
        out = oiio.ImageOutput.create(tmp)
        if out is None or not out.open(tmp, spec):
            raise VolclError(f"cannot write {path}: {oiio.geterror()}")
        ok = out.write_image(np.ascontiguousarray(data))
        out.close()
        if not ok:
            raise VolclError(f"cannot write {path}: {oiio.geterror()}")
        os.chmod(tmp, new_file_mode())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def read_image(path) -> tuple[np.ndarray, dict]:
    """(pixels (h, w, c) float32, {attribute name: value}) of an image file."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise VolclError(f"cannot read {path}: {oiio.geterror()}")
    spec = inp.spec()
    pixels = np.asarray(inp.read_image(oiio.FLOAT), np.float32)
    attrs = {a.name: a.value for a in spec.extra_attribs}
    inp.close()
    return pixels.reshape(spec.height, spec.width, spec.nchannels), attrs
