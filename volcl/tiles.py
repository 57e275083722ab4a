"""Tiles: rectangles of an image that render independently and merge into it bit for bit.

A pixel's samples do not depend on what else is rendered with it: its random streams are keyed by
(seed, pixel, sample index), and sample i lands in accumulator slot i % slots, where `slots`
depends on the size of the whole image only (accumulator_slots). A tile renders all samples of its
pixels into accumulators of its own (kernels/render.cl), and each slot adds its samples in
increasing sample index, so a tile's float32 sums, and the mean and variance computed from them,
are the ones a render of the whole image computes for those pixels. Tiles may therefore be
rendered in any order, on any devices of the same implementation, in any process, and merged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import VolclError

# Work items per launch that fill a device (see volcl.renderer); the slot count of an image is
# chosen so that one round of slots over all its pixels reaches it.
MIN_ITEMS = 1 << 14
MAX_SLOTS = 4096


def accumulator_slots(width: int, height: int) -> int:
    """Accumulator slots per pixel of a width x height image (and of every tile of it)."""
    return int(np.clip(MIN_ITEMS // (width * height), 1, MAX_SLOTS))


@dataclass(frozen=True)
class Tile:
    """A rectangle of the image: `width` x `height` pixels from column x, row y."""
    x: int
    y: int
    width: int
    height: int

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def rows(self) -> slice:
        return slice(self.y, self.y + self.height)

    @property
    def columns(self) -> slice:
        return slice(self.x, self.x + self.width)

    def check(self, width: int, height: int) -> "Tile":
        """This tile, after checking that it lies inside a width x height image."""
        if not (self.width >= 1 and self.height >= 1 and 0 <= self.x and 0 <= self.y
                and self.x + self.width <= width and self.y + self.height <= height):
            raise VolclError(f"tile {self.width}x{self.height} at ({self.x}, {self.y}) does not lie inside "
                             f"the {width}x{height} image")
        return self

    @classmethod
    def of(cls, value, width: int, height: int) -> "Tile":
        """A Tile from a Tile, an (x, y, width, height) tuple, or None (the whole image)."""
        if value is None:
            return cls(0, 0, width, height)
        if not isinstance(value, Tile):
            try:
                x, y, w, h = (int(v) for v in value)
            except (TypeError, ValueError):
                raise VolclError(f"tile {value!r}: expected (x, y, width, height) in pixels") from None
            value = cls(x, y, w, h)
        return value.check(width, height)


def tiles(width: int, height: int, size=64) -> list[Tile]:
    """Tiles of `size` (one number, or (width, height)) covering a width x height image row by row;
    the last column and row of tiles are narrower where the image size is not a multiple."""
    tw, th = (size, size) if np.isscalar(size) else size
    if tw < 1 or th < 1:
        raise VolclError(f"tile size {size!r}: expected positive pixel counts")
    return [Tile(x, y, min(tw, width - x), min(th, height - y))
            for y in range(0, height, th) for x in range(0, width, tw)]


def check_cover(tile_list, width: int, height: int) -> None:
    """Raise VolclError unless the tiles cover every pixel of the image exactly once."""
    count = np.zeros((height, width), np.int32)
    for t in tile_list:
        t.check(width, height)
        count[t.rows, t.columns] += 1
    if (count != 1).any():
        missing, twice = int((count == 0).sum()), int((count > 1).sum())
        raise VolclError(f"the tiles do not cover the {width}x{height} image exactly once: {missing} pixels "
                         f"missing, {twice} covered more than once")


def slice_state(state: dict, tile: Tile) -> dict:
    """The part of a whole-image accumulator state (Renderer.state) that belongs to `tile`."""
    width, height, slots = int(state["width"]), int(state["height"]), int(state["slots"])
    tile.check(width, height)
    out = dict(state, tile=(tile.x, tile.y, tile.width, tile.height))
    for key in ("sums", "sums_sq", "invalid", "cutoffs"):
        a = np.asarray(state[key])
        full = a.reshape((slots, height, width) + a.shape[1:])
        out[key] = np.ascontiguousarray(full[:, tile.rows, tile.columns]).reshape((-1,) + a.shape[1:])
    return out


def merge_states(states: list, width: int, height: int) -> dict:
    """The whole-image accumulator state of tile states that cover the image once (each from
    Renderer.state of a tile render with the same seed and sample count)."""
    tile_list = [Tile(*s["tile"]) for s in states]
    check_cover(tile_list, width, height)
    first = states[0]
    for s in states[1:]:
        for key in ("slots", "seed", "samples_done"):
            if int(s[key]) != int(first[key]):
                raise VolclError(f"tile states differ in {key}: {int(first[key])} and {int(s[key])}")
    slots = int(first["slots"])
    out = dict(first, tile=(0, 0, width, height), width=width, height=height,
               seconds=float(sum(float(s["seconds"]) for s in states)))
    for key in ("sums", "sums_sq", "invalid", "cutoffs"):
        a = np.asarray(first[key])
        full = np.zeros((slots, height, width) + a.shape[1:], a.dtype)
        for s, t in zip(states, tile_list):
            full[:, t.rows, t.columns] = np.asarray(s[key]).reshape((slots, t.height, t.width) + a.shape[1:])
        out[key] = full.reshape((-1,) + a.shape[1:])
    return out
