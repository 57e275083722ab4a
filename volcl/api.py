"""The Python API (exported by the volcl package; README, "Python"). Names follow Mitsuba 3's where the
meaning is the same: load_file, load_string, render, traverse, write."""
from __future__ import annotations

import os
import warnings
from pathlib import Path

from . import device as devmod
from .errors import VolclError
from .estimator import Estimator
from .params import SceneParameters, apply_pending
from .prepared import Scene
from .renderer import Renderer
from .result import RenderResult
from .scene import load as _load_model
from .scene import load_string as _load_model_string
from .scene.model import Scene as ModelScene
from .scene.model import TTest


class SceneWarning(UserWarning):
    """Something in a scene file volcl reads differently from the file's own renderer, or ignores."""


def _warn(message: str):
    warnings.warn(message, SceneWarning, stacklevel=4)


def prepare(model, path=None, defines=None, width: int | None = None, height: int | None = None,
            warn=_warn) -> Scene:
    """A volcl.Scene of a loaded model: the film size replaced where given, each of the file's
    warnings passed to warn(message)."""
    if isinstance(model, TTest):
        raise VolclError(f"{model.path} is a Nori test file, not a scene; run it with `volcl test {model.path}`")
    if width:
        model.camera.width = width
    if height:
        model.camera.height = height
    for w in model.warnings:
        warn(w)
    return Scene(model, path=path, defines=defines)


def _defines(defines: dict) -> dict:
    return {str(k): str(v).lower() if isinstance(v, bool) else str(v) for k, v in defines.items()}


def load_file(path, **defines) -> Scene:
    """Load a Mitsuba 3 or Nori scene file. Keyword arguments set the scene's <default> parameters
    (its $name values), as `-D name=value` does on the command line: load_file("fog.xml", spp=64,
    width=320). A name the scene never uses is an error. What volcl reads differently from the
    file's own renderer comes as a SceneWarning."""
    defines = _defines(defines)
    return prepare(_load_model(path, defines), os.fspath(path), defines)


def load_string(xml, base_dir=None, **defines) -> Scene:
    """Load a scene from XML text; files it names (meshes, volumes) are found relative to `base_dir`
    (default: the working folder). Keyword arguments as for load_file."""
    defines = _defines(defines)
    return prepare(_load_model_string(xml, base_dir, defines), None, defines)


def _prepared(scene) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, ModelScene):
        return Scene(scene)
    raise TypeError(f"render takes a volcl.Scene (from volcl.load_file or volcl.load_string), not "
                    f"{type(scene).__name__}")


def _progress(progress, scene: Scene, spp):
    """(callback for Renderer.render, closer) for render's progress argument."""
    if progress is None or progress is False:
        return None, lambda: None
    if progress is True:
        from tqdm import tqdm
        bar = tqdm(total=spp, unit="spp", leave=False)
        return bar.update, bar.close
    if callable(progress):
        return progress, lambda: None
    raise TypeError("progress: expected None, True (a progress bar) or a callable taking the samples per "
                    "pixel each pass added")


def render(scene, spp: int | None = None, seed: int | None = None, device=None, time_limit: float | None = None,
           target_error: float | None = None, progress=None, estimator: Estimator | None = None,
           tile=None, tile_size=None, scheduler=None) -> RenderResult:
    """Render `scene` and return a RenderResult (numpy image and variance, spp, seconds, invalid
    samples, stop reason, metadata).

    spp, time_limit, target_error  stop at the first rule met; with none of them, the scene's spp;
                                   spp caps the other two
    seed        the random sequence (default: the scene's sampler seed); the same seed and device
                give the same bits
    device      a volcl.Device (volcl.devices()), a selector ('P:D', a name substring, 'cpu',
                'gpu'), or None: $VOLCL_DEVICE, else the first device whose kernels build; or
                several devices for one render: 'all', 'A,B,...', or a list of Devices and
                selectors (the image's tiles go to whichever device is free; the same bits as
                one device of the same implementation; RenderResult.shares: who did what)
    progress    True for a progress bar, or a callable given the samples per pixel each pass adds
    estimator   a volcl.Estimator (NEE, MIS, equiangular sampling; default: volcl's defaults)
    tile        (x, y, width, height) or a volcl.Tile: render only those pixels, all their samples;
                volcl.merge joins tiles into the image, bit for bit (on one device)
    tile_size   the tiles' size in pixels (one number or (width, height)) of a render on several
                devices (default: volcl.rounds.default_tile_size)
    scheduler   render on a Dask cluster instead (volcl.cluster): a distributed.Client, a
                scheduler address, or 'local:N' (N single-threaded worker processes here); the
                image is bit for bit a local render's on the same device implementation

    The scene stays uploaded to the device, and each kernel feature set is built once per device,
    so renders in a loop (after traverse() edits, too) pay only for their samples. Values set
    through traverse() and not yet applied are applied first."""
    scene = _prepared(scene)
    if scene.pending:
        apply_pending(scene, stacklevel=2)
    if scheduler is not None:
        return _render_on_cluster(scene, scheduler, spp, seed, time_limit, target_error, progress, estimator,
                                  tile, tile_size, device)
    devices = devmod.resolve_many(device)
    if len(devices) == 1 and tile_size is None:
        r = Renderer(scene, device=devices[0], seed=seed, estimator=estimator, tile=tile)
    elif tile is not None:
        raise VolclError("tile= renders one tile on one device; a render on several devices cuts the image "
                         "into tiles itself (tile_size=)")
    else:
        from .rounds import renderer_for
        r = renderer_for(scene, devices, seed=seed, estimator=estimator, tile_size=tile_size)
    return _run(r, scene, spp, time_limit, target_error, progress)


def _run(r, scene, spp, time_limit, target_error, progress) -> RenderResult:
    """r.render with render()'s defaults and progress bar."""
    if spp is None and time_limit is None and target_error is None:
        spp = scene.spp
    callback, close = _progress(progress, scene, spp)
    try:
        return r.render(spp, progress=callback, time_limit=time_limit, target_error=target_error)
    finally:
        close()


def _render_on_cluster(scene, scheduler, spp, seed, time_limit, target_error, progress, estimator, tile,
                       tile_size, device) -> RenderResult:
    from . import cluster
    from .rounds import renderer_for
    if tile is not None or device is not None:
        raise VolclError("scheduler= renders on the cluster's workers, each with the device it chose (volcl "
                         "worker --device); tile= and device= are for renders on this machine")
    client = cluster.connect(scheduler)
    executor = cluster.DaskExecutor(client)
    try:
        r = renderer_for(scene, executor=executor, seed=seed, estimator=estimator, tile_size=tile_size)
        return _run(r, scene, spp, time_limit, target_error, progress)
    finally:
        executor.close()
        if client is not scheduler:
            cluster.close(client)


def write(result: RenderResult, path) -> Path:
    """Write a render to `path`: .exr (linear float32, with a variance layer and volcl:* metadata
    attributes) or .png (sRGB, clamped). The file appears complete or not at all."""
    from .image import check_writable, write_image
    out = check_writable(path)
    layers = {"variance": result.variance} if out.suffix.lower() == ".exr" else None
    return write_image(out, result.image, result.metadata, layers)


def devices() -> list:
    """Every OpenCL device (volcl.Device objects; `volcl.device.kernels_build(d)` tells whether
    volcl's kernels build on one, `volcl.device.check(d)` whether it also passes volcl's
    self-test). The same objects are handed out every time."""
    return devmod.list_devices()


def traverse(scene) -> SceneParameters:
    """The scene's editable parameters, keyed "<id>.<name>" as in Mitsuba 3 (volcl.params): set
    values, call update(), render again."""
    return SceneParameters(scene)
