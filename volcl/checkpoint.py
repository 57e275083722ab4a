"""Checkpoints: a render's accumulated state on disk, so a long render survives an interrupt.

A checkpoint holds the raw device accumulators (per-slot float32 sums, sums of squares, invalid
counts), the samples done and the seed: restored into a Renderer of the same scene, the render
continues at the same sample index and ends bit-identical to one that never stopped (see
volcl/renderer.py). It also holds what makes it belong to one render, the identity: the scene file
and its sha256, the -D overrides, a hash of every array the kernel reads, the kernel sources'
hash and the feature set. A checkpoint whose identity differs from the render asked for is
refused, never silently mixed in.

Files are written to a temporary name in the same folder, flushed to disk and renamed, so a
checkpoint is always either the old one or the new one, never half of each.
"""
from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from . import __version__
from .errors import VolclError
from .features import describe
from .image import new_file_mode
from .prepared import defines_key, file_sha256  # noqa: F401  (part of this module's interface)
from .program import sources_hash

FORMAT = 1
SUFFIX = ".checkpoint.npz"
ARRAYS = ("sums", "sums_sq", "invalid", "cutoffs")

# identity keys, in the order a mismatch is reported, with what to say about each
IDENTITY = {
    "scene": "scene file",
    "scene_sha256": "scene file contents (edited since the checkpoint)",
    "defines": "-D overrides",
    "width": "image width",
    "height": "image height",
    "data_sha256": "scene data (meshes, media or camera changed)",
    "kernel_sha256": "kernel sources (volcl was updated)",
    "features": "compiled feature set",
    "slots": "accumulator slots",
}


def path_for(output) -> Path:
    """The checkpoint of an output file: beside it, named after it (fog.exr -> fog.exr.checkpoint.npz)."""
    output = Path(output)
    return output.with_name(output.name + SUFFIX)


def identity(renderer, scene_path, defines: dict) -> dict:
    """What a checkpoint must match to continue this renderer's render."""
    return {
        "scene": str(Path(scene_path).resolve()),
        "scene_sha256": file_sha256(scene_path),
        "defines": defines_key(defines),
        "width": renderer.width,
        "height": renderer.height,
        "data_sha256": renderer.data_hash(),
        "kernel_sha256": sources_hash(),
        "features": describe(renderer.packed.features),
        "slots": renderer.slots,
    }


def save(path, renderer, ident: dict, extra: dict | None = None) -> Path:
    """Write the renderer's state and `ident` (plus `extra` notes such as the target spp) to `path`."""
    path = Path(path)
    state = renderer.state()
    meta = dict(ident, format=FORMAT, version=__version__, seed=state["seed"],
                samples_done=state["samples_done"], seconds=state["seconds"],
                device=renderer.device_label, **(extra or {}))
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), **{k: state[k] for k in ARRAYS})
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(buf.getbuffer())
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, new_file_mode())
        os.replace(tmp, path)
        _fsync_folder(path.parent)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _fsync_folder(folder):
    """Make the rename itself durable (POSIX; a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def load(path) -> tuple[dict, dict]:
    """(state for Renderer.restore, metadata) of a checkpoint file."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in ARRAYS}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        raise VolclError(f"checkpoint {path} is unreadable ({exc}); delete it to render from the start") from None
    if meta.get("format") != FORMAT:
        raise VolclError(f"checkpoint {path} has format {meta.get('format')!r}, this volcl reads {FORMAT}; "
                         "delete it to render from the start")
    state = dict(arrays, samples_done=meta["samples_done"], seconds=meta["seconds"], slots=meta["slots"],
                 width=meta["width"], height=meta["height"], seed=meta["seed"])
    return state, meta


def _short(value):
    text = repr(value)
    return text[:14] + "...'" if isinstance(value, str) and len(value) == 64 else text


def check(path, meta: dict, ident: dict, seed: int):
    """Refuse (VolclError) a checkpoint made for another render than `ident` with `seed`."""
    diffs = [f"{what}: {_short(meta.get(key))} in the checkpoint, {_short(ident[key])} now"
             for key, what in IDENTITY.items() if meta.get(key) != ident[key]]
    if meta.get("seed") != seed:
        diffs.append(f"seed: {meta.get('seed')} in the checkpoint, {seed} now")
    if diffs:
        raise VolclError(f"checkpoint {path} belongs to a different render ({'; '.join(diffs)}); "
                         "render without --resume to start over (the checkpoint is then replaced)")
