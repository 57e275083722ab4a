"""Mitsuba .vol files: round trips, the byte layout, and every kind of corrupt file."""
import struct

import numpy as np
import pytest

from volcl.errors import VolclError
from volcl.scene.volfile import read_vol, write_vol


def header(magic=b"VOL", version=3, encoding=1, res=(4, 3, 2), channels=1, bbox=(0,) * 6):
    return struct.pack("<3sBiiiii6f", magic, version, encoding, *res, channels, *bbox)


@pytest.mark.parametrize("channels", [1, 3])
def test_round_trip(tmp_path, channels):
    rng = np.random.default_rng(1)
    data = rng.random((2, 3, 4, channels), dtype=np.float32)
    path = tmp_path / "v.vol"
    write_vol(path, data, bbox=[-1, -2, -3, 1, 2, 3])
    back, bbox = read_vol(path)
    assert back.dtype == np.float32 and back.shape == (2, 3, 4, channels)
    assert np.array_equal(back, data)
    assert np.allclose(bbox, [[-1, -2, -3], [1, 2, 3]])


def test_byte_layout(tmp_path):
    z, y, x, c = 2, 3, 4, 3
    data = np.arange(z * y * x * c, dtype=np.float32).reshape(z, y, x, c)
    path = tmp_path / "v.vol"
    write_vol(path, data)
    raw = path.read_bytes()
    assert raw[:4] == b"VOL\x03"
    assert struct.unpack_from("<iiiii", raw, 4) == (1, x, y, z, c)
    assert struct.unpack_from("<6f", raw, 24) == (0, 0, 0, 1, 1, 1)
    values = np.frombuffer(raw, "<f4", offset=48)
    zi, yi, xi, ci = 1, 2, 3, 1
    assert values[((zi * y + yi) * x + xi) * c + ci] == data[zi, yi, xi, ci]


def test_three_dimensional_input_gets_one_channel(tmp_path):
    path = tmp_path / "v.vol"
    write_vol(path, np.ones((1, 2, 3)))
    assert read_vol(path)[0].shape == (1, 2, 3, 1)


BODY = np.zeros(24, "<f4").tobytes()


@pytest.mark.parametrize("raw, message", [
    (header() + BODY[:-4], "truncated"),
    (header() + BODY + b"\0\0\0\0", "over-long"),
    (header(magic=b"VOX") + BODY, "b'VOX'"),
    (header(version=2) + BODY, "version 2"),
    (header(encoding=2) + BODY, "encoding 2"),
    (header(channels=2) + np.zeros(48, "<f4").tobytes(), "2 channels"),
    (header(res=(4, 0, 2)) + BODY, "must be positive"),
    (header()[:20], "shorter than"),
    (header() + np.r_[np.zeros(23), np.nan].astype("<f4").tobytes(), "non-finite"),
])
def test_corrupt_files(tmp_path, raw, message):
    path = tmp_path / "bad.vol"
    path.write_bytes(raw)
    with pytest.raises(VolclError) as info:
        read_vol(path)
    assert "bad.vol" in str(info.value) and message in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(VolclError, match="nothere.vol"):
        read_vol(tmp_path / "nothere.vol")


def test_write_rejects_bad_shapes(tmp_path):
    with pytest.raises(VolclError, match="shape"):
        write_vol(tmp_path / "v.vol", np.zeros((2, 2, 2, 2)))
    with pytest.raises(VolclError, match="non-finite"):
        write_vol(tmp_path / "v.vol", np.full((1, 1, 1), np.inf))
