"""RenderResult: a rendered image (or tile) with its variance, how it was made, and how to show it."""
from __future__ import annotations

import io
from dataclasses import dataclass, field, replace

import numpy as np

from .accuracy import relative_standard_error
from .errors import VolclError
from .image import srgb_encode
from .tiles import Tile, check_cover


@dataclass
class RenderResult:
    """What a render returns. `image` is the (h, w, 3) float32 linear mean radiance of each pixel;
    `variance` the estimated variance of that mean, from the samples themselves. For a tile render
    both cover the tile only (`tile`, in pixels of the image of size `image_size`)."""
    image: np.ndarray
    variance: np.ndarray
    spp: int
    invalid: int                # samples that came out NaN, infinite or negative and were left out
    seconds: float              # render time (device passes, not kernel builds or scene uploads)
    device: str
    features: dict
    build_seconds: float        # kernel build time this render waited for (0 when the program was built before)
    stats: dict = field(default_factory=dict)
    # medium segments whose delta / ratio tracking hit its step bound and was cut short (each a
    # biased estimate; never happens in ordinary scenes, see kernels/media.h)
    tracking_cutoffs: int = 0
    # the rule that ended the render: 'spp', 'time', 'error', 'stopped' (a stop() request) or
    # 'failed' (every device failed; the image holds the samples every pixel got before)
    stop_reason: str = "spp"
    seed: int = 0
    tile: Tile | None = None    # None: the whole image
    image_size: tuple = (0, 0)  # (width, height) of the whole image
    info: dict = field(default_factory=dict)   # metadata: scene file, -D values, estimator, kernels
    # device (or worker) label -> fraction of the samples it rendered in this session; {} for one device
    shares: dict = field(default_factory=dict)
    # the mean of each pixel's squared samples (the layer Mitsuba's moment integrator asks for)
    second_moment: np.ndarray | None = None

    @property
    def rel_error(self) -> float:
        """The image's estimated relative standard error (volcl.accuracy.relative_standard_error)."""
        return relative_standard_error(self.image, self.variance)

    @property
    def samples_per_second(self) -> float:
        h, w = self.image.shape[:2]
        return h * w * self.spp / self.seconds if self.seconds > 0 else float("inf")

    @property
    def complete(self) -> bool:
        """Whether the render reached what it was asked for (False after a stop() request)."""
        return (self.stop_reason not in ("stopped", "failed")
                and self.spp >= int(self.info.get("spp_requested", 0) or 0))

    @property
    def metadata(self) -> dict:
        """The attributes an EXR file of this render carries (as volcl:NAME; README)."""
        out = {k: self.info[k] for k in ("scene", "scene_sha256", "defines") if k in self.info}
        out.update(spp=self.spp, spp_requested=int(self.info.get("spp_requested", 0) or 0),
                   complete=int(self.complete), seed=self.seed, device=self.device,
                   features=self.stats.get("features", ""), kernel_sha256=self.info.get("kernel_sha256", ""),
                   render_seconds=round(self.seconds, 3), version=self.info.get("version", ""),
                   invalid_samples=self.invalid, tracking_cutoffs=self.tracking_cutoffs,
                   rel_error=float(self.rel_error), stop_reason=self.stop_reason,
                   estimator=self.info.get("estimator", ""), device_shares=self.shares_text())
        return out

    def shares_text(self) -> str:
        """'0:0 NAME 0.512, 0:1 NAME 0.488': each device's share of the samples (one device: 1)."""
        shares = self.shares or {self.device: 1.0}
        return ", ".join(f"{label} {share:.3f}" for label, share in shares.items())

    def to_srgb(self, exposure: float = 0.0) -> np.ndarray:
        """The image for display: scaled by 2^exposure, clamped to [0, 1] and sRGB-encoded, as
        (h, w, 3) float32 (the same encoding PNG outputs get)."""
        return srgb_encode(np.asarray(self.image, np.float64) * 2.0 ** exposure).astype(np.float32)

    def _repr_png_(self) -> bytes:
        """Jupyter shows a result as its image."""
        from PIL import Image
        pixels = np.round(self.to_srgb() * 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(pixels, "RGB").save(buf, format="PNG")
        return buf.getvalue()

    def __repr__(self) -> str:
        h, w = self.image.shape[:2]
        where = "" if self.tile is None else f", tile {self.tile.width}x{self.tile.height} at ({self.tile.x}, {self.tile.y})"
        return (f"<RenderResult {w}x{h}{where}, {self.spp} spp, {self.seconds:.3g} s, relative error "
                f"{100 * self.rel_error:.2f}%, stop: {self.stop_reason}, device {self.device}>")


def merge(results: list, width: int | None = None, height: int | None = None) -> RenderResult:
    """One whole-image RenderResult from tile renders that cover the image exactly once, with the
    same seed and sample count. Pixels are copied, not recomputed, so the merged image is bit for
    bit the one a single render of the whole image gives on the same kind of device (volcl.tiles).
    `seconds` and the sample counts are summed over the tiles; `device` names every device."""
    if not results:
        raise VolclError("merge: no tile results")
    first = results[0]
    width, height = (width, height) if width is not None else first.image_size
    tile_list = [r.tile or Tile(0, 0, *r.image_size) for r in results]
    check_cover(tile_list, width, height)
    for r in results[1:]:
        for attr in ("spp", "seed"):
            if getattr(r, attr) != getattr(first, attr):
                raise VolclError(f"merge: tiles rendered with different {attr} ({getattr(first, attr)} and "
                                 f"{getattr(r, attr)}); every tile needs the same")
    image = np.zeros((height, width, 3), np.float32)
    variance = np.zeros((height, width, 3), np.float32)
    moments = None if any(r.second_moment is None for r in results) else np.zeros((height, width, 3), np.float32)
    for r, t in zip(results, tile_list):
        image[t.rows, t.columns] = r.image
        variance[t.rows, t.columns] = r.variance
        if moments is not None:
            moments[t.rows, t.columns] = r.second_moment
    devices = list(dict.fromkeys(r.device for r in results))
    reasons = list(dict.fromkeys(r.stop_reason for r in results))
    shares = dict.fromkeys(devices, 0.0)
    for r, t in zip(results, tile_list):
        shares[r.device] += t.pixels / (width * height)
    return replace(first, image=image, variance=variance, second_moment=moments, tile=None,
                   image_size=(width, height),
                   invalid=sum(r.invalid for r in results), seconds=sum(r.seconds for r in results),
                   tracking_cutoffs=sum(r.tracking_cutoffs for r in results), device=", ".join(devices),
                   build_seconds=sum(r.build_seconds for r in results), shares=shares if len(shares) > 1 else {},
                   stop_reason="stopped" if "stopped" in reasons else reasons[0])
