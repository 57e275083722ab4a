"""The Python API: loading, rendering, editing parameters with traverse() + update(), tiles, devices
and their program caches, results in notebooks and on disk."""
import io
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import volcl
from volcl.scene import transform as tf
from volcl.scene.volfile import read_vol, write_vol

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"


def same(a, b):
    return (a.spp == b.spp and a.invalid == b.invalid and a.image.tobytes() == b.image.tobytes()
            and a.variance.tobytes() == b.variance.tobytes())


def private_device(device):
    """A Device of its own (own context and program cache) for the same OpenCL device, so that
    build counts do not depend on what other tests built."""
    other = device.fresh()
    assert other is not device and other.key == device.key and other not in volcl.devices()
    return other


def text(value) -> str:
    """A value as a scene file writes it, exactly (repr round-trips every float64)."""
    a = np.asarray(value, np.float64).reshape(-1)
    return ", ".join(repr(float(x)) for x in a)


CAMERA = tf.lookat([0.0, 1.0, 4.5], [0.0, 0.8, 0.0], [0.0, 1.0, 0.0])
FLOOR = tf.rotate([1, 0, 0], -90) @ np.diag([3.0, 3.0, 1.0, 1.0])
BALL = tf.translate([-0.6, 0.5, 0.2]) @ np.diag([0.5, 0.5, 0.5, 1.0])

# Every kind of object traverse() knows, each value a <default> the tests override: a file loaded
# with a value is what an edit of that value must render.
TEMPLATE = f"""<scene version="3.0.0">
    <default name="sigma_t" value="0.4"/>
    <default name="albedo" value="0.7, 0.8, 0.9"/>
    <default name="scale" value="1.5"/>
    <default name="g" value="0.3"/>
    <default name="med_radiance" value="0.2"/>
    <default name="reflectance" value="0.6, 0.5, 0.4"/>
    <default name="int_ior" value="1.33"/>
    <default name="spec" value="0.9"/>
    <default name="eta" value="0.2, 0.9, 1.1"/>
    <default name="k" value="3.9, 2.4, 2.2"/>
    <default name="area" value="6"/>
    <default name="intensity" value="3"/>
    <default name="position" value="-0.3, 1.1, 0.4"/>
    <default name="irradiance" value="0.5"/>
    <default name="direction" value="0.2, -1, 0.3"/>
    <default name="env" value="0.1"/>
    <default name="floor" value="{text(FLOOR).replace(',', '')}"/>
    <default name="ball" value="{text(BALL).replace(',', '')}"/>
    <default name="camera" value="{text(CAMERA).replace(',', '')}"/>
    <integrator type="volpathmis"><integer name="max_depth" value="6"/></integrator>
    <medium type="homogeneous" id="fog">
        <rgb name="sigma_t" value="$sigma_t"/>
        <rgb name="albedo" value="$albedo"/>
        <float name="scale" value="$scale"/>
        <rgb name="volcl_radiance" value="$med_radiance"/>
        <phase type="hg"><float name="g" value="$g"/></phase>
    </medium>
    <sensor type="perspective" id="cam">
        <float name="fov" value="45"/>
        <transform name="to_world"><matrix value="$camera"/></transform>
        <sampler type="independent"><integer name="sample_count" value="8"/></sampler>
        <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="16"/>
            <rfilter type="box"/></film>
    </sensor>
    <emitter type="point" id="lamp">
        <point name="position" value="$position"/>
        <rgb name="intensity" value="$intensity"/>
    </emitter>
    <emitter type="directional" id="sun">
        <vector name="direction" value="$direction"/>
        <rgb name="irradiance" value="$irradiance"/>
    </emitter>
    <emitter type="constant" id="sky"><rgb name="radiance" value="$env"/></emitter>
    <bsdf type="diffuse" id="white"><rgb name="reflectance" value="$reflectance"/></bsdf>
    <bsdf type="twosided" id="two"><ref id="white"/></bsdf>
    <shape type="rectangle" id="floor">
        <transform name="to_world"><matrix value="$floor"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle" id="wall">
        <transform name="to_world"><translate value="0, 1, -1.5"/></transform>
        <ref id="two"/>
    </shape>
    <shape type="sphere" id="cloud">
        <point name="center" value="-0.3, 0.9, 0.2"/>
        <float name="radius" value="1.1"/>
        <bsdf type="null"/>
        <ref name="interior" id="fog"/>
    </shape>
    <shape type="sphere" id="ball">
        <transform name="to_world"><matrix value="$ball"/></transform>
        <bsdf type="dielectric" id="glass"><float name="int_ior" value="$int_ior"/></bsdf>
        <ref name="interior" id="fog"/>
        <ref name="exterior" id="fog"/>
    </shape>
    <shape type="sphere" id="mirror">
        <point name="center" value="0.7, 0.4, 0"/>
        <float name="radius" value="0.4"/>
        <bsdf type="conductor" id="metal">
            <rgb name="specular_reflectance" value="$spec"/>
            <rgb name="eta" value="$eta"/>
            <rgb name="k" value="$k"/>
        </bsdf>
    </shape>
    <shape type="rectangle" id="panel">
        <transform name="to_world"><scale value="0.4"/><rotate x="1" angle="90"/><translate value="0.8, 2.2, 0"/></transform>
        <emitter type="area" id="panel_light"><rgb name="radiance" value="$area"/></emitter>
    </shape>
</scene>
"""

# (key, the <default> that sets the same value in the file, the new value)
EDITS = [
    ("fog.sigma_t.value", "sigma_t", 0.9),
    ("fog.albedo.value", "albedo", (0.5, 0.6, 0.95)),
    ("fog.scale", "scale", 0.75),
    ("fog.phase_function.g", "g", -0.4),
    ("fog.volcl_radiance.value", "med_radiance", 0.6),
    ("white.reflectance.value", "reflectance", (0.2, 0.7, 0.3)),     # the two-sided copy follows
    ("two.reflectance.value", "reflectance", (0.3, 0.2, 0.6)),       # and the one it wraps
    ("glass.int_ior", "int_ior", 1.7),
    ("metal.specular_reflectance.value", "spec", (0.8, 0.7, 0.2)),
    ("metal.eta.value", "eta", (0.3, 0.6, 1.4)),
    ("metal.k.value", "k", (2.0, 3.0, 4.0)),
    ("panel_light.radiance.value", "area", (9.0, 8.0, 7.0)),
    ("lamp.intensity.value", "intensity", (5.0, 4.0, 3.0)),
    ("lamp.position", "position", (-0.1, 1.0, 0.2)),
    ("sun.irradiance.value", "irradiance", 0.8),
    ("sun.direction", "direction", (-0.3, -1.0, 0.1)),
    ("sky.radiance.value", "env", 0.25),
    ("floor.to_world", "floor", tf.rotate([1, 0, 0], -90) @ tf.translate([0.1, 0.0, -0.05]) @ np.diag([2.5, 3.0, 1.0, 1.0])),
    ("ball.to_world", "ball", tf.translate([-0.5, 0.6, 0.3]) @ tf.rotate([0, 1, 1], 30) @ np.diag([0.6, 0.6, 0.6, 1.0])),
    ("cam.to_world", "camera", tf.lookat([0.3, 1.1, 4.4], [0.0, 0.7, 0.0], [0.0, 1.0, 0.0])),
]


def load(**values):
    return volcl.load_string(TEMPLATE, base_dir=SCENES, **{k: text(v).replace(",", "") if np.ndim(v) == 2
                                                            else text(v) for k, v in values.items()})


@pytest.fixture(scope="module")
def original(device):
    return volcl.render(load(), seed=3, device=device)


@pytest.mark.parametrize("key, define, value", EDITS, ids=[e[0] for e in EDITS])
def test_an_edit_renders_what_loading_the_value_renders_bit_for_bit(device, original, key, define, value):
    scene = load()
    params = volcl.traverse(scene)
    params[key] = value
    params.update()
    edited = volcl.render(scene, seed=3, device=device)
    loaded = volcl.render(load(**{define: value}), seed=3, device=device)
    assert same(edited, loaded), key
    assert not np.array_equal(edited.image, original.image), f"{key}: the edit changed nothing"


def test_every_parameter_of_the_template_is_covered():
    keys = set(volcl.traverse(load()))
    edited = {e[0] for e in EDITS}
    # the rest: shapes placed by other transform elements, the dielectric's exterior IOR, the
    # panel's default bsdf
    assert keys - edited == {"wall.to_world", "mirror.to_world", "panel.to_world", "cloud.to_world", "glass.ext_ior",
                             "panel.bsdf.reflectance.value"}


def test_grid_density_scale_and_values(device, tmp_path):
    """A heterogeneous medium: its scale against -D density, its grid values against a volume file
    holding them."""
    xml = (SCENES / "smoke_grid.xml").read_text()
    small = dict(width=20, height=20, spp=4)
    scene = volcl.load_string(xml, base_dir=SCENES, **small)
    params = volcl.traverse(scene)
    params["smoke.scale"] = 40.0
    assert same(volcl.render(scene, seed=2, device=device),
                volcl.render(volcl.load_string(xml, base_dir=SCENES, density=40.0, **small), seed=2, device=device))
    data, _ = read_vol(str(SCENES / "volumes" / "smoke.vol"))
    thinner = data * np.float32(0.5) + np.float32(0.01)
    params["smoke.sigma_t.data"] = thinner
    write_vol(str(tmp_path / "thin.vol"), thinner)
    other = xml.replace("volumes/smoke.vol", str(tmp_path / "thin.vol"))
    assert same(volcl.render(scene, seed=2, device=device),
                volcl.render(volcl.load_string(other, base_dir=SCENES, density=40.0, **small), seed=2, device=device))
    with pytest.raises(volcl.VolclError, match=r"must keep the grid's shape"):
        params["smoke.sigma_t.data"] = thinner[:-1]


def test_update_uploads_only_the_arrays_that_changed(device):
    dev = private_device(device)
    scene = load()
    volcl.render(scene, spp=1, device=dev)
    uploaded = scene.upload(dev)
    before = uploaded.uploads
    params = volcl.traverse(scene)
    params["white.reflectance.value"] = 0.3
    update = params.update()
    assert update.arrays == ["bsdfs"] and uploaded.uploads == before + 1
    params["fog.sigma_t.value"] = 0.5
    assert params.update().arrays == ["media"]
    params["lamp.position"] = (0.0, 1.5, 0.0)
    assert params.update().arrays == ["lights"]
    params["floor.to_world"] = FLOOR @ tf.translate([0.0, 0.0, 0.01])
    moved = params.update()
    # the BVH and the triangles move; the scene's bounds (in RenderParams) may, too
    assert {"nodes", "triangles"} <= set(moved.arrays) <= {"nodes", "leaves", "triangles", "params"}
    params["cam.to_world"] = CAMERA
    assert params.update().arrays in ([], ["params"])      # RenderParams: each render uploads its own
    params["glass.int_ior"] = 1.33                         # the value it already has
    assert params.update().arrays == []
    assert uploaded.uploads == before + 1 + 1 + 1 + len(set(moved.arrays) - {"params"})


def test_a_feature_change_builds_once_and_says_so(device):
    """g = 0.5 on an isotropic medium: the kernel needs Henyey-Greenstein code, so the next render
    builds a program, once; edits that change no feature build nothing."""
    dev = private_device(device)
    xml = TEMPLATE.replace('<phase type="hg"><float name="g" value="$g"/></phase>', "").replace(
        '<default name="g" value="0.3"/>', "")
    scene = volcl.load_string(xml, base_dir=SCENES)
    assert not scene.features["HG"]
    volcl.render(scene, spp=1, device=dev)
    assert dev.builds == 1
    params = volcl.traverse(scene)
    assert params["fog.phase_function.g"] == 0.0
    params["fog.sigma_t.value"] = 0.7
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        params.update()                                    # no feature changes: no warning
    volcl.render(scene, spp=1, device=dev)
    assert dev.builds == 1
    params["fog.phase_function.g"] = 0.5
    with pytest.warns(volcl.FeatureChange, match=r"\+hg.*next render on .* builds a program"):
        update = params.update()
    assert update.features_changed and update.feature_change() == "+hg"
    first = volcl.render(scene, spp=1, device=dev)
    assert dev.builds == 2 and first.build_seconds > 0
    again = volcl.render(scene, spp=1, device=dev)
    assert dev.builds == 2 and again.build_seconds == 0
    # one-colour to three-colour extinction and back: the second change finds its program built
    params["fog.sigma_t.value"] = (0.3, 0.5, 0.7)
    with pytest.warns(volcl.FeatureChange, match=r"\+chromatic_media"):
        params.update()
    volcl.render(scene, spp=1, device=dev)
    assert dev.builds == 3
    params["fog.sigma_t.value"] = 0.7
    with pytest.warns(volcl.FeatureChange, match=r"-chromatic_media.*built already"):
        params.update()
    volcl.render(scene, spp=1, device=dev)
    assert dev.builds == 3


def test_render_applies_pending_edits_and_an_old_renderer_refuses_to_mix(device):
    scene = load()
    r = volcl.Renderer(scene, device=device, seed=3)
    r.render(2)
    params = volcl.traverse(scene)
    params["fog.albedo.value"] = 0.5
    assert params.pending == ["fog.albedo.value"]
    edited = volcl.render(scene, seed=3, device=device)      # applies the pending edit
    assert params.pending == []
    assert same(edited, volcl.render(load(albedo=0.5), seed=3, device=device))
    with pytest.raises(volcl.VolclError, match="updated after this render began"):
        r.render(2)


def test_1000_renders_keep_memory_flat_and_build_once(device):
    """The loop a notebook runs: one scene, one device, a thousand renders (every tenth after an
    edit). Memory is measured (resident set size) after the first 200 renders, when every cache is
    warm, and at the end; the program is built once and the device keeps one context."""
    dev = private_device(device)
    scene = volcl.load_file(SCENES / "cbox.xml", width=16, height=12)
    params = volcl.traverse(scene)
    page = __import__("os").sysconf("SC_PAGE_SIZE")

    def rss():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * page

    ctx = dev.ctx
    samples = {}
    for i in range(1000):
        if i % 10 == 0:
            params["white.reflectance.value"] = 0.5 + 0.2 * (i % 20 == 0)
        volcl.render(scene, spp=1, seed=i, device=dev)
        if i + 1 in (200, 600, 1000):
            samples[i + 1] = rss()
    growth = samples[1000] - samples[200]
    print(f"resident set: {samples[200] / 2**20:.1f} MiB after 200 renders, {samples[600] / 2**20:.1f} MiB "
          f"after 600, {samples[1000] / 2**20:.1f} MiB after 1000")
    # a context or a program per render costs megabytes each; a leaked accumulator 20 kB each
    assert growth < 8 * 2**20, f"memory grew by {growth / 2**20:.1f} MiB over 800 renders"
    assert dev.builds == 1 and dev.ctx is ctx


def test_tiles_on_two_devices_merge_into_the_image_bit_for_bit(device):
    """Tiles of a media scene, half of them on a device object of their own (own context, program
    and upload), merged: the image one render of the whole gives."""
    scene = volcl.load_file(SCENES / "fog.xml", width=37, height=23, spp=6)
    other = private_device(device)
    whole = volcl.render(scene, seed=4, device=device)
    parts = [volcl.render(scene, seed=4, device=(device, other)[i % 2], tile=t)
             for i, t in enumerate(volcl.tiles(37, 23, (16, 9)))]
    assert parts[0].image.shape == (9, 16, 3) and parts[0].tile == volcl.Tile(0, 0, 16, 9)
    assert same(volcl.merge(parts), whole)
    assert len(scene.devices) == 2
    with pytest.raises(volcl.VolclError, match="do not cover"):
        volcl.merge(parts[1:])


def test_tile_states_merge_and_resume_bit_for_bit(device):
    from volcl.tiles import merge_states
    scene = volcl.load_file(SCENES / "cbox.xml", width=24, height=10)
    whole = volcl.Renderer(scene, device=device, seed=1).render(20)
    states = []
    for t in volcl.tiles(24, 10, 8):
        r = volcl.Renderer(scene, device=device, seed=1, tile=t)
        r.render(7)
        states.append(r.state())
    merged = volcl.Renderer(scene, device=device, seed=1)
    merged.restore(merge_states(states, 24, 10))
    assert same(merged.render(13), whole)
    # a tile continues from a whole-image state
    part = volcl.Renderer(scene, device=device, seed=1, tile=(3, 2, 9, 5))
    part.restore(merge_states(states, 24, 10))
    assert part.render(13).image.tobytes() == np.ascontiguousarray(whole.image[2:7, 3:12]).tobytes()


def test_unknown_keys_list_the_keys_that_exist():
    params = volcl.traverse(load())
    with pytest.raises(volcl.UnknownParameter) as info:
        params["fog.sigma_s.value"] = 1.0
    message = str(info.value)
    assert "no parameter 'fog.sigma_s.value'" in message and "did you mean 'fog.sigma_t.value'" in message
    assert all(k in message for k in params)
    with pytest.raises(KeyError):
        params["nothing"]


def parser_message(xml_error_case):
    """The message the parser gives for a file with the bad value, less its file:line: <element>."""
    with pytest.raises(volcl.VolclError) as info:
        volcl.load_string(TEMPLATE.replace(*xml_error_case), base_dir=SCENES)
    return re.sub(r"^<string>:\d+: <[^>]*>: ", "", str(info.value))


@pytest.mark.parametrize("key, value, file_change", [
    ("fog.albedo.value", 1.5, ('name="albedo" value="$albedo"', 'name="albedo" value="1.5"')),
    ("fog.sigma_t.value", -1, ('name="sigma_t" value="$sigma_t"', 'name="sigma_t" value="-1"')),
    ("fog.scale", 0.0, ('name="scale" value="$scale"', 'name="scale" value="0.0"')),
    ("fog.phase_function.g", 1.2, ('name="g" value="$g"', 'name="g" value="1.2"')),
    ("glass.int_ior", -1.0, ('name="int_ior" value="$int_ior"', 'name="int_ior" value="-1.0"')),
    ("glass.int_ior", "unobtainium", ('<float name="int_ior" value="$int_ior"/>', '<string name="int_ior" value="unobtainium"/>')),
    ("fog.scale", float("nan"), ('name="scale" value="$scale"', 'name="scale" value="nan"')),
    ("fog.sigma_t.value", 1e39, ('name="sigma_t" value="$sigma_t"', 'name="sigma_t" value="1e+39"')),
    ("fog.sigma_t.value", 3e38, ('name="sigma_t" value="$sigma_t"', 'name="sigma_t" value="3e+38"')),
    ("sun.direction", (0, 0, 0), ('name="direction" value="$direction"', 'name="direction" value="0, 0, 0"')),
    ("cam.to_world", np.diag([2.0, 2.0, 2.0, 1.0]), ('<matrix value="$camera"/>', '<scale value="2"/>')),
    ("ball.to_world", np.diag([1.0, 2.0, 1.0, 1.0]), ('<matrix value="$ball"/>', '<scale value="1, 2, 1"/>')),
    ("floor.to_world", np.diag([0.0, 1.0, 1.0, 1.0]), ('<matrix value="$floor"/>', '<scale value="0, 1, 1"/>')),
], ids=lambda v: v if isinstance(v, str) else None)
def test_bad_values_get_the_parsers_messages(key, value, file_change):
    """The same value in a file and through traverse(): the same message (after the file's place
    and the parameter's key), and the scene unchanged."""
    expected = parser_message(file_change)
    params = volcl.traverse(load())
    before = params[key]
    with pytest.raises(volcl.VolclError) as info:
        params[key] = value
    message = str(info.value)
    assert message.startswith(f"{key}: {expected}") or expected in message, (message, expected)
    assert np.array_equal(params[key], before) and params.pending == []


def test_values_of_the_wrong_type():
    params = volcl.traverse(load())
    for key, value, kind in [("fog.scale", "thick", "a <float>"), ("fog.albedo.value", (0.1, 0.2), "a colour"),
                             ("fog.albedo.value", "grey", "a colour"), ("lamp.position", 1.0, "a <point>"),
                             ("floor.to_world", np.eye(3), "a <transform>"), ("fog.scale", True, "a <float>")]:
        with pytest.raises(volcl.VolclError, match=rf"^{re.escape(key)}: parameter '\w+' of <[^>]+> must be "
                                                   rf"{re.escape(kind)}"):
            params[key] = value


def test_loading_errors_name_the_text_and_files_resolve_from_base_dir(tmp_path):
    xml = (SCENES / "cbox.xml").read_text()
    scene = volcl.load_string(xml, base_dir=SCENES, width=8, height=6)
    assert scene.width == 8 and len(scene.model.shapes) > 5
    with pytest.raises(volcl.VolclError, match=r"cannot load mesh 'meshes/"):
        volcl.load_string(xml, base_dir=tmp_path)
    with pytest.raises(volcl.VolclError, match=r"^<string>:1: malformed XML"):
        volcl.load_string("<scene version='3.0.0'>")
    with pytest.raises(volcl.VolclError, match=r"-D nope=\.\.\.: the scene has no"):
        volcl.load_file(SCENES / "cbox.xml", nope=1)
    with pytest.raises(volcl.VolclError, match="Nori test file"):
        volcl.load_file(ROOT.parent / "shared" / "nori" / "furnace" / "test-furnace.xml")


def test_results_show_in_notebooks_and_write_to_disk(device, tmp_path):
    from PIL import Image
    from volcl.image import read_image
    scene = volcl.load_file(SCENES / "cbox.xml", width=24, height=18, spp=4)
    result = volcl.render(scene, device=device, seed=9)
    srgb = result.to_srgb()
    assert srgb.shape == (18, 24, 3) and srgb.dtype == np.float32 and 0 <= srgb.min() and srgb.max() <= 1
    assert result.to_srgb(exposure=1).mean() > srgb.mean()
    png = Image.open(io.BytesIO(result._repr_png_()))
    assert png.size == (24, 18) and png.mode == "RGB"
    assert "24x18, 4 spp" in repr(result)
    out = volcl.write(result, tmp_path / "cbox.exr")
    pixels, attrs = read_image(out)
    assert np.array_equal(pixels[..., :3], result.image) and np.array_equal(pixels[..., 3:], result.variance)
    assert attrs["volcl:spp"] == 4 and attrs["volcl:seed"] == 9 and attrs["volcl:complete"] == 1
    assert attrs["volcl:scene"] == str(SCENES / "cbox.xml") and attrs["volcl:defines"] == '{"height": "18", "width": "24"}'
    volcl.write(result, tmp_path / "cbox.png")
    assert read_image(tmp_path / "cbox.png")[0].shape == (18, 24, 3)


def test_devices_are_the_same_objects_every_time(device):
    first, second = volcl.devices(), volcl.devices()
    assert first and all(a is b for a, b in zip(first, second))
    assert device in first
    assert volcl.render(load(), spp=1, device=device.key).device == device.label


def readme_python_example() -> str:
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("\n## Python"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_readme_python_example_runs(tmp_path):
    """The README's example, as a user runs it: in a folder of their own beside the scenes."""
    (tmp_path / "scenes").symlink_to(SCENES)
    script = tmp_path / "example.py"
    script.write_text(readme_python_example())
    env = dict(__import__("os").environ, PYTHONPATH=str(ROOT))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "fog.exr").is_file()


def test_a_scene_pickles_without_its_uploads_and_renders_the_same(device):
    """What a worker process receives: the model and its packed arrays, not the device buffers."""
    import pickle
    scene = load()
    first = volcl.render(scene, seed=5, device=device)
    copy = pickle.loads(pickle.dumps(scene))
    assert copy.devices == [] and scene.devices == [device]
    assert same(volcl.render(copy, seed=5, device=device), first)


def test_the_package_imports_what_it_names_when_first_used():
    """`import volcl` and the command's module load neither numpy nor pyopencl (start-up of
    commands that need neither, and OpenBLAS's thread count set before numpy loads); every name in
    volcl.__all__ still resolves, and volcl.tiles stays the function after its module loads."""
    code = ("import os, sys; import volcl.cli, volcl; "
            "assert 'numpy' not in sys.modules and 'pyopencl' not in sys.modules, sorted(sys.modules); "
            "assert os.environ['OPENBLAS_NUM_THREADS'] == '1'; "
            "missing = [n for n in volcl.__all__ if not hasattr(volcl, n)]; assert not missing, missing; "
            "import volcl.tiles; from volcl.tiles import tiles; assert volcl.tiles is tiles; "
            "assert callable(volcl.render) and volcl.Renderer.__module__ == 'volcl.renderer'")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
