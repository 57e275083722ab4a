"""Reading Mitsuba's rough and layered bsdfs and its textures: defaults and rules as Mitsuba 3.9
has them, conductor presets, bad input named by file, line, element and path, the kernel features
they switch on, traverse() keys, and edits that render bit for bit what the edited file renders."""
import numpy as np
import pytest

import volcl
from volcl import device as devmod
from volcl.errors import VolclError
from volcl.features import detect
from volcl.pack import pack
from volcl.scene import load, load_string
from volcl.scene.conductors import PRESETS
from volcl.scene.model import Texture

M = '<scene version="3.0.0">\n{}\n</scene>\n'      # body starts on line 2


def bsdf_of(xml, tmp_path=None):
    return load_string(M.format(f'<shape type="sphere">{xml}</shape>'), base_dir=tmp_path).shapes[0].bsdf


def expect_error(tmp_path, body, line, *fragments):
    path = tmp_path / "scene.xml"
    path.write_text(M.format(body))
    with pytest.raises(VolclError) as info:
        load(path)
    message = str(info.value)
    assert f"scene.xml:{line}:" in message, message
    for fragment in fragments:
        assert fragment in message, message
    return message


def write_image(path, pixels, fmt="float"):
    import OpenImageIO as oiio
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()


def test_defaults_are_mitsubas():
    b = bsdf_of('<bsdf type="roughconductor"/>')
    assert (b.distribution, b.alpha_u, b.alpha_v, b.sample_visible, b.anisotropic) == ("beckmann", 0.1, 0.1, True, False)
    assert b.eta is None        # material "none": eta 0, k 1, which reflects everything
    b = bsdf_of('<bsdf type="roughdielectric"/>')
    assert (b.int_ior, b.ext_ior, b.distribution, b.alpha_u) == (1.5046, 1.000277, "beckmann", 0.1)
    b = bsdf_of('<bsdf type="plastic"/>')
    assert (b.int_ior, b.ext_ior, b.nonlinear) == (1.49, 1.000277, False)
    np.testing.assert_array_equal(b.reflectance, 0.5)
    b = bsdf_of('<bsdf type="roughplastic"><string name="distribution" value="GGX"/></bsdf>')
    assert (b.distribution, b.alpha_u) == ("ggx", 0.1)
    b = bsdf_of('<bsdf type="thindielectric"/>')
    assert (b.int_ior, b.ext_ior) == (1.5046, 1.000277)
    b = bsdf_of('<bsdf type="mask"><bsdf type="diffuse"/></bsdf>')
    assert b.opacity == 0.5 and b.nested.kind == "diffuse"
    b = bsdf_of('<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf>')
    assert (b.alpha_u, b.alpha_v, b.anisotropic) == (0.1, 0.3, True)


def test_conductor_presets():
    b = bsdf_of('<bsdf type="roughconductor"><string name="material" value="Au"/></bsdf>')
    np.testing.assert_array_equal(b.eta, PRESETS["Au"][0])
    np.testing.assert_array_equal(b.k, PRESETS["Au"][1])
    assert b.material == "Au"
    b = bsdf_of('<bsdf type="conductor"><string name="material" value="Cu_palik"/></bsdf>')
    np.testing.assert_array_equal(b.k, PRESETS["Cu_palik"][1])
    assert len(PRESETS) == 71


@pytest.mark.parametrize("body, line, fragments", [
    ('<bsdf type="roughconductor">\n<string name="material" value="Au"/><rgb name="eta" value="1"/></bsdf>', 3,
     ("either eta and k or a conductor material",)),
    ('<bsdf type="roughconductor">\n<string name="material" value="gold"/></bsdf>', 3, ("'gold'", "Au", "Ag")),
    ('<bsdf type="roughconductor">\n<float name="alpha_u" value="0.1"/></bsdf>', 3, ("both 'alpha_u' and 'alpha_v'",)),
    ('<bsdf type="roughdielectric"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.1"/>\n'
     '<float name="alpha" value="0.1"/></bsdf>', 3, ("either 'alpha' or",)),
    ('<bsdf type="roughconductor">\n<string name="distribution" value="phong"/></bsdf>', 3, ("'phong'", "beckmann, ggx")),
    ('<bsdf type="roughplastic">\n<float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.2"/></bsdf>', 3,
     ("anisotropic",)),
    ('<bsdf type="roughplastic">\n<texture type="checkerboard" name="alpha"/></bsdf>', 3, ("must be a number",)),
    ('<bsdf type="roughdielectric">\n<float name="int_ior" value="1.3"/><float name="ext_ior" value="1.3"/></bsdf>', 3,
     ("must differ",)),
    ('<bsdf type="twosided">\n<bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>', 3, ("mask", "transmission")),
    ('<bsdf type="twosided">\n<bsdf type="roughdielectric"/></bsdf>', 3, ("roughdielectric", "transmission")),
    ('<bsdf type="bumpmap"><texture type="checkerboard"/>\n<bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>', 3,
     ("mask outermost",)),
    ('<bsdf type="bumpmap">\n<texture type="checkerboard"/><bsdf type="diffuse"/></bsdf>', 3, ("bitmap",)),
    ('<bsdf type="bumpmap">\n<bsdf type="diffuse"/></bsdf>', 2, ("exactly one texture",)),
    ('<bsdf type="normalmap">\n<bsdf type="diffuse"/></bsdf>', 2, ("'normalmap'",)),
    ('<bsdf type="mask">\n<float name="opacity" value="0.3"/></bsdf>', 2, ("exactly one bsdf",)),
    ('<bsdf type="diffuse">\n<texture type="checkerboard" name="albedo"/></bsdf>', 3,
     ("'albedo'", "reflectance")),
    ('<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/>\n<texture type="checkerboard" name="reflectance"/>'
     '</bsdf>', 3, ("both as a property",)),
    ('<bsdf type="diffuse"><texture type="bitmap" name="reflectance">\n<string name="wrap_mode" value="wrap"/>'
     '<string name="filename" value="x.exr"/></texture></bsdf>', 3, ("'wrap'", "repeat, mirror, clamp")),
    ('<bsdf type="diffuse"><texture type="bitmap" name="reflectance">\n<string name="filter_type" value="cubic"/>'
     '<string name="filename" value="x.exr"/></texture></bsdf>', 3, ("'cubic'", "bilinear, nearest")),
    ('<bsdf type="diffuse"><texture type="checkerboard" name="reflectance">\n<float name="scale" value="2"/>'
     '</texture></bsdf>', 3, ("'scale'", "color0, color1, to_uv")),
])
def test_bad_bsdfs_and_textures(tmp_path, body, line, fragments):
    expect_error(tmp_path, f'<shape type="sphere">{body}</shape>', line, *fragments)


def test_missing_and_unreadable_images(tmp_path):
    """The error names the scene file, the line and element of the filename, and the path tried."""
    tex = ('<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">\n'
           '<string name="filename" value="{}"/></texture></bsdf></shape>')
    msg = expect_error(tmp_path, tex.format("nowhere.png"), 3, "<string", "'nowhere.png'", "not found",
                       str(tmp_path))
    assert "image" in msg
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    expect_error(tmp_path, tex.format("broken.png"), 3, "broken.png", "cannot read")


@pytest.mark.parametrize("bad, what", [(np.nan, "non-finite"), (-0.25, "negative")])
def test_bad_texels_are_named(tmp_path, bad, what):
    pixels = np.full((3, 4, 3), 0.5, np.float32)
    pixels[2, 1, 1] = bad
    write_image(tmp_path / "bad.exr", pixels)
    expect_error(tmp_path, '<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">\n'
                 '<string name="filename" value="bad.exr"/></texture></bsdf></shape>', 3,
                 what, "x=1 y=2 channel=1", "bad.exr")


def test_textures_by_reference_are_shared(tmp_path):
    write_image(tmp_path / "t.exr", np.random.default_rng(1).random((4, 4, 3)).astype(np.float32))
    sc = load_string(M.format(
        '<texture type="bitmap" id="wood"><string name="filename" value="t.exr"/></texture>'
        '<texture type="checkerboard" id="checks"><ref name="color1" id="wood"/></texture>'
        '<shape type="sphere"><bsdf type="diffuse"><ref name="reflectance" id="checks"/></bsdf></shape>'
        '<shape type="cube"><bsdf type="roughplastic"><ref name="diffuse_reflectance" id="wood"/></bsdf></shape>'),
        base_dir=tmp_path)
    checks, wood = sc.shapes[0].bsdf.reflectance, sc.shapes[1].bsdf.reflectance
    assert isinstance(checks, Texture) and checks.color1 is wood
    p = pack(sc)
    assert len(p.arrays["textures"]) == 2 and len(p.arrays["texels"]) == 48
    assert p.features["TEXTURES"] and p.features["ROUGHPLASTIC"] and p.features["DIFFUSE"]


def test_features_follow_the_bsdfs():
    sc = load_string(M.format(
        '<shape type="sphere"><bsdf type="mask"><bsdf type="twosided"><bsdf type="roughconductor"/></bsdf></bsdf></shape>'
        '<shape type="cube"><bsdf type="thindielectric"/></shape>'))
    f = detect(sc)
    assert f["MASK"] and f["ROUGHCONDUCTOR"] and f["THINDIELECTRIC"]
    assert not (f["TEXTURES"] or f["BUMP_MAPS"] or f["PLASTIC"] or f["CONDUCTOR"] or f["DIFFUSE"])


def test_volpath_with_thin_dielectric_and_path_warning():
    sc = load_string(M.format('<integrator type="path"><integer name="max_depth" value="5"/></integrator>'
                              '<shape type="cube"><bsdf type="thindielectric"/></shape>'))
    assert any("mask or thin dielectric" in w for w in sc.warnings)
    sc = load_string(M.format('<shape type="cube"><bsdf type="roughdielectric">'
                              '<boolean name="sample_visible" value="false"/></bsdf></shape>'))
    assert any("biases its image" in w for w in sc.warnings)


def test_texels_count_towards_the_device_memory_check(tmp_path):
    from test_device import _small_device
    # float texels (more than 256 values: not byte-coded)
    write_image(tmp_path / "big.exr", np.random.default_rng(3).random((64, 64, 3)).astype(np.float32))
    sc = load_string(M.format('<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
                              '<string name="filename" value="big.exr"/></texture></bsdf></shape>'), base_dir=tmp_path)
    p = pack(sc)
    sizes = {k: a.nbytes for k, a in p.arrays.items()}
    assert sizes["texels"] == 64 * 64 * 3 * 4
    with pytest.raises(VolclError, match=r"its texels buffer needs .*\(smaller or fewer textures\)"):
        devmod.check_fits(_small_device(global_mem=1 << 30, max_alloc=40_000), sizes)


# ---- traverse ---------------------------------------------------------------------------------

TEMPLATE = """<scene version="3.0.0">
    <default name="alpha_u" value="0.2"/>
    <default name="alpha_v" value="0.05"/>
    <default name="alpha_g" value="0.2"/>
    <default name="alpha_p" value="0.2"/>
    <default name="opacity" value="0.6"/>
    <default name="color0" value="0.8, 0.2, 0.1"/>
    <default name="plastic" value="0.3, 0.5, 0.2"/>
    <default name="scale" value="4"/>
    <default name="int_ior" value="1.4"/>
    <default name="bump" value="0.5"/>
    <integrator type="volpath"><integer name="max_depth" value="6"/></integrator>
    <sensor type="perspective" id="cam">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 1.2, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="16"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
    <emitter type="point"><point name="position" value="1, 3, 2"/><rgb name="intensity" value="20"/></emitter>
    <texture type="checkerboard" id="checks">
        <rgb name="color0" value="$color0"/>
        <transform name="to_uv"><scale value="$scale"/></transform>
    </texture>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/><translate y="-1"/></transform>
        <bsdf type="diffuse" id="floor"><ref name="reflectance" id="checks"/></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" value="-0.9, 0, 0"/><float name="radius" value="0.6"/>
        <bsdf type="roughconductor" id="metal">
            <string name="material" value="Al"/><string name="distribution" value="ggx"/>
            <float name="alpha_u" value="$alpha_u"/><float name="alpha_v" value="$alpha_v"/>
        </bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" value="0.5, 0, 0.4"/><float name="radius" value="0.5"/>
        <bsdf type="roughdielectric" id="glass"><float name="alpha" value="$alpha_g"/>
            <float name="int_ior" value="$int_ior"/></bsdf>
    </shape>
    <shape type="cube">
        <transform name="to_world"><scale value="0.4"/><translate x="1.4" z="-0.8"/></transform>
        <bsdf type="mask" id="holes"><float name="opacity" value="$opacity"/>
            <bsdf type="roughplastic" id="shiny"><rgb name="diffuse_reflectance" value="$plastic"/>
                <float name="alpha" value="$alpha_p"/></bsdf>
        </bsdf>
    </shape>
    <shape type="disk">
        <transform name="to_world"><scale value="0.5"/><translate y="0.8" z="-1"/></transform>
        <bsdf type="bumpmap" id="bumpy"><float name="scale" value="$bump"/>
            <texture type="bitmap" name="heights"><string name="filename" value="heights.exr"/></texture>
            <bsdf type="diffuse"/>
        </bsdf>
    </shape>
</scene>
"""

EDITS = [
    ("checks.color0.value", "color0", (0.1, 0.7, 0.3)),
    ("checks.to_uv", "scale", 2.5),
    ("metal.alpha_u.value", "alpha_u", 0.45),
    ("metal.alpha_v.value", "alpha_v", 0.3),
    ("glass.alpha.value", "alpha_g", 0.45),
    ("glass.int_ior", "int_ior", 1.7),
    ("holes.opacity.value", "opacity", 0.3),
    ("shiny.diffuse_reflectance.value", "plastic", (0.7, 0.1, 0.1)),
    ("shiny.alpha", "alpha_p", 0.45),
    ("bumpy.scale", "bump", 1.5),
]


@pytest.fixture(scope="module")
def template_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("materials")
    y, x = np.mgrid[0:16, 0:16] / 16.0
    write_image(folder / "heights.exr", (0.5 + 0.5 * np.sin(6 * x + 3 * y))[..., None].astype(np.float32))
    return folder


def _load(folder, **values):
    def text(v):
        return ", ".join(repr(float(x)) for x in np.asarray(v, np.float64).reshape(-1))
    return volcl.load_string(TEMPLATE, base_dir=folder, **{k: text(v) for k, v in values.items()})


def _same(a, b):
    return a.image.tobytes() == b.image.tobytes() and a.variance.tobytes() == b.variance.tobytes()


def test_traverse_keys(template_dir):
    keys = set(volcl.traverse(_load(template_dir)))
    want = {"checks.color0.value", "checks.color1.value", "checks.to_uv", "metal.alpha_u.value", "metal.alpha_v.value",
            "metal.eta.value", "metal.k.value", "glass.alpha.value", "glass.int_ior", "holes.opacity.value",
            "shiny.diffuse_reflectance.value", "shiny.alpha", "bumpy.scale", "bumpy.nested_texture.data",
            "bumpy.nested_texture.to_uv"}
    assert want <= keys, want - keys
    assert "glass.specular_reflectance.value" not in keys      # Mitsuba lists it only where given
    assert "bumpy.nested_bsdf.reflectance.value" in keys


@pytest.mark.parametrize("key, define, value", EDITS, ids=[e[0] for e in EDITS])
def test_an_edit_renders_what_the_edited_file_renders(device, template_dir, key, define, value):
    scene = _load(template_dir)
    params = volcl.traverse(scene)
    if key == "checks.to_uv":
        params[key] = np.diag([value, value, 1.0])
    else:
        params[key] = value
    params.update()
    edited = volcl.render(scene, seed=4, device=device)
    loaded = volcl.render(_load(template_dir, **{define: value}), seed=4, device=device)
    assert _same(edited, loaded), key


def test_texture_data_edit_and_bad_texels(device, template_dir, tmp_path):
    scene = _load(template_dir)
    params = volcl.traverse(scene)
    data = params["bumpy.nested_texture.data"]
    flatter = data * np.float32(0.25)
    params["bumpy.nested_texture.data"] = flatter
    write_image(tmp_path / "heights.exr", flatter)
    edited = volcl.render(scene, seed=4, device=device)
    loaded = volcl.render(_load(tmp_path), seed=4, device=device)
    assert _same(edited, loaded)
    bad = flatter.copy()
    bad[3, 5, 0] = -1
    with pytest.raises(VolclError, match=r"negative texel -1.0 at x=5 y=3 channel=0"):
        params["bumpy.nested_texture.data"] = bad
    with pytest.raises(VolclError, match=r"must keep the texture's shape"):
        params["bumpy.nested_texture.data"] = flatter[1:]
