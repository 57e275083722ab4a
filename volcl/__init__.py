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

from .api import SceneWarning, devices, load_file, load_string, render, traverse, write  # noqa: E402
from .device import Device  # noqa: E402
from .errors import VolclError  # noqa: E402
from .estimator import Estimator  # noqa: E402
from .params import FeatureChange, SceneParameters, UnknownParameter  # noqa: E402
from .prepared import Scene  # noqa: E402
from .renderer import Renderer  # noqa: E402
from .result import RenderResult, merge  # noqa: E402
from .tiles import Tile, tiles  # noqa: E402

__all__ = ["load_file", "load_string", "render", "write", "devices", "traverse", "tiles", "merge",
           "Scene", "RenderResult", "Device", "Renderer", "Estimator", "Tile", "SceneParameters",
           "VolclError", "UnknownParameter", "FeatureChange", "SceneWarning", "__version__"]
