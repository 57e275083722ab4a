"""The wavefront renderer (volcl/wavefront.py, kernels/wavefront*.cl) renders the megakernel's
samples: with one seed the same paths (up to the roundings of the lanes stage's vector arithmetic),
with two seeds the same image within the renders' standard errors, for every estimator choice the
lanes stage takes over; and it says why it will not render a scene outside its case."""
from pathlib import Path

import numpy as np
import pytest

import volcl
from imagestats import assert_same_image
from volcl.errors import VolclError
from volcl.estimator import Estimator
from volcl import wavefront
from volcl.renderer import Renderer

pytestmark = pytest.mark.every_implementation

SCENES = Path(__file__).resolve().parent.parent / "scenes"

# a chromatic isotropic medium in a box of diffuse walls, the camera and two point lights in it: the chromatic
# distance sampler, the isotropic phase function and the pick between lights
CHROMATIC = """<scene version="3.0.0">
    <integrator type="volpath"/>
    <medium type="homogeneous" id="haze">
        <rgb name="sigma_t" value="0.4, 0.25, 0.1"/>
        <rgb name="albedo" value="0.9, 0.7, 0.5"/>
        <phase type="isotropic"/>
    </medium>
    <sensor type="perspective">
        <float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0, 0, 3.5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <ref id="haze"/>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="18"/></film>
    </sensor>
    <emitter type="point"><point name="position" value="0.5, 0.6, 0"/><rgb name="intensity" value="3, 3, 3"/></emitter>
    <emitter type="point"><point name="position" value="-0.7, -0.3, -0.5"/><rgb name="intensity" value="1, 2, 4"/></emitter>
    <shape type="cube">
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>
        <transform name="to_world"><scale value="4"/></transform>
        <ref name="exterior" id="haze"/>
    </shape>
</scene>"""

ESTIMATORS = {
    "default": Estimator(),
    "one-sample MIS": Estimator(equiangular_mis="one"),
    "MIS off": Estimator(mis=False),
    "equiangular off": Estimator(equiangular="off"),
    "NEE off": Estimator(nee=False),
}


def _channels_off(image, reference, limit=1e-3):
    """The share of pixel channels that differ from the reference's by more than `limit` relative."""
    rel = np.abs(image - reference) / np.maximum(np.abs(reference), 1e-6)
    return float(np.mean(rel > limit))


def _scene(name):
    if name == "chromatic":
        return volcl.load_string(CHROMATIC)
    return volcl.load_file(SCENES / "point_in_fog.xml", width=32, height=24)


def _pair(device, scene, estimator, spp, seeds=(3, 3)):
    mk = Renderer(scene, device=device, estimator=estimator, seed=seeds[0], engine="megakernel").render(spp)
    r = Renderer(scene, device=device, estimator=estimator, seed=seeds[1], engine="wavefront")
    assert r.engine == "wavefront"
    return mk, r.render(spp)


@pytest.mark.parametrize("what", sorted(ESTIMATORS))
def test_same_paths_as_megakernel(device, what):
    """One seed: nearly every pixel within 1e-3 of the megakernel's (exp, log and sqrt of the vector
    stage round differently; a path a rounding sends another way changes its pixel more)."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    mk, wf = _pair(device, _scene("point_in_fog"), ESTIMATORS[what], 8)
    assert wf.invalid == 0 and mk.invalid == 0
    off = _channels_off(wf.image, mk.image)
    assert off < 0.01, f"{off:.3%} of pixel channels differ by more than 1e-3"
    np.testing.assert_allclose(wf.image.mean(), mk.image.mean(), rtol=1e-3)


@pytest.mark.parametrize("loop", [0, wavefront.LOOP_PATHS, 8])
@pytest.mark.parametrize("name", ["point_in_fog", "chromatic"])
def test_medium_stage_loop_same_paths(device, name, loop):
    """The medium stage with one path per work-item (0) and with its paths in a loop of each
    work-item (VOLCL_WF_LOOP, PoCL's default), on every runtime: the megakernel's paths, and
    the launch covers every path (a wave of 4,096 paths a loop of 8 or 16 divides)."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = _scene(name)
    mk = Renderer(scene, device=device, seed=3, engine="megakernel").render(8)
    r = Renderer(scene, device=device, seed=3, engine="wavefront")
    r.wavefront = wavefront.Wavefront(r.device, r.features, r.packed, r.group_items, loop=loop)
    assert r.wavefront.loop == loop
    wf = r.render(8)
    assert wf.invalid == 0 and mk.invalid == 0
    off = _channels_off(wf.image, mk.image)
    assert off < 0.01, f"loop {loop}: {off:.3%} of pixel channels differ by more than 1e-3"
    np.testing.assert_allclose(wf.image.mean(), mk.image.mean(), rtol=1e-3)


def test_medium_stage_loop_where_pocl():
    """PoCL's medium stage loops over its paths (its work-item vectorizer failed on AVX2); other
    runtimes keep one path per work-item for their own vectorizers."""
    class Dev:
        def __init__(self, platform_name):
            self.platform_name = platform_name
    assert wavefront.lanes_loop(Dev("Portable Computing Language")) == wavefront.LOOP_PATHS
    assert wavefront.lanes_loop(Dev("Intel(R) OpenCL")) == 0
    assert wavefront.lanes_loop(Dev("Oclgrind")) == 0


@pytest.mark.parametrize("name", ["point_in_fog", "chromatic"])
def test_same_image_as_megakernel(device, name):
    """Two seeds: the same image within the standard errors, over 4 x 4 blocks; and one seed, the
    chromatic scene's paths too."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = _scene(name)
    mk, wf = _pair(device, scene, Estimator(), 64, seeds=(1, 2))
    assert mk.image.mean() > 0.01, "a black image compares nothing"
    assert_same_image(mk, wf, what=f"{name}: megakernel and wavefront")
    mk, wf = _pair(device, scene, Estimator(), 8)
    assert _channels_off(wf.image, mk.image) < 0.01


def test_auto_takes_it_where_it_pays(device):
    """"auto" (the default) renders point_in_fog (camera in the fog, a point light) with the wavefront
    renderer on CPUs, the fog box (an area light) with the megakernel, and the Cornell box (no
    medium, few primitives) with the packet renderer on CPUs (tests/test_packets.py), which it
    prefers to the surface stage."""
    cpu = device.kind == "cpu"
    expected = {"point_in_fog": "wavefront" if cpu else "megakernel", "fog": "megakernel",
                "cbox": "packet" if cpu else "megakernel"}
    for name, engine in expected.items():
        r = Renderer(volcl.load_file(SCENES / f"{name}.xml", width=8, height=8), device=device)
        assert r.engine == engine, name


def test_says_why_not(device):
    """A scene outside both stages' case (no medium, and an environment light the surface stage does
    not sample) is refused by name, not rendered otherwise."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    text = (SCENES / "cbox.xml").read_text().replace("</scene>", '<emitter type="constant"/></scene>')
    scene = volcl.load_string(text, base_dir=SCENES, width=8, height=8)
    with pytest.raises(VolclError, match="wavefront renderer cannot render this scene.*point lights and area lights"):
        Renderer(scene, device=device, engine="wavefront")
    with pytest.raises(VolclError, match="engine"):
        Renderer(scene, device=device, engine="lanes")


def _tree_route(r):
    """The renderer r's wavefront with the scalar stage's BVH queries instead of the lanes' whole-scene
    tests (volcl.wavefront.tiny_lanes)."""
    r.wavefront = wavefront.Wavefront(r.device, r.features, r.packed, r.group_items, tiny=False)
    return r


@pytest.mark.parametrize("name", ["point_in_fog", "chromatic"])
def test_whole_scene_tests_match_the_tree(device, name):
    """A scene small enough to test whole: the lanes stage's closest hits and shadow rays
    (kernels/lanes_triangles.h) give the BVH's bits. point_in_fog's tree is one leaf, whose
    traversal order the tests follow, so its image is the one the scalar stage's queries give, bit
    for bit, for every estimator choice of the lanes stage; the box's six leaves are visited in
    another order, which can only change which of two triangles at the same distance (a face's two
    halves along their diagonal) wins, so there the paths are the same up to such ties."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = _scene(name)
    for what, estimator in ESTIMATORS.items():
        tiny = Renderer(scene, device=device, estimator=estimator, seed=5, engine="wavefront")
        assert tiny.wavefront.tiny > 0
        tree = _tree_route(Renderer(scene, device=device, estimator=estimator, seed=5, engine="wavefront"))
        a, b = tiny.render(4), tree.render(4)
        # (point lights alone, without NEE: black, by design)
        assert what == "NEE off" or a.image.mean() > 0.01, "a black image compares nothing"
        if name == "point_in_fog":
            assert np.array_equal(a.image, b.image), f"{what}: {np.mean(a.image != b.image):.2%} of channels differ"
        else:
            off = _channels_off(a.image, b.image)
            assert off < 0.02, f"{what}: {off:.2%} of channels differ by > 1e-3"


@pytest.mark.parametrize("name", ["fog", "milk_glass"])
def test_spheres_tested_whole(device, name):
    """Spheres in a scene tested whole (the fog box's two, milk_glass's medium-filled one): the lanes
    stage's sphere test (lanes_sphere_hit) gives sphere_intersect's bits, so the image is the one the
    scalar stage's BVH queries give, bit for bit."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = volcl.load_file(SCENES / f"{name}.xml", width=24, height=24)
    tiny = Renderer(scene, device=device, seed=5, engine="wavefront")
    assert tiny.wavefront.tiny > 0 and wavefront.tiny_lanes(tiny.packed, tiny.features)[2] > 0
    a = tiny.render(4)
    b = _tree_route(Renderer(scene, device=device, seed=5, engine="wavefront")).render(4)
    assert a.image.mean() > 0.01, "a black image compares nothing"
    assert np.array_equal(a.image, b.image), f"{np.mean(a.image != b.image):.2%} of channels differ"


def test_tree_route_same_paths_as_megakernel(device):
    """The route for scenes too big to test whole (the scalar stage's BVH queries) still renders the
    megakernel's paths."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = _scene("point_in_fog")
    mk = Renderer(scene, device=device, seed=3, engine="megakernel").render(8)
    wf = _tree_route(Renderer(scene, device=device, seed=3, engine="wavefront")).render(8)
    assert _channels_off(wf.image, mk.image) < 0.01


AREA_LIGHT = ('<shape type="rectangle"><transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/>'
              '<translate y="0.95"/></transform><emitter type="area"><rgb name="radiance" value="4, 4, 4"/></emitter>'
              '<bsdf type="diffuse"/><ref name="exterior" id="haze"/></shape>')


def test_whole_scene_tests_with_an_area_light(device):
    """A scene tested whole that also has an area light (engine="wavefront"; "auto" would not take
    it): NEE towards the area light goes to the scalar stage, before the roulette, and the paths are
    the megakernel's."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = _with_shape(AREA_LIGHT)
    wf = Renderer(scene, device=device, seed=3, engine="wavefront")
    assert wf.wavefront.tiny > 0
    mk = Renderer(scene, device=device, seed=3, engine="megakernel").render(16)
    b = wf.render(16)
    assert b.invalid == 0 and mk.invalid == 0
    off = _channels_off(b.image, mk.image)
    assert off < 0.01, f"{off:.3%} of pixel channels differ by more than 1e-3"


def _with_shape(shape_xml):
    text = CHROMATIC.replace("</scene>", shape_xml + "</scene>")
    return volcl.load_string(text)


@pytest.mark.parametrize("shape, expect", [
    ("", 12),           # the box: 12 triangles, three packets
    # a sphere is tested whole too (lanes_sphere_hit)
    ('<shape type="sphere"><float name="radius" value="0.2"/><bsdf type="diffuse"/><ref name="exterior" id="haze"/></shape>', 12),
    ('<shape type="rectangle"><bsdf type="null"/><ref name="exterior" id="haze"/></shape>', 0),
    ('<shape type="rectangle"><bsdf type="thindielectric"/><ref name="exterior" id="haze"/></shape>', 0),
    # a dielectric blocks shadow rays in the megakernel too (refraction is specular)
    ('<shape type="rectangle"><bsdf type="dielectric"/><ref name="exterior" id="haze"/></shape>', 14),
])
def test_which_scenes_are_tested_whole(device, shape, expect):
    """Only opaque triangles and spheres, at most wavefront.TINY_LANES and TINY_SPHERES: a null or a
    thin glass surface (which shadow rays cross) sends the scene to the scalar stage's queries."""
    r = Renderer(_with_shape(shape), device=device, engine="megakernel")
    assert wavefront.tiny_lanes(r.packed, r.features)[0] == expect


# The surface stage's case (kernels/wavefront_surface.cl): no medium, 16 triangles and two spheres.
# A two-sided diffuse box (seen from inside, against its outward normals), two area lights of two
# triangles each (the pick between them and the cdf over their triangles) and a point light, a
# diffuse sphere and a glass one (which the scalar stage scatters from)
SURFACES = """<scene version="3.0.0">
    <default name="max_depth" value="-1"/>
    <integrator type="path"><integer name="max_depth" value="$max_depth"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="70"/>
        <transform name="to_world"><lookat origin="0, 0, 3.5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="18"/></film>
    </sensor>
    <emitter type="point"><point name="position" value="0.5, 0.6, 0"/><rgb name="intensity" value="3, 3, 3"/></emitter>
    <shape type="cube">
        <bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.6, 0.5"/></bsdf></bsdf>
        <transform name="to_world"><scale value="4"/></transform>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.8"/><rotate x="1" angle="90"/><translate y="3.9"/></transform>
        <emitter type="area"><rgb name="radiance" value="4, 4, 4"/></emitter>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.5"/><rotate y="1" angle="90"/><translate x="-3.9"/></transform>
        <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter>
    </shape>
    <shape type="sphere">
        <point name="center" value="0.8, -1, 0"/><float name="radius" value="0.5"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.5, 0.7"/></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" value="-0.8, -0.8, 0.5"/><float name="radius" value="0.4"/>
        <bsdf type="dielectric"/>
    </shape>
</scene>"""

# the same box with a checkerboard of two colours for its reflectance, tilted on its uv: the lanes'
# texcoords and checkerboard (lanes_surface.h lanes_color_at) on two-sided walls
CHECKERS = SURFACES.replace(
    '<rgb name="reflectance" value="0.7, 0.6, 0.5"/>',
    '<texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.7, 0.6, 0.5"/>'
    '<rgb name="color1" value="0.2, 0.4, 0.6"/>'
    '<transform name="to_uv"><rotate z="1" angle="20"/><scale x="3" y="5"/><translate x="0.1"/></transform></texture>')
assert CHECKERS != SURFACES

SURFACE_CASES = {
    "default": (Estimator(), {}),
    "MIS off": (Estimator(mis=False), {}),
    "NEE off": (Estimator(nee=False), {}),
    "max_depth 3": (Estimator(), {"max_depth": 3}),
}


def _surface_scene(name, **defaults):
    if name == "cbox":
        return volcl.load_file(SCENES / "cbox.xml", width=32, height=32, **defaults)
    return volcl.load_string(CHECKERS if name == "checkers" else SURFACES, **defaults)


@pytest.mark.parametrize("name", ["cbox", "surfaces", "checkers"])
@pytest.mark.parametrize("what", sorted(SURFACE_CASES))
def test_surface_stage_same_paths_as_megakernel(device, name, what):
    """A scene without media tested whole: the surface stage scatters from its diffuse triangles
    itself (NEE towards point and area lights, the shadow ray, the new direction, the roulette),
    draw for draw, with the megakernel's arithmetic and no vector exp or log, so one seed gives the
    megakernel's image (bit for bit on PoCL and Intel's runtime on the AVX-512 host; the limit of
    1e-5 leaves another compiler room to contract a multiply-add differently)."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    estimator, defaults = SURFACE_CASES[what]
    scene = _surface_scene(name, **defaults)
    r = Renderer(scene, device=device, estimator=estimator, seed=3, engine="wavefront")
    assert r.wavefront.surface and r.wavefront.tiny > 0
    assert ("-DVOLCL_WF_CHECKERS=1" in r.wavefront.sources[1][1]) == (name == "checkers")
    mk = Renderer(scene, device=device, estimator=estimator, seed=3, engine="megakernel").render(8)
    wf = r.render(8)
    assert mk.image.mean() > 0.01, "a black image compares nothing"
    assert wf.invalid == 0 and mk.invalid == 0
    off = _channels_off(wf.image, mk.image, 1e-5)
    assert off < 0.01, f"{off:.3%} of pixel channels differ by more than 1e-5"
    np.testing.assert_allclose(wf.image.mean(), mk.image.mean(), rtol=1e-5)


def test_surface_stage_same_image_as_megakernel(device):
    """Two seeds: the surface stage's image is the megakernel's within the standard errors."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    scene = _surface_scene("surfaces")
    mk, wf = _pair(device, scene, Estimator(), 64, seeds=(1, 2))
    assert mk.image.mean() > 0.01, "a black image compares nothing"
    assert_same_image(mk, wf, what="surfaces: megakernel and wavefront")


def cbox_with(change, size=8):
    """cbox with `change` added to it (XML text), or with the camera in a homogeneous medium
    rendered by volpath ("medium")."""
    text = (SCENES / "cbox.xml").read_text()
    if change == "medium":
        text = text.replace('<scene version="3.0.0">', '<scene version="3.0.0"><medium type="homogeneous" id="m"/>')
        text = text.replace("<sampler", '<ref id="m"/><sampler').replace('type="path"', 'type="volpath"')
    else:
        text = text.replace("</scene>", change + "</scene>")
    return volcl.load_string(text, base_dir=SCENES, width=size, height=size)


@pytest.mark.parametrize("change, why", [
    ('<emitter type="constant"/>', "point lights and area lights on triangles only"),
    ('<shape type="sphere"><float name="radius" value="0.1"/><emitter type="area"/></shape>',
     "point lights and area lights on triangles only"),
    ('<shape type="obj"><string name="filename" value="meshes/glass_sphere.obj"/></shape>', "not small enough"),
    ('medium', None),       # the camera in a medium, with volpath
])
def test_which_scenes_the_surface_stage_takes(device, change, why):
    """The surface stage takes a scene without media small enough to test whole and lit by point
    lights and area lights on triangles; it says why it will not take the others (a scene with a
    medium is the medium stage's)."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renderer is for CPU devices")
    reason = wavefront.surface_lanes(*_packed(device, cbox_with(change)))
    if why is None:
        assert reason == "the surface stage is for scenes without media"
    else:
        assert reason is not None and why in reason
    assert wavefront.surface_lanes(*_packed(device, volcl.load_file(SCENES / "cbox.xml", width=8, height=8))) is None


def _packed(device, scene):
    r = Renderer(scene, device=device, engine="megakernel")
    return r.packed, r.features, r.params
