"""Mitsuba's envmap and spot emitters in scene files: parameters and defaults, bad input named with file,
line, element and what was tried, the feature flags they compile, the device memory the map takes,
and their traverse() parameters (each edit renders bit for bit what loading the value renders)."""
import re
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

import volcl
from volcl import device as devmod
from volcl.errors import VolclError
from volcl.features import detect
from volcl.renderer import Renderer
from volcl.scene import load
from volcl.scene import transform as tf

from test_api import same, text
from test_device import _small_device

SENSOR = ('<sensor type="perspective"><float name="fov" value="40"/><transform name="to_world">'
          '<lookat origin="0, 0.5, 3" target="0, 0, 0"/></transform><sampler type="independent">'
          '<integer name="sample_count" value="4"/></sampler><film type="hdrfilm"><integer name="width" value="12"/>'
          '<integer name="height" value="10"/><rfilter type="box"/></film></sensor>'
          '<integrator type="volpath"/>')


def write_image(path, pixels, fmt=oiio.FLOAT):
    pixels = np.asarray(pixels)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(np.ascontiguousarray(pixels))
    out.close()


def sky(h=8, w=16):
    rng = np.random.default_rng(2)
    return (rng.random((h, w, 3)) + 0.1).astype(np.float32)


def scene_file(tmp_path, body, name="scene.xml", **defines):
    path = tmp_path / name
    path.write_text(f'<scene version="3.0.0">\n{SENSOR}\n{body}\n</scene>\n')
    return load(path, {k: str(v) for k, v in defines.items()} or None)


ENVMAP = '<emitter type="envmap" id="env"><string name="filename" value="{file}"/>{extra}</emitter>'


def test_envmap_parameters(tmp_path):
    write_image(tmp_path / "sky.exr", sky())
    rot = '<transform name="to_world"><rotate y="1" angle="30"/></transform>'
    sc = scene_file(tmp_path, ENVMAP.format(file="sky.exr", extra='<float name="scale" value="2.5"/>' + rot))
    (e,) = sc.emitters
    assert e.kind == "envmap" and e.id == "env" and e.scale == 2.5
    assert e.filename == str(tmp_path / "sky.exr")
    np.testing.assert_array_equal(e.image, sky())
    np.testing.assert_allclose(e.to_world, tf.rotate([0, 1, 0], 30))
    flags = detect(sc)
    assert flags["ENV_LIGHTS"] and flags["ENVMAP"] and not flags["SPOT_LIGHTS"]
    assert sc.warnings == []


def test_envmap_of_an_srgb_png(tmp_path):
    """8-bit images are sRGB-decoded, as Mitsuba decodes them (volcl.scene.images)."""
    codes = np.array([[[0, 128, 255], [64, 32, 16]], [[255, 255, 255], [10, 20, 30]]], np.uint8)
    codes = np.repeat(codes, 2, axis=1)       # 4 x 2: 2:1
    write_image(tmp_path / "sky.png", codes, oiio.UINT8)
    (e,) = scene_file(tmp_path, ENVMAP.format(file="sky.png", extra="")).emitters
    from volcl.scene.images import srgb_decode
    np.testing.assert_allclose(e.image, srgb_decode(codes / 255.0), rtol=1e-5, atol=1e-7)


def test_envmap_of_a_radiance_hdr_file(tmp_path):
    """RGBE (.hdr) files are linear: 8-bit mantissas under an exponent shared by the texel's channels,
    so each channel is within 1/128 of the texel's largest one of what was written."""
    written = sky() * 50.0
    write_image(tmp_path / "sky.hdr", written)
    (e,) = scene_file(tmp_path, ENVMAP.format(file="sky.hdr", extra="")).emitters
    assert e.image.shape == (8, 16, 3)
    assert np.all(np.abs(e.image - written) <= written.max(axis=-1, keepdims=True) / 128)


def test_envmap_that_is_not_two_to_one_is_read_as_mitsuba_reads_it(tmp_path):
    write_image(tmp_path / "square.exr", sky(8, 8))
    sc = scene_file(tmp_path, ENVMAP.format(file="square.exr", extra=""))
    assert sc.emitters[0].image.shape == (8, 8, 3)
    (warning,) = sc.warnings
    assert re.search(r"scene\.xml:\d+: <string\b", warning), warning
    assert "8x8 texels, not 2:1" in warning and "as Mitsuba reads it" in warning


def test_envmap_mis_compensation_is_a_warning(tmp_path):
    write_image(tmp_path / "sky.exr", sky())
    sc = scene_file(tmp_path, ENVMAP.format(file="sky.exr", extra='<boolean name="mis_compensation" value="true"/>'))
    assert any("'mis_compensation' is ignored" in w for w in sc.warnings)


def _error(tmp_path, body, **defines):
    with pytest.raises(VolclError) as info:
        scene_file(tmp_path, body, **defines)
    return str(info.value)


def test_missing_envmap_names_file_line_element_and_the_path_tried(tmp_path):
    message = _error(tmp_path, ENVMAP.format(file="textures/nope.exr", extra=""))
    assert re.search(r"scene\.xml:\d+: <string\b", message), message
    assert "cannot load environment map 'textures/nope.exr': file not found" in message
    assert str(tmp_path) in message


def test_unreadable_envmap_names_the_path(tmp_path):
    (tmp_path / "junk.exr").write_bytes(b"this is not an image")
    message = _error(tmp_path, ENVMAP.format(file="junk.exr", extra=""))
    assert re.search(r"scene\.xml:\d+: <string\b", message), message
    assert f"cannot read image {tmp_path / 'junk.exr'}" in message


@pytest.mark.parametrize("value, word", [(np.nan, "non-finite"), (-2.0, "negative"), (np.inf, "non-finite")])
def test_bad_texels_are_named(tmp_path, value, word):
    pixels = sky()
    pixels[5, 11, 1] = value
    write_image(tmp_path / "bad.exr", pixels)
    message = _error(tmp_path, ENVMAP.format(file="bad.exr", extra=""))
    assert re.search(r"scene\.xml:\d+: <string\b", message), message
    assert f"{word} texel" in message and "at x=11 y=5 channel=1" in message


@pytest.mark.parametrize("extra, words", [
    ('<float name="scale" value="-1"/>', "'scale' must be >= 0"),
    ('<transform name="to_world"><scale value="2"/></transform>', "may rotate and mirror, but not scale"),
    ('<transform name="to_world"><scale value="1, 1, 0.5"/></transform>', "may rotate and mirror, but not scale"),
    ('<float name="scale" value="1e38"/>', "beyond the single-precision range"),
    ('<string name="bitmap" value="x"/>', "unknown parameter 'bitmap'"),
])
def test_bad_envmap_parameters(tmp_path, extra, words):
    write_image(tmp_path / "sky.exr", sky() * 10)
    message = _error(tmp_path, ENVMAP.format(file="sky.exr", extra=extra))
    assert words in message and re.search(r"scene\.xml:\d+: <", message), message


def test_a_mirrored_envmap_is_fine(tmp_path):
    write_image(tmp_path / "sky.exr", sky())
    sc = scene_file(tmp_path, ENVMAP.format(file="sky.exr", extra='<transform name="to_world"><scale x="-1"/></transform>'))
    assert sc.emitters[0].to_world[0, 0] == -1


def test_only_one_environment(tmp_path):
    write_image(tmp_path / "sky.exr", sky())
    message = _error(tmp_path, ENVMAP.format(file="sky.exr", extra="")
                     + '<emitter type="constant"><rgb name="radiance" value="1"/></emitter>')
    assert "only one environment emitter" in message and "the first is at line" in message
    # two constants add up, as volcl always rendered them
    sc = scene_file(tmp_path, '<emitter type="constant"/>' * 2)
    assert [e.kind for e in sc.emitters] == ["constant", "constant"]


def test_spot_defaults_and_parameters(tmp_path):
    sc = scene_file(tmp_path, '<emitter type="spot" id="lamp"/>')
    (e,) = sc.emitters
    assert (e.kind, e.cutoff_angle, e.beam_width) == ("spot", 20.0, 15.0)
    np.testing.assert_array_equal(e.value, [1, 1, 1])
    np.testing.assert_array_equal(e.position, [0, 0, 0])
    sc = scene_file(tmp_path, '<emitter type="spot"><rgb name="intensity" value="3, 2, 1"/>'
                              '<float name="cutoff_angle" value="40"/><float name="beam_width" value="10"/>'
                              '<transform name="to_world"><lookat origin="1, 2, 3" target="0, 0, 0"/></transform>'
                              '</emitter>')
    (e,) = sc.emitters
    assert (e.cutoff_angle, e.beam_width) == (40.0, 10.0)
    np.testing.assert_allclose(e.position, [1, 2, 3])
    np.testing.assert_allclose(e.to_world[:3, 2], -np.array([1, 2, 3]) / np.sqrt(14))
    flags = detect(sc)
    assert flags["SPOT_LIGHTS"] and not flags["ENV_LIGHTS"] and not flags["EQUIANGULAR"]


def test_spot_in_fog_compiles_equiangular_sampling(tmp_path):
    sc = scene_file(tmp_path, '<emitter type="spot"/><shape type="sphere"><float name="radius" value="3"/>'
                              '<bsdf type="null"/><medium type="homogeneous" name="interior"/></shape>')
    assert detect(sc)["EQUIANGULAR"]


@pytest.mark.parametrize("extra, words", [
    ('<float name="cutoff_angle" value="0"/>', "'cutoff_angle' must lie in (0, 180]"),
    ('<float name="cutoff_angle" value="200"/>', "'cutoff_angle' must lie in (0, 180]"),
    ('<float name="beam_width" value="-3"/>', "'beam_width' must lie in [0, 180]"),
    ('<texture type="checkerboard" name="pattern"/>', "a texture named 'pattern' is not a parameter"),
    ('<rgb name="texture" value="0.5"/>', "texture"),
])
def test_bad_spot_parameters(tmp_path, extra, words):
    message = _error(tmp_path, f'<emitter type="spot">{extra}</emitter>')
    assert words in message and re.search(r"scene\.xml:\d+: <", message), message


def test_spot_beam_wider_than_its_cutoff_warns(tmp_path):
    sc = scene_file(tmp_path, '<emitter type="spot"><float name="cutoff_angle" value="10"/>'
                              '<float name="beam_width" value="30"/></emitter>')
    assert any("hard-edged cone" in w for w in sc.warnings)


def test_envmap_memory_is_counted_before_upload(tmp_path):
    """The map's texels and sampling tables are a buffer of their own (env_data) in the pre-upload
    check: too large for the device, an error names it and what to make smaller."""
    write_image(tmp_path / "sky.exr", sky(64, 128))
    sc = scene_file(tmp_path, ENVMAP.format(file="sky.exr", extra=""))
    prepared = volcl.Scene(sc)
    sizes = prepared.buffer_sizes()
    from volcl.envmap import table_size
    assert sizes["env_data"] == 4 * table_size(128, 64)
    with pytest.raises(VolclError) as info:
        Renderer(prepared, device=_small_device(global_mem=1 << 30, max_alloc=sizes["env_data"] - 1))
    message = str(info.value)
    assert "its env_data buffer needs" in message and "a smaller environment map" in message
    devmod.check_fits(_small_device(global_mem=1 << 30, max_alloc=sizes["env_data"]), sizes)


# ---- traverse() ----------------------------------------------------------------------------------

ROTATED = tf.rotate([0.2, 1.0, 0.1], 35.0)
SPOT_FRAME = tf.lookat([0.8, 1.6, 0.9], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])

TEMPLATE = f"""<scene version="3.0.0">
    <default name="scale" value="1.5"/>
    <default name="map" value="sky.exr"/>
    <default name="env_frame" value="{text(ROTATED).replace(',', '')}"/>
    <default name="intensity" value="4, 3, 2"/>
    <default name="cutoff" value="35"/>
    <default name="beam" value="20"/>
    <default name="spot_frame" value="{text(SPOT_FRAME).replace(',', '')}"/>
    {SENSOR.replace('<integrator type="volpath"/>', '')}
    <integrator type="volpath"><integer name="max_depth" value="5"/></integrator>
    <emitter type="envmap" id="env">
        <string name="filename" value="$map"/>
        <float name="scale" value="$scale"/>
        <transform name="to_world"><matrix value="$env_frame"/></transform>
    </emitter>
    <emitter type="spot" id="lamp">
        <rgb name="intensity" value="$intensity"/>
        <float name="cutoff_angle" value="$cutoff"/>
        <float name="beam_width" value="$beam"/>
        <transform name="to_world"><matrix value="$spot_frame"/></transform>
    </emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>
        <translate y="-0.5"/></transform></shape>
    <shape type="sphere"><float name="radius" value="0.5"/><bsdf type="null"/>
        <medium type="homogeneous" name="interior"><rgb name="sigma_t" value="2"/><float name="albedo" value="0.8"/></medium>
    </shape>
</scene>
"""

EDITS = [
    ("env.scale", "scale", 0.7),
    ("env.to_world", "env_frame", tf.rotate([1.0, 0.0, 0.3], -70.0)),
    ("lamp.intensity.value", "intensity", (1.0, 2.0, 5.0)),
    ("lamp.cutoff_angle", "cutoff", 50.0),
    ("lamp.beam_width", "beam", 5.0),
    ("lamp.to_world", "spot_frame", tf.lookat([-0.5, 1.2, 1.0], [0.2, 0.0, 0.0], [0.0, 1.0, 0.0])),
]


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    folder = tmp_path_factory.mktemp("env_traverse")
    write_image(folder / "sky.exr", sky())
    write_image(folder / "other.exr", sky()[::-1] * 2.0)
    return folder


def load_template(folder, **values):
    return volcl.load_string(TEMPLATE, base_dir=folder, **{k: text(v).replace(",", "") if np.ndim(v) == 2
                                                           else (v if isinstance(v, str) else text(v))
                                                           for k, v in values.items()})


@pytest.mark.parametrize("key, define, value", EDITS, ids=[e[0] for e in EDITS])
def test_an_edit_renders_what_loading_the_value_renders_bit_for_bit(device, maps, key, define, value):
    original = volcl.render(load_template(maps), seed=3, device=device)
    scene = load_template(maps)
    params = volcl.traverse(scene)
    params[key] = value
    params.update()
    edited = volcl.render(scene, seed=3, device=device)
    loaded = volcl.render(load_template(maps, **{define: value}), seed=3, device=device)
    assert same(edited, loaded), key
    assert not np.array_equal(edited.image, original.image), f"{key}: the edit changed nothing"


def test_envmap_data_edit_renders_what_the_file_renders(device, maps):
    scene = load_template(maps)
    params = volcl.traverse(scene)
    assert set(k for k in params if k.startswith(("env.", "lamp."))) == {e[0] for e in EDITS} | {"env.data"}
    other = volcl.load_string(TEMPLATE, base_dir=maps, map="other.exr")
    params["env.data"] = other.model.emitters[0].image
    update = params.update()
    assert update.arrays == ["env_data"]
    assert same(volcl.render(scene, seed=3, device=device), volcl.render(other, seed=3, device=device))
    with pytest.raises(VolclError, match=r"must keep the image's shape"):
        params["env.data"] = sky(4, 8)
    bad = sky()
    bad[1, 2, 0] = -1.0
    with pytest.raises(VolclError, match=r"negative texel -1.0 at x=2 y=1 channel=0"):
        params["env.data"] = bad


def test_editing_another_light_keeps_the_envmap_tables(maps):
    scene = load_template(maps)
    before = scene.packed.arrays["env_data"]
    params = volcl.traverse(scene)
    params["lamp.intensity.value"] = 2.0
    update = params.update()
    assert update.arrays == ["lights"] and scene.packed.arrays["env_data"] is before


@pytest.mark.parametrize("key, value, file_change", [
    ("env.scale", -1.0, ('name="scale" value="$scale"', 'name="scale" value="-1"')),
    ("env.to_world", np.diag([2.0, 2.0, 2.0, 1.0]), ('<matrix value="$env_frame"/>', '<scale value="2"/>')),
    ("lamp.cutoff_angle", 0.0, ('name="cutoff_angle" value="$cutoff"', 'name="cutoff_angle" value="0"')),
    ("lamp.beam_width", 190.0, ('name="beam_width" value="$beam"', 'name="beam_width" value="190"')),
], ids=lambda v: v if isinstance(v, str) else None)
def test_bad_values_get_the_parsers_messages(maps, key, value, file_change):
    with pytest.raises(VolclError) as info:
        volcl.load_string(TEMPLATE.replace(*file_change), base_dir=maps)
    expected = re.sub(r"^<string>:\d+: <[^>]*>: ", "", str(info.value))
    params = volcl.traverse(load_template(maps))
    with pytest.raises(VolclError) as info:
        params[key] = value
    assert expected in str(info.value), (str(info.value), expected)


def test_environment_through_an_unbounded_camera_medium_warns(tmp_path):
    fog = '<medium type="homogeneous" id="fog"><float name="sigma_t" value="0.1"/></medium>'
    sensor = SENSOR.replace('<sampler', '<ref id="fog"/><sampler')
    path = tmp_path / "fog.xml"
    path.write_text(f'<scene version="3.0.0">{fog}{sensor}<emitter type="constant"/></scene>')
    assert any("not enclosed by a shape" in w for w in load(path).warnings)
    bounded = (f'<scene version="3.0.0">{fog}{sensor}<emitter type="constant"/><shape type="sphere">'
               '<float name="radius" value="10"/><bsdf type="null"/><ref name="interior" id="fog"/></shape></scene>')
    path.write_text(bounded)
    assert not any("not enclosed" in w for w in load(path).warnings)


def test_spot_projection_texture(tmp_path):
    """Mitsuba's spot `texture`: read like any colour texture, packed with the scene's textures
    (after the bsdfs'), and it switches on the texture code."""
    write_image(tmp_path / "slide.png", np.full((4, 6, 3), 0.5, np.float32), fmt=oiio.UINT8)
    sc = scene_file(tmp_path, '<emitter type="spot"><texture type="bitmap" name="texture">'
                              '<string name="filename" value="slide.png"/></texture></emitter>'
                              '<shape type="sphere"><bsdf type="diffuse"><texture type="checkerboard" '
                              'name="reflectance"/></bsdf></shape>')
    spot = [e for e in sc.emitters if e.kind == "spot"][0]
    assert spot.texture is not None and spot.texture.data.shape == (4, 6, 3)
    assert detect(sc)["TEXTURES"]
    from volcl.pack import pack
    packed = pack(sc)
    light = [r for r in packed.arrays["lights"] if r["type"] == 5][0]
    assert light["texture"] == 1 and packed.arrays["textures"][1]["width"] == 6
    assert np.isclose(light["tan_cutoff"], np.tan(np.radians(20.0)))


SLIDE_SCENE = TEMPLATE.replace(
    '<transform name="to_world"><matrix value="$spot_frame"/></transform>',
    '<transform name="to_world"><matrix value="$spot_frame"/></transform>'
    '<texture type="bitmap" name="texture"><string name="filename" value="$slide"/></texture>')


def test_spot_texture_edits_render_what_the_file_renders(device, maps):
    """The spot's projection texture gives its own keys under `texture` (Mitsuba's name), and an
    edit of its texels renders bit for bit what loading the other image renders."""
    write_image(maps / "slide_a.exr", 0.5 * sky(4, 6))
    write_image(maps / "slide_b.exr", 0.25 * sky(4, 6)[::-1])
    scene = volcl.load_string(SLIDE_SCENE, base_dir=maps, slide="slide_a.exr")
    params = volcl.traverse(scene)
    assert {"lamp.texture.data", "lamp.texture.to_uv"} <= set(params)
    original = volcl.render(scene, seed=3, device=device)
    other = volcl.load_string(SLIDE_SCENE, base_dir=maps, slide="slide_b.exr")
    params["lamp.texture.data"] = other.model.emitters[1].texture.data
    update = params.update()
    assert "texels" in update.arrays and "env_data" not in update.arrays
    edited = volcl.render(scene, seed=3, device=device)
    assert same(edited, volcl.render(other, seed=3, device=device))
    assert not np.array_equal(edited.image, original.image), "the edit changed nothing"
