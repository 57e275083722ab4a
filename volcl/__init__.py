"""volcl: a physically based volumetric path tracer on OpenCL.

The Python API (README, "Python"):

    import volcl
    scene = volcl.load_file("scenes/fog.xml", spp=64, width=320, height=240)
    result = volcl.render(scene)                 # result.image, result.variance: numpy arrays
    params = volcl.traverse(scene)
    params["fog.sigma_t.value"] = 0.3
    params.update()                              # re-uploads only what changed
    volcl.write(volcl.render(scene, seed=1), "fog.exr")

load_file, load_string   scenes in the Mitsuba 3 and Nori dialects, with <default> values as keywords
render                   a RenderResult (image, variance, spp, seconds, ...); a tile of it with tile=
traverse                 editable parameters keyed "<id>.<name>", applied by update()
write                    EXR (with variance and metadata) or PNG
devices                  the OpenCL devices (volcl.Device), each owning its context and built programs
tiles, merge             split an image into tiles, join tile renders into it bit for bit
Renderer                 a progressive render on one device (state, restore: checkpoints)
"""
__version__ = "0.1.0"

import sys as _sys  # noqa: E402
import types as _types  # noqa: E402

# The names below are imported when first used (PEP 562), so that `import volcl` and the `volcl`
# command start without numpy and pyopencl; a command that renders pays for them when it needs them.
_LAZY = {
    "SceneWarning": "api", "devices": "api", "load_file": "api", "load_string": "api", "render": "api",
    "traverse": "api", "write": "api", "Device": "device", "VolclError": "errors", "Estimator": "estimator",
    "FeatureChange": "params", "SceneParameters": "params", "UnknownParameter": "params", "Scene": "prepared",
    "Renderer": "renderer", "RenderResult": "result", "merge": "result", "Tile": "tiles", "tiles": "tiles",
}


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'volcl' has no attribute {name!r}")
    import importlib
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


class _Package(_types.ModuleType):
    """volcl itself. `volcl.tiles` is the function (volcl.tiles.tiles), as it was when this file
    imported it: the import system binds each loaded submodule to its package's attribute, and
    for the submodule volcl.tiles that binding is refused here."""

    def __setattr__(self, name, value):
        if name == "tiles" and isinstance(value, _types.ModuleType):
            return
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package


__all__ = ["load_file", "load_string", "render", "write", "devices", "traverse", "tiles", "merge",
           "Scene", "RenderResult", "Device", "Renderer", "Estimator", "Tile", "SceneParameters",
           "VolclError", "UnknownParameter", "FeatureChange", "SceneWarning", "__version__"]
