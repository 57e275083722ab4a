"""The packet renderer (volcl/packets.py, kernels/packets.cl) renders the megakernel's samples: its
lanes run the megakernel's path functions and its queries make the tree's tests with the tree's
arithmetic, so one seed gives the megakernel's image (bit for bit on PoCL and Intel's runtime on the
AMD AVX-512 host), across the estimator choices, several passes per launch, slots and tiles; two
seeds the same image within the standard errors; and it says why it will not render a scene outside
its case."""
from pathlib import Path

import numpy as np
import pytest

import volcl
from imagestats import assert_same_image
from test_wavefront import CHECKERS, SURFACES, cbox_with
from volcl import packets, selftest, wavefront
from volcl.errors import VolclError
from volcl.estimator import Estimator
from volcl.renderer import Renderer
from volcl.tiles import Tile

pytestmark = pytest.mark.every_implementation

SCENES = Path(__file__).resolve().parent.parent / "scenes"

CASES = {
    "default": (Estimator(), {}),
    "MIS off": (Estimator(mis=False), {}),
    "NEE off": (Estimator(nee=False), {}),
    "max_depth 3": (Estimator(), {"max_depth": 3}),
}


def _cpu(device):
    if device.kind != "cpu":
        pytest.skip("the packet renderer is for CPU devices")


# the surface stage's scene with its box's walls in two-sided rough plastic (GGX): a tiled bitmap
# mirrored at its edges under a rotated, scaled to_uv ("rough"), a constant nonlinear one
# ("rough_constant")
ROUGH = SURFACES.replace(
    '<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.6, 0.5"/></bsdf></bsdf>',
    '<bsdf type="twosided"><bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
    '<float name="alpha" value="0.2"/><texture type="bitmap" name="diffuse_reflectance">'
    f'<string name="filename" value="{SCENES / "textures" / "tiles.png"}"/><string name="wrap_mode" value="mirror"/>'
    '<transform name="to_uv"><rotate z="1" angle="30"/><scale x="1.5" y="2.5"/><translate x="0.2"/></transform>'
    '</texture></bsdf></bsdf>')
ROUGH_CONSTANT = SURFACES.replace(
    '<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.6, 0.5"/></bsdf></bsdf>',
    '<bsdf type="twosided"><bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
    '<float name="alpha" value="0.35"/><boolean name="nonlinear" value="true"/><float name="int_ior" value="1.6"/>'
    '<rgb name="diffuse_reflectance" value="0.6, 0.5, 0.3"/></bsdf></bsdf>')
# (the coating dims the walls: brighter area lights, so that every case's image says something)
ROUGH, ROUGH_CONSTANT = (t.replace('value="4, 4, 4"', 'value="16, 16, 16"').replace('value="1, 2, 3"', 'value="4, 8, 12"')
                         for t in (ROUGH, ROUGH_CONSTANT))
assert ROUGH != SURFACES and ROUGH_CONSTANT != SURFACES


def _scene(name, size=24, **defaults):
    """cbox (area light, mirror and glass spheres), the surface stage's test scene (a two-sided box,
    two area lights and a point light, a diffuse and a glass sphere), textured_cbox (rough bsdfs,
    bitmaps, bump and normal maps), and cbox under a constant environment (NEE whose shadow rays
    are traced in the whole scene, beside the area light's in the tree without the box's hull) and
    with hidden emitters (camera rays pass through the light: no roulette there)."""
    texts = {"surfaces": SURFACES, "checkers": CHECKERS, "rough": ROUGH, "rough_constant": ROUGH_CONSTANT}
    if name in texts:
        return volcl.load_string(texts[name], **defaults)
    if name in ("cbox_sky", "cbox_hidden"):
        text = (SCENES / "cbox.xml").read_text()
        if name == "cbox_sky":
            text = text.replace("</scene>", '<emitter type="constant"><rgb name="radiance" value="0.5"/></emitter></scene>')
        else:
            text = text.replace('<integrator type="path">', '<integrator type="path"><boolean name="hide_emitters" value="true"/>')
        return volcl.load_string(text, base_dir=SCENES, width=size, height=size, **defaults)
    return volcl.load_file(SCENES / f"{name}.xml", width=size, height=size, **defaults)


def _pair(device, scene, estimator, spp, seeds=(3, 3), tile=None):
    mk = Renderer(scene, device=device, estimator=estimator, seed=seeds[0], engine="megakernel", tile=tile)
    pk = Renderer(scene, device=device, estimator=estimator, seed=seeds[1], engine="packet", tile=tile)
    assert mk.engine == "megakernel" and pk.engine == "packet"
    return mk.render(spp), pk.render(spp)


def _channels_off(image, reference, limit):
    rel = np.abs(image - reference) / np.maximum(np.abs(reference), 1e-6)
    return float(np.mean(rel > limit))


def _assert_same_paths(mk, pk):
    """One seed: the megakernel's image. The limit of 1e-5 on 1% of the channels leaves another
    compiler room to contract a multiply-add differently, and the tree room to let the other of two
    primitives at the same distance win."""
    assert mk.image.mean() > 0.01, "a black image compares nothing"
    assert mk.invalid == 0 and pk.invalid == 0
    off = _channels_off(pk.image, mk.image, 1e-5)
    assert off < 0.01, f"{off:.3%} of pixel channels differ by more than 1e-5"
    np.testing.assert_allclose(pk.image.mean(), mk.image.mean(), rtol=1e-5)


@pytest.mark.parametrize("name", ["cbox", "surfaces", "textured_cbox", "cbox_sky", "cbox_hidden"])
@pytest.mark.parametrize("what", sorted(CASES))
def test_same_paths_as_megakernel(device, name, what):
    _cpu(device)
    estimator, defaults = CASES[what]
    _assert_same_paths(*_pair(device, _scene(name, **defaults), estimator, 4))


def test_same_paths_over_passes_slots_and_tiles(device):
    """64x64 pixels take 4 slots, so 16 spp are 4 passes in one launch: lanes start their next
    samples while others finish theirs, some with a shadow ray untraced; 8x8 pixels take 256 slots
    (work items of one pixel's samples side by side in a packet); a tile renders the pixels the
    whole image renders there."""
    _cpu(device)
    _assert_same_paths(*_pair(device, _scene("cbox", 64), Estimator(), 16))
    _assert_same_paths(*_pair(device, _scene("textured_cbox", 8), Estimator(), 300))
    tile = Tile(5, 7, 13, 11)
    mk, pk = _pair(device, _scene("cbox", 32), Estimator(), 8, tile=tile)
    _assert_same_paths(mk, pk)
    whole = Renderer(_scene("cbox", 32), device=device, seed=3, engine="megakernel").render(8).image
    np.testing.assert_array_equal(mk.image, whole[7:18, 5:18])


@pytest.mark.parametrize("name", ["surfaces", "textured_cbox"])
def test_same_image_as_megakernel(device, name):
    """Two seeds: the megakernel's image within the standard errors, over 4 x 4 blocks."""
    _cpu(device)
    mk, pk = _pair(device, _scene(name, 32), Estimator(), 64, seeds=(1, 2))
    assert mk.image.mean() > 0.01, "a black image compares nothing"
    assert_same_image(mk, pk, what=f"{name}: megakernel and packet renderer")


def test_auto_takes_it_on_cpus(device):
    """"auto" renders the scenes the packet renderer takes with it on CPUs, and elsewhere the
    megakernel."""
    for name in ("cbox", "textured_cbox"):
        r = Renderer(_scene(name, 8), device=device)
        assert r.engine == ("packet" if device.kind == "cpu" else "megakernel"), name


def _packed(device, scene):
    r = Renderer(scene, device=device, engine="megakernel")
    return r.features, r.packed, r.params, r.device


@pytest.mark.parametrize("change, why", [
    ('<shape type="obj"><string name="filename" value="meshes/glass_sphere.obj"/></shape>', "primitives"),
    ('<shape type="sphere"><float name="radius" value="0.2"/><bsdf type="null"/></shape>', "NULL_BSDF"),
    ('<shape type="sphere"><float name="radius" value="0.2"/><bsdf type="thindielectric"/></shape>', "THINDIELECTRIC"),
    ('<shape type="cylinder"><float name="radius" value="0.1"/></shape>', "CYLINDERS"),
    ('medium', "MEDIA"),
])
def test_which_scenes_it_takes(device, change, why):
    """Every surface opaque (a shadow ray is an occlusion query), no media, instances or cylinders,
    and few enough primitives to test every one for every ray: it says why it will not take the
    others, and a render that asks for it gets that reason."""
    scene = cbox_with(change)
    reason = packets.supported(*_packed(device, scene))
    if device.kind != "cpu":
        assert reason == "the packet renderer is written for a CPU's SIMD lanes"
        return
    assert reason is not None and why in reason, reason
    with pytest.raises(VolclError, match="packet renderer cannot render this scene"):
        Renderer(scene, device=device, engine="packet")
    assert packets.supported(*_packed(device, _scene("cbox", 8))) is None


def test_self_test_renders_through_it(device, monkeypatch):
    """On CPUs the device self-test renders its bare wall through the packet renderer, and a
    packet renderer whose queries find nothing fails it."""
    _cpu(device)
    assert selftest._bare_wall_failures(device) == []
    made = packets.Packets.__init__

    def blind(self, *args):
        made(self, *args)
        self.leaf_ends = (np.int32(0), np.int32(0))
    monkeypatch.setattr(packets.Packets, "__init__", blind)
    failures = selftest._bare_wall_failures(device)
    assert failures and "packet renderer" in failures[0], failures


def _packet_renderer(scene, device, estimator=None, vector_step=True, bsdf_steps=None):
    """A packet Renderer whose kernel takes its diffuse lanes' steps in the vector lanes or not,
    whichever the device's default (packets.vector_step_pays), and its rough plastic lanes' there
    too or not (default: packets.bsdf_steps_pay)."""
    r = Renderer(scene, device=device, estimator=estimator or Estimator(), seed=5, engine="packet")
    r.wavefront = packets.Packets(r.device, r.features, r.packed, vector_step=vector_step, bsdf_steps=bsdf_steps)
    return r


@pytest.mark.parametrize("name", ["cbox", "surfaces", "checkers", "textured_cbox"])
def test_vector_step_takes_the_diffuse_lanes(device, name):
    """Lanes whose rays hit a plain diffuse triangle, or a diffuse one whose reflectance is a
    checkerboard of two colours, take their step in the vector lanes (kernels/packet_lanes.h), on
    every runtime, whether or not it is the runtime's default: with it and without it, the
    megakernel's paths (across the estimator choices and a depth limit, with point and area lights
    and two-sided walls in "surfaces", those walls checkered in "checkers", textured_cbox's
    checkered wall beside its rough, bitmap-textured and bump-mapped bsdfs), and the same bits."""
    _cpu(device)
    lanes = wavefront.diffuse_lanes(Renderer(_scene(name), device=device, engine="megakernel").packed)
    assert lanes is not None and lanes[4] == (name in ("checkers", "textured_cbox")), name
    for what in sorted(CASES):
        estimator, defaults = CASES[what]
        scene = _scene(name, **defaults)
        mk = Renderer(scene, device=device, estimator=estimator, seed=5, engine="megakernel").render(4)
        images = []
        for vector in (True, False):
            r = _packet_renderer(scene, device, estimator, vector)
            assert r.wavefront.vector_step == vector, what
            images.append(r.render(4))
            _assert_same_paths(mk, images[-1])
        np.testing.assert_array_equal(images[0].image, images[1].image, err_msg=what)


@pytest.mark.parametrize("name", ["rough", "rough_constant", "textured_cbox"])
def test_rough_step_takes_the_rough_plastic_lanes(device, name):
    """Lanes whose rays hit a rough plastic triangle the step handles (kernels/lanes_rough.h: GGX,
    a bitmap reflectance mirrored at its edges under a to_uv in "rough", a constant nonlinear one
    in "rough_constant", textured_cbox's tiled floor beside bsdfs it leaves to the scalar steps)
    take their step in the vector lanes, on every runtime when asked to: the megakernel's image
    within the standard errors across the estimator choices and a depth limit, with point and area
    lights and two-sided walls; and on PoCL, where it is the default, for one seed the megakernel's
    paths and the bits of the scalar steps. (Intel's runtime rounds the step's vector code
    otherwise than its scalar code, so one seed's paths part there: about 1% of the channels.)"""
    _cpu(device)
    lanes = wavefront.diffuse_lanes(Renderer(_scene(name), device=device, engine="megakernel").packed, bsdfs=True)
    assert lanes is not None and lanes.rough == 1 and lanes.bitmaps == (name != "rough_constant"), name
    for what in sorted(CASES):
        estimator, defaults = CASES[what]
        scene = _scene(name, **defaults)
        mk = Renderer(scene, device=device, estimator=estimator, seed=5, engine="megakernel")
        rough = _packet_renderer(scene, device, estimator, True, True)
        assert rough.wavefront.bsdf_steps == ("rough",), what
        other = Renderer(scene, device=device, estimator=estimator, seed=6, engine="packet")
        other.wavefront = rough.wavefront
        assert_same_image(mk.render(32), other.render(32), what=f"{name}, {what}: megakernel and rough step")
        if packets.bsdf_steps_pay(device):
            mk.reset()
            image = rough.render(4)
            _assert_same_paths(mk.render(4), image)
            scalar = _packet_renderer(scene, device, estimator, True, False)
            assert scalar.wavefront.bsdf_steps == ()
            np.testing.assert_array_equal(image.image, scalar.render(4).image, err_msg=what)


@pytest.mark.parametrize("change, taken", [
    ("", True),
    ('<string name="distribution" value="beckmann"/>', False),
    ('<boolean name="sample_visible" value="false"/>', False),
    ('<texture type="bitmap" name="diffuse_reflectance"><string name="filename" value="textures/tiles.png"/>'
     '<string name="filter_type" value="nearest"/></texture>', False),
    ('<texture type="bitmap" name="diffuse_reflectance"><string name="filename" value="textures/bumps.exr"/>'
     '</texture>', False),
    ('<texture type="checkerboard" name="diffuse_reflectance"/>', False),
])
def test_which_rough_plastics_the_rough_step_takes(device, change, taken):
    """The rough step takes GGX sampled by its visible normals with a constant or bilinear
    byte-coded bitmap reflectance (Mitsuba's roughplastic is isotropic, its roughness a number);
    it leaves Beckmann, all-normal sampling, nearest lookups, float texels and checkerboards to the
    scalar steps, as it does a roughplastic inside a bump map."""
    _cpu(device)
    default = '' if "distribution" in change else '<string name="distribution" value="ggx"/>'
    alpha = '' if "alpha" in change else '<float name="alpha" value="0.2"/>'
    panel = ('<shape type="rectangle"><transform name="to_world"><scale value="0.3"/><translate y="1" z="0.5"/>'
             f'</transform><bsdf type="roughplastic">{default}{alpha}{change}</bsdf></shape>')
    for wrapped in (False, True):
        text = panel.replace('<bsdf type="roughplastic">', '<bsdf type="bumpmap"><texture type="bitmap" '
                             'name="map"><string name="filename" value="textures/bumps.exr"/></texture>'
                             '<bsdf type="roughplastic">').replace("</bsdf></shape>", "</bsdf></bsdf></shape>") \
            if wrapped else panel
        packed = Renderer(cbox_with(text), device=device, engine="megakernel").packed
        lanes = wavefront.diffuse_lanes(packed, bsdfs=True)
        assert lanes is not None
        assert lanes.rough == (taken and not wrapped), (change, wrapped)


def test_vector_step_only_where_it_can(device):
    """PoCL takes the vector step by default, Intel's runtime not (its compiler leaves the loop
    scalar); beside a light the lanes cannot sample (a spherical area light) every lane's step is
    the scalar one."""
    _cpu(device)
    default = Renderer(_scene("cbox", 8), device=device, engine="packet").wavefront.vector_step
    assert default == ("portable computing language" in device.platform_name.lower())
    assert _packet_renderer(_scene("cbox", 8), device).wavefront.vector_step
    lit = cbox_with('<shape type="sphere"><float name="radius" value="0.05"/>'
                    '<emitter type="area"><rgb name="radiance" value="3"/></emitter></shape>')
    assert not _packet_renderer(lit, device).wavefront.vector_step
