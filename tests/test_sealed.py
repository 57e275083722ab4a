"""Sealed media (volcl/sealed.py): which media the kernels skip NEE in, and that skipping it leaves
the image's expectation as it was (and that the comparison sees a medium sealed that should not be)."""
import numpy as np
import pytest

import volcl
from volcl import pack
from volcl.pack import Packer

from imagestats import assert_same_image

SCENE = """<scene version="3.0.0">
    <integrator type="volpath"><integer name="max_depth" value="12"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0.3, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="16"/></film>
        {camera_medium}
    </sensor>
    <medium type="homogeneous" id="milk">
        <rgb name="sigma_t" value="2, 3, 4"/><rgb name="albedo" value="0.9, 0.8, 0.95"/>
        <phase type="hg"><float name="g" value="0.5"/></phase>
    </medium>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/><translate y="-0.8"/></transform>
        <bsdf type="diffuse"/>
    </shape>
    <shape type="{kind}">
        {placement}
        {bsdf}
        <ref name="interior" id="milk"/>
        {extra}
    </shape>
    {lights}
</scene>"""
SPHERE = '<point name="center" value="0, 0, 0"/><float name="radius" value="0.7"/>'
CUBE = '<transform name="to_world"><scale value="0.6"/></transform>'
OUTSIDE = """<emitter type="point" id="bulb"><point name="position" value="1.5, 2, 1"/><rgb name="intensity" value="6"/></emitter>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="2.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="3"/></emitter>
    </shape>"""
INSIDE = '<emitter type="point"><point name="position" value="0.1, 0, 0"/><rgb name="intensity" value="2"/></emitter>'
GLASS = '<bsdf type="dielectric"><float name="int_ior" value="1.33"/></bsdf>'


def scene(kind="sphere", bsdf=GLASS, lights=OUTSIDE, extra="", camera_medium="", placement=None):
    return volcl.load_string(SCENE.format(kind=kind, bsdf=bsdf, lights=lights, extra=extra,
                                          camera_medium=camera_medium,
                                          placement=placement or (SPHERE if kind == "sphere" else CUBE)))


def sealed(s) -> list:
    packer = Packer(s.model)
    packed = packer.pack()
    return [bool(x) for x in packed.arrays["media"]["sealed"][:len(packer.media)]]


def test_a_medium_inside_closed_glass_lit_from_outside_is_sealed():
    assert sealed(scene()) == [True]
    assert sealed(scene(kind="cube")) == [True]
    assert sealed(scene(bsdf='<bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf>')) == [True]
    assert sealed(scene(bsdf='<bsdf type="diffuse"/>')) == [True]        # opaque walls seal as well


@pytest.mark.parametrize("what, kwargs", [
    ("a null boundary", dict(bsdf='<bsdf type="null"/>')),
    ("a thin dielectric, which passes shadow rays", dict(bsdf='<bsdf type="thindielectric"/>')),
    ("a mask", dict(bsdf='<bsdf type="mask"><float name="opacity" value="0.9"/>' + GLASS + '</bsdf>')),
    ("a point light inside", dict(lights=OUTSIDE + INSIDE)),
    ("an emitting boundary", dict(extra='<emitter type="area"><rgb name="radiance" value="1"/></emitter>')),
    ("an open surface", dict(kind="rectangle")),
    ("a cube turned inside out", dict(kind="cube", extra='<boolean name="flip_normals" value="true"/>')),
    ("the camera inside it", dict(camera_medium='<ref id="milk"/>')),
])
def test_what_keeps_a_medium_unsealed(what, kwargs):
    assert sealed(scene(**kwargs)) == [False], what


def test_a_medium_outside_some_shape_is_not_sealed():
    s = scene(lights=OUTSIDE + """<shape type="sphere"><point name="center" value="0, 0, 0"/>
        <float name="radius" value="0.2"/><bsdf type="diffuse"/><ref name="exterior" id="milk"/></shape>""")
    assert sealed(s) == [False]


def test_a_mesh_with_a_hole_is_not_closed():
    s = scene(kind="cube")
    cube = next(sh for sh in s.model.shapes if sh.interior is not None)
    cube.faces = cube.faces[1:]
    assert sealed(s) == [False]


def test_moving_a_light_inside_unseals_the_medium(device):
    """The verdict follows edits: the point light moved into the sphere (an edit that repacks the
    lights only) renders what loading it there renders, bit for bit."""
    s = scene()
    volcl.render(s, spp=1, device=device)
    params = volcl.traverse(s)
    params["bulb.position"] = [0.1, 0.0, 0.0]
    assert "media" in params.update().arrays
    moved = scene(lights=OUTSIDE.replace("1.5, 2, 1", "0.1, 0, 0"))
    assert sealed(moved) == [False]
    a, b = (volcl.render(x, spp=16, seed=4, device=device) for x in (s, moved))
    assert a.image.tobytes() == b.image.tobytes()


@pytest.mark.every_implementation
@pytest.mark.parametrize("kind", ["sphere", "cube"])
def test_skipping_nee_in_a_sealed_medium_keeps_the_image(device, monkeypatch, kind):
    """Sealed and not sealed (the verdict forced off): independent renders of one expectation."""
    s = scene(kind=kind)
    assert sealed(s) == [True]
    skipped = volcl.render(s, spp=1024, seed=1, device=device)
    monkeypatch.setattr(pack, "sealed_media", lambda scene, media, *rest: [False] * len(media))
    full = volcl.render(scene(kind=kind), spp=1024, seed=2, device=device)
    assert_same_image(skipped, full, what=f"a sealed {kind}: NEE skipped against NEE traced")


@pytest.mark.every_implementation
def test_the_comparison_sees_a_medium_sealed_with_a_light_inside(device, monkeypatch):
    """A point light inside the glass: forced sealed, its light through the milk is lost, and the
    comparison above reports it."""
    truth = volcl.render(scene(lights=OUTSIDE + INSIDE), spp=1024, seed=1, device=device)
    monkeypatch.setattr(pack, "sealed_media", lambda scene, media, *rest: [True] * len(media))
    wrong = volcl.render(scene(lights=OUTSIDE + INSIDE), spp=1024, seed=2, device=device)
    with pytest.raises(AssertionError, match="difference"):
        assert_same_image(wrong, truth)
    assert np.mean(wrong.image) < np.mean(truth.image)
