"""Mitsuba's binary grid-volume file (.vol): reading with full validation, and writing.

Layout (little-endian): bytes 'VOL', version byte 3, int32 encoding (1 = float32), int32 xres, yres,
zres, int32 channels (1 or 3), six float32 of a bounding box (min xyz, max xyz), then float32 data
indexed ((z * yres + y) * xres + x) * channels + c. In memory the data is an array of shape
(z, y, x, c), which is the same order, so no transpose is needed.
"""
from __future__ import annotations

import os
import struct

import numpy as np

from ..errors import VolclError

_HEADER = struct.Struct("<3sBiiiii6f")
_VERSION = 3
_FLOAT32 = 1
_CHANNELS = (1, 3)


def read_vol(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Return (data float32 (z, y, x, c), bbox float64 (2, 3) as [min, max])."""
    if not os.path.isfile(path):
        # Also refuses devices such as /dev/zero, which would never finish reading.
        raise VolclError("volume file not found (or not a regular file)", file=path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise VolclError(f"cannot read volume file: {exc.strerror or exc}", file=path) from None

    def bad(what: str) -> VolclError:
        return VolclError(f"not a valid Mitsuba .vol file: {what}", file=path)

    if len(raw) < _HEADER.size:
        raise bad(f"{len(raw)} bytes is shorter than the {_HEADER.size}-byte header")
    magic, version, encoding, xres, yres, zres, channels, *bbox = _HEADER.unpack_from(raw)
    if magic != b"VOL":
        raise bad(f"starts with {magic!r} instead of b'VOL'")
    if version != _VERSION:
        raise bad(f"version {version}; only version {_VERSION} is supported")
    if encoding != _FLOAT32:
        raise bad(f"encoding {encoding}; only 1 (float32) is supported")
    if min(xres, yres, zres) <= 0:
        raise bad(f"resolution {xres} x {yres} x {zres} must be positive")
    if channels not in _CHANNELS:
        raise bad(f"{channels} channels; supported: 1 or 3")
    expected = xres * yres * zres * channels * 4
    body = len(raw) - _HEADER.size
    if body != expected:
        kind = "truncated" if body < expected else "over-long"
        raise bad(f"{kind}: {xres}x{yres}x{zres}x{channels} float32 values need {expected} bytes "
                  f"of data, the file has {body}")
    data = np.frombuffer(raw, dtype="<f4", offset=_HEADER.size).reshape(zres, yres, xres, channels)
    finite = np.isfinite(data)
    if not finite.all():
        z, y, x, c = np.argwhere(~finite)[0]
        raise bad(f"non-finite value {data[z, y, x, c]} at x={x} y={y} z={z} channel={c}")
    return data.astype(np.float32), np.array(bbox, dtype=np.float64).reshape(2, 3)


def write_vol(path: str, data, bbox=None) -> None:
    """Write `data` of shape (z, y, x) or (z, y, x, c) with c in (1, 3); bbox defaults to [0,1]^3."""
    arr = np.asarray(data, dtype=np.float32)
    if arr.ndim == 3:
        arr = arr[..., None]
    if arr.ndim != 4 or arr.shape[3] not in _CHANNELS or min(arr.shape) == 0:
        raise VolclError(f"volume data must have shape (z, y, x) or (z, y, x, 1|3), not {arr.shape}",
                         file=path)
    if not np.isfinite(arr).all():
        raise VolclError("volume data holds non-finite values", file=path)
    box = np.asarray([0, 0, 0, 1, 1, 1] if bbox is None else bbox, dtype=np.float64).reshape(6)
    zres, yres, xres, channels = arr.shape
    header = _HEADER.pack(b"VOL", _VERSION, _FLOAT32, xres, yres, zres, channels, *box)
    try:
        with open(path, "wb") as fh:
            fh.write(header)
            fh.write(arr.astype("<f4").tobytes(order="C"))
    except OSError as exc:
        raise VolclError(f"cannot write volume file: {exc.strerror or exc}", file=path) from None
