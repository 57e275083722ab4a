"""Mitsuba's own compressed mesh format (.serialized), as Mitsuba 3.9 reads it (src/shapes/serialized.cpp).

Layout, little-endian throughout:
- uint16 0x041C, uint16 version (3 or 4); then, per mesh, a zlib stream holding
  uint32 flags, (version 4: the mesh's name, NUL-terminated), uint64 vertex count, uint64 triangle
  count, positions (vertices x 3), normals if flagged (x 3), texture coordinates if flagged (x 2),
  colours if flagged (x 3) as float32 or float64 (flag 0x1000 / 0x2000), then the triangles as
  uint32 index triples;
- a file of several meshes starts each later one with the same 4-byte header and ends with their
  offsets (uint64 in version 4, uint32 in version 3) followed by a uint32 count.
Flags: 0x1 normals, 0x2 texture coordinates, 0x8 colours (skipped, as Mitsuba skips them).
"""
from __future__ import annotations

import os
import struct
import zlib

import numpy as np

from .errors import VolclError
from .mesh import TriangleMesh, validated

MAGIC = 0x041C
HAS_NORMALS, HAS_TEXCOORDS, HAS_COLORS = 0x1, 0x2, 0x8
SINGLE, DOUBLE = 0x1000, 0x2000
# a name longer than this is a broken file, not a mesh name
_MAX_NAME = 1 << 16


def load_serialized(path: str, shape_index: int = 0) -> TriangleMesh:
    """Mesh number `shape_index` of a .serialized file; every problem is a VolclError naming the file."""
    if not os.path.isfile(path):
        raise VolclError("mesh file not found (or not a regular file)", file=path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise VolclError(f"cannot read mesh file: {exc.strerror or exc}", file=path) from None
    try:
        mesh = _parse(data, shape_index)
    except (struct.error, zlib.error, ValueError) as exc:
        raise VolclError(f"cannot parse serialized mesh {shape_index}: {exc}", file=path) from None
    return validated(mesh, path)


def _parse(data: bytes, shape_index: int) -> TriangleMesh:
    if shape_index < 0:
        raise ValueError("shape_index must be >= 0")
    magic, version = struct.unpack_from("<HH", data, 0)
    if magic != MAGIC:
        raise ValueError(f"not a Mitsuba serialized file (header 0x{magic:04X}, expected 0x{MAGIC:04X})")
    if version not in (3, 4):
        raise ValueError(f"unsupported serialized version {version} (Mitsuba reads 3 and 4)")
    start = 4
    if shape_index:
        (count,) = struct.unpack_from("<I", data, len(data) - 4)
        if shape_index >= count:
            raise ValueError(f"shape_index {shape_index} is out of range: the file holds {count} "
                             f"mesh{'es' if count != 1 else ''} (0 to {count - 1})")
        if version == 4:
            (start,) = struct.unpack_from("<Q", data, len(data) - 4 - 8 * (count - shape_index))
        else:
            (start,) = struct.unpack_from("<I", data, len(data) - 4 * (count - shape_index + 1))
        if not 0 <= start < len(data) - 4:
            raise ValueError(f"mesh {shape_index} starts at offset {start}, outside the file")
        start += 4                      # each mesh repeats the file header
    return _mesh(_Inflater(data[start:]), version)


class _Inflater:
    """Reads a zlib stream piece by piece, never inflating more than asked for (a corrupt or
    hostile file cannot make it allocate beyond the sizes its own header states)."""

    def __init__(self, data: bytes):
        self.z = zlib.decompressobj()
        self.pending = data
        self.buffer = b""

    def read(self, n: int) -> bytes:
        while len(self.buffer) < n:
            if not self.pending and not self.z.unconsumed_tail:
                raise ValueError("the compressed stream ends early")
            source = self.z.unconsumed_tail or self.pending
            self.pending = b"" if source is self.pending else self.pending
            chunk = self.z.decompress(source, n - len(self.buffer))
            if not chunk and self.z.eof:
                raise ValueError("the compressed stream ends early")
            self.buffer += chunk
        out, self.buffer = self.buffer[:n], self.buffer[n:]
        return out


def _mesh(stream: _Inflater, version: int) -> TriangleMesh:
    (flags,) = struct.unpack("<I", stream.read(4))
    if version == 4:
        name = b""
        while True:
            ch = stream.read(1)
            if ch == b"\0":
                break
            name += ch
            if len(name) > _MAX_NAME:
                raise ValueError("the mesh name does not end")
    vertex_count, face_count = struct.unpack("<QQ", stream.read(16))
    if vertex_count > 1 << 32 or face_count > 1 << 32:
        raise ValueError(f"implausible sizes: {vertex_count} vertices, {face_count} triangles")
    real = np.float64 if flags & DOUBLE else np.float32

    def block(columns: int) -> np.ndarray:
        count = vertex_count * columns
        raw = stream.read(count * np.dtype(real).itemsize)
        return np.frombuffer(raw, dtype=np.dtype(real).newbyteorder("<")).astype(np.float64).reshape(-1, columns)

    vertices = block(3)
    normals = block(3) if flags & HAS_NORMALS else None
    uvs = block(2) if flags & HAS_TEXCOORDS else None
    if flags & HAS_COLORS:
        block(3)
    faces = np.frombuffer(stream.read(face_count * 12), dtype="<u4").astype(np.int64).reshape(-1, 3)
    return TriangleMesh(vertices, faces, normals, uvs)
