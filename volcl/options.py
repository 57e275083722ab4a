"""Typed options of the `volcl render` batch runner (volcl.batch), which volcl.cli fills from the
command line: what to load, how to render, and where and how to write."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .errors import VolclError
from .estimator import Estimator


@dataclass(frozen=True)
class SceneOptions:
    """How each scene file is loaded: its <default> overrides, a film size that replaces the
    scene's, and which of its sensors to render (0-based; None: the first, with a warning when
    there are several)."""
    defines: dict = field(default_factory=dict)
    width: int | None = None
    height: int | None = None
    sweep: Path | None = None       # a sweep file: one set of -D values a line (volcl.sweep)
    sensor: int | None = None

    def __post_init__(self):
        for name in ("width", "height"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise VolclError(f"--{name} {value}: expected a positive pixel count")


@dataclass(frozen=True)
class RenderOptions:
    """How each scene is rendered. spp caps time_limit and target_error; without spp the scene's own
    spp caps time_limit (the render stops at whichever comes first), and target_error runs until it
    is met. features: a feature set to compile instead of the scene's (None: the
    scene's)."""
    spp: int | None = None
    seed: int | None = None
    time_limit: float | None = None
    target_error: float | None = None
    min_spp: int = 16
    estimator: Estimator = field(default_factory=Estimator)
    features: dict | None = None
    tile_size: int | None = None    # tiles of a render on several devices (None: chosen per image)

    def __post_init__(self):
        if self.tile_size is not None and self.tile_size < 1:
            raise VolclError(f"--tile-size {self.tile_size}: expected a positive pixel count")
        if self.spp is not None and self.spp < 1:
            raise VolclError(f"--spp {self.spp}: expected a positive sample count")
        if self.time_limit is not None and not self.time_limit > 0:
            raise VolclError(f"--time-limit {self.time_limit}: expected a positive number of seconds")
        if self.target_error is not None and not self.target_error > 0:
            raise VolclError(f"--target-error {self.target_error}: expected a positive relative error, e.g. 0.02")


@dataclass(frozen=True)
class OutputOptions:
    """Where outputs go and how long renders are kept safe: -o (a single scene) or a folder,
    checkpoints every `checkpoint_every` minutes (0: never), resuming from them."""
    output: Path | None = None
    output_dir: Path | None = None
    checkpoint_every: float = 5.0
    resume: bool = False
    keep_checkpoint: bool = False
    quiet: bool = False
    verbose: bool = False

    def __post_init__(self):
        if self.checkpoint_every < 0:
            raise VolclError("--checkpoint-every: expected minutes >= 0 (0 disables checkpoints)")
