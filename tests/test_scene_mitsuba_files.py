"""What real Mitsuba files do before any plugin is built, as Mitsuba 3.9 does it: versions, <include>,
<path>, forward <ref>, <alias>, defaults shared with included files; and the new plugins' parameters
(sensors, integrators, shapes, spectra, media), read into the scene model."""
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from volcl.errors import VolclError
from volcl.scene import load, mitsuba_files
from volcl.scene import transform as tf
from volcl.scene.model import select_sensor

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
QUAD = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"
SENSOR = '<sensor type="perspective"><float name="fov" value="40"/></sensor>'


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def scene_file(tmp_path, body, version="3.0.0", name="scene.xml"):
    return write(tmp_path / name, f'<scene version="{version}">\n{body}\n</scene>\n')


def scene(tmp_path, body, version="3.0.0", **defines):
    return load(scene_file(tmp_path, body, version), defines or None)


# -- versions ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("version", ["2.0.0", "2.1.0", "3.0.0", "3.5"])
def test_versions_2_and_3_read_unchanged(tmp_path, version):
    s = scene(tmp_path, SENSOR + '<shape type="sphere"><float name="radius" value="2"/></shape>', version)
    assert s.dialect == "mitsuba" and s.shapes[0].radius == 2.0
    assert not [w for w in s.warnings if "upgraded" in w]


def test_version_0_files_are_upgraded_like_mitsuba(tmp_path):
    body = ('<sensor type="perspective"><float name="fov" value="30"/><float name="nearClip" value="0.5"/>'
            '<transform name="toWorld"><translate x="1"/></transform></sensor>'
            '<shape type="cube"><bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.25"/></bsdf></shape>')
    s = scene(tmp_path, body, "0.6.0")
    assert s.camera.near_clip == 0.5 and np.allclose(s.camera.to_world, tf.translate([1, 0, 0]))
    assert np.allclose(s.shapes[0].bsdf.reflectance, 0.25)
    assert any("upgraded" in w and "camelCase" in w for w in s.warnings)


def test_camel_case_rule_is_mitsubas():
    assert mitsuba_files._camel_to_snake("toWorld") == "to_world"
    assert mitsuba_files._camel_to_snake("intIOR") == "int_ior"
    assert mitsuba_files._camel_to_snake("sampleCount") == "sample_count"
    assert mitsuba_files._camel_to_snake("max_depth") == "max_depth"


# -- includes, paths, defaults ------------------------------------------------------------------------

def test_include_splices_a_scene_and_shares_parameters(tmp_path):
    write(tmp_path / "parts" / "lights.xml", '<scene version="2.1.0">\n<default name="power" value="7"/>\n'
          '<emitter type="point"><rgb name="intensity" value="$power"/></emitter>\n</scene>\n')
    write(tmp_path / "parts" / "material.xml",
          '<bsdf version="3.0.0" type="diffuse" id="mat"><rgb name="reflectance" value="$tone"/></bsdf>\n')
    body = ('<default name="tone" value="0.3"/><include filename="parts/lights.xml"/>'
            '<include filename="parts/material.xml"/>' + SENSOR +
            '<shape type="sphere"><ref id="mat"/></shape>'
            '<shape type="cube"><float name="flip_normals" value="$power"/></shape>')
    with pytest.raises(VolclError, match="must be a <boolean>"):      # $power reaches the main file
        scene(tmp_path, body)
    s = scene(tmp_path, body.replace('<shape type="cube"><float name="flip_normals" value="$power"/></shape>', ''),
              power="2")
    assert np.allclose(s.emitters[0].value, 2)                  # -D beats the included default
    assert np.allclose(s.shapes[0].bsdf.reflectance, 0.3)


def test_first_default_wins_as_in_mitsuba(tmp_path):
    s = scene(tmp_path, '<default name="r" value="1"/><default name="r" value="2"/>' + SENSOR +
              '<shape type="sphere"><float name="radius" value="$r"/></shape>')
    assert s.shapes[0].radius == 1.0


def test_path_folders_come_before_the_scene_folder_even_when_declared_later(tmp_path):
    """Mitsuba resolves mesh files after reading the whole file, with the <path> folders first
    (the latest first), then the scene's folder."""
    write(tmp_path / "m.obj", TRIANGLE)
    write(tmp_path / "first" / "m.obj", QUAD)
    write(tmp_path / "second" / "only_here.obj", TRIANGLE)
    s = scene(tmp_path, SENSOR + '<shape type="obj"><string name="filename" value="m.obj"/></shape>'
              '<path value="first"/><path value="second"/>'
              '<shape type="obj"><string name="filename" value="only_here.obj"/></shape>')
    assert [len(sh.faces) for sh in s.shapes] == [2, 1]


def test_included_meshes_resolve_against_the_main_scene(tmp_path):
    """As in Mitsuba: an included file's relative filenames are looked up from the main scene's
    folder (and its <path>s), not the included file's own folder."""
    write(tmp_path / "m.obj", TRIANGLE)
    write(tmp_path / "inc" / "m.obj", QUAD)
    write(tmp_path / "inc" / "part.xml",
          '<scene version="3.0.0"><shape type="obj"><string name="filename" value="m.obj"/></shape></scene>')
    s = scene(tmp_path, SENSOR + '<include filename="inc/part.xml"/>')
    assert len(s.shapes[0].faces) == 1


def test_missing_file_names_every_folder_searched(tmp_path):
    (tmp_path / "assets").mkdir()
    with pytest.raises(VolclError) as info:
        scene(tmp_path, '<path value="assets"/>' + SENSOR +
              '<shape type="obj">\n<string name="filename" value="gone.obj"/></shape>')
    message = str(info.value)
    assert "scene.xml:3" in message and "'gone.obj'" in message
    assert str(tmp_path / "assets") in message and str(tmp_path) in message


def test_include_of_a_file_found_by_path(tmp_path):
    write(tmp_path / "lib" / "sensor.xml", f'<scene version="3.0.0">{SENSOR}</scene>')
    s = scene(tmp_path, '<path value="lib"/><include filename="sensor.xml"/>')
    assert s.camera.fov == 40


# -- references --------------------------------------------------------------------------------------

def test_forward_references_build_once_and_share(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="cube"><ref id="later"/></shape>'
              '<shape type="sphere"><ref id="later"/></shape>'
              '<bsdf type="diffuse" id="later"><rgb name="reflectance" value="0.1, 0.2, 0.3"/></bsdf>')
    a, b = s.shapes
    assert a.bsdf is b.bsdf and np.allclose(a.bsdf.reflectance, [0.1, 0.2, 0.3])


def test_reference_to_an_object_nested_in_another(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="cube"><bsdf type="conductor" id="inner"/></shape>'
              '<shape type="sphere"><ref id="inner"/></shape>')
    assert s.shapes[0].bsdf is s.shapes[1].bsdf


def test_alias(tmp_path):
    s = scene(tmp_path, SENSOR + '<bsdf type="dielectric" id="glass"/><alias id="glass" as="window"/>'
              '<shape type="sphere"><ref id="window"/></shape>')
    assert s.shapes[0].bsdf.kind == "dielectric"


def test_top_level_area_emitter_referred_to_by_shapes(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="rectangle"><ref id="glow"/></shape>'
              '<emitter type="area" id="glow"><rgb name="radiance" value="3"/></emitter>'
              '<emitter type="area" id="unused"/>')
    assert np.allclose(s.shapes[0].emitter_radiance, 3) and s.emitters == []
    assert np.allclose(s.shapes[0].bsdf.reflectance, 0)        # an emitter's default bsdf is black
    assert any("emits nothing" in w and "scene.xml:2" in w for w in s.warnings)


# -- transforms ----------------------------------------------------------------------------------------

def test_rotate_uses_its_axis_as_given(tmp_path):
    s = scene(tmp_path, SENSOR + '<emitter type="point"><transform name="to_world"><translate x="1"/>'
              '<rotate x="0" y="0" z="2" angle="90"/></transform></emitter>')
    # (1, 0, 0) about (0, 0, 2) by 90 degrees: c I + s [a]x + (1 - c) a a^T = [a]x here
    assert np.allclose(s.emitters[0].position, [0, 2, 0])


def test_nori_rotate_still_normalizes(tmp_path):
    text = ('<scene><integrator type="path_mis"/><camera type="perspective"><transform name="toWorld">'
            '<rotate axis="0,0,2" angle="90"/></transform></camera></scene>')
    write(tmp_path / "nori.xml", text)
    with pytest.raises(VolclError):           # Nori's rotate takes axis=, not x/y/z: an error either way
        load(tmp_path / "nori.xml")
    m = tf.rotate([0, 0, 2], 90)
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3))


# -- sensors ----------------------------------------------------------------------------------------

def test_several_sensors_render_the_first_and_warn(tmp_path):
    body = ('<sensor type="perspective"><float name="fov" value="20"/><sampler type="independent">'
            '<integer name="sample_count" value="3"/></sampler></sensor>\n'
            '<sensor type="orthographic"><sampler type="independent"><integer name="sample_count" value="5"/>'
            '<integer name="seed" value="9"/></sampler></sensor>')
    s = scene(tmp_path, body)
    assert (s.camera.kind, s.camera.fov, s.spp) == ("perspective", 20, 3)
    assert any("2 sensors" in w and "--sensor" in w and "scene.xml:3" in w for w in s.warnings)
    select_sensor(s, 1)
    assert (s.camera.kind, s.spp, s.seed) == ("orthographic", 5, 9)
    with pytest.raises(VolclError, match="0 to 1"):
        select_sensor(s, 2)


def test_perspective_extras(tmp_path):
    body = ('<sensor type="perspective"><string name="focal_length" value="35mm"/>'
            '<float name="principal_point_offset_x" value="0.1"/>'
            '<float name="focus_distance" value="3"/></sensor>')
    s = scene(tmp_path, body)
    assert s.camera.fov == pytest.approx(2 * math.degrees(math.atan(math.hypot(36, 24) / 70)))
    assert s.camera.fov_axis == "diagonal" and s.camera.principal_point == (0.1, 0.0)
    assert any("'focus_distance' has no effect" in w for w in s.warnings)


def test_thinlens_and_orthographic(tmp_path):
    s = scene(tmp_path, '<sensor type="thinlens"><float name="aperture_radius" value="0.2"/>'
              '<float name="far_clip" value="50"/></sensor>')
    assert (s.camera.kind, s.camera.aperture_radius, s.camera.focus_distance) == ("thinlens", 0.2, 50.0)
    s = scene(tmp_path, '<sensor type="thinlens"><float name="aperture_radius" value="0"/></sensor>')
    assert s.camera.kind == "perspective" and any("pinhole" in w for w in s.warnings)
    s = scene(tmp_path, '<sensor type="orthographic"><transform name="to_world"><scale value="2"/>'
              '</transform></sensor>')
    assert s.camera.kind == "orthographic" and np.allclose(s.camera.to_world, tf.scale(2))


def test_machinery_parameters_warn_with_what_volcl_does(tmp_path):
    body = ('<integrator type="volpath"><float name="timeout" value="10"/><integer name="samples_per_pass" value="4"/>'
            '</integrator><sensor type="perspective"><float name="shutter_close" value="1"/>'
            '<film type="hdrfilm">'
            '<string name="component_format" value="float16"/><integer name="crop_width" value="4"/></film></sensor>'
            '<shape type="cube"><medium type="homogeneous" name="interior"><boolean name="sample_emitters" '
            'value="false"/><boolean name="has_spectral_extinction" value="false"/></medium></shape>')
    warnings = "\n".join(scene(tmp_path, body).warnings)
    for name, fragment in [("timeout", "--time-limit"), ("samples_per_pass", "passes"), ("shutter_close", "still"),
                           ("component_format", "float32"), ("crop_width", "whole film"),
                           ("sample_emitters", "same"), ("has_spectral_extinction", "same image")]:
        assert f"'{name}'" in warnings and fragment in warnings, (name, warnings)


def test_chromatic_extinction_without_spectral_flag_warns_of_the_difference(tmp_path):
    body = ('<shape type="cube"><medium type="homogeneous" name="interior"><rgb name="sigma_t" value="0.2, 0.5, 1"/>'
            '<boolean name="has_spectral_extinction" value="false"/></medium></shape>')
    assert any("a different image" in w for w in scene(tmp_path, SENSOR + body).warnings)


# -- integrators ----------------------------------------------------------------------------------------

def test_direct_and_moment(tmp_path):
    s = scene(tmp_path, SENSOR + '<integrator type="direct"><integer name="emitter_samples" value="3"/>'
              '<integer name="bsdf_samples" value="0"/></integrator><emitter type="point"/>')
    i = s.integrator
    assert (i.kind, i.max_depth, i.emitter_samples, i.bsdf_samples, i.moment) == ("direct", 2, 3, 0, False)
    assert any("3x as bright" in w for w in s.warnings)
    s = scene(tmp_path, SENSOR + '<integrator type="direct"><integer name="shading_samples" value="2"/></integrator>')
    assert (s.integrator.emitter_samples, s.integrator.bsdf_samples) == (2, 2)
    s = scene(tmp_path, SENSOR + '<integrator type="moment"><integrator type="path">'
              '<integer name="max_depth" value="4"/></integrator></integrator>')
    assert (s.integrator.kind, s.integrator.max_depth, s.integrator.moment) == ("path", 4, True)
    assert any("m2.R/G/B" in w for w in s.warnings)


# -- shapes ------------------------------------------------------------------------------------------------

def write_serialized(path, meshes, version=4):
    blobs = []
    for vertices, faces, normals in meshes:
        body = struct.pack("<I", 0x1000 | (1 if normals is not None else 0)) + (b"m\0" if version == 4 else b"")
        body += struct.pack("<QQ", len(vertices), len(faces)) + np.asarray(vertices, "<f4").tobytes()
        if normals is not None:
            body += np.asarray(normals, "<f4").tobytes()
        body += np.asarray(faces, "<u4").tobytes()
        blobs.append(struct.pack("<HH", 0x041C, version) + zlib.compress(body))
    offsets = np.cumsum([0] + [len(b) for b in blobs[:-1]])
    data = b"".join(blobs) + b"".join(struct.pack("<Q" if version == 4 else "<I", int(o)) for o in offsets)
    Path(path).write_bytes(data + struct.pack("<I", len(blobs)))


@pytest.mark.parametrize("version", [3, 4])
def test_serialized_meshes_by_index(tmp_path, version):
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    quad = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 0]], float)
    write_serialized(tmp_path / "m.serialized", [(tri, [[0, 1, 2]], None),
                                                 (quad, [[0, 1, 2], [1, 3, 2]], np.tile([0, 0, 1.0], (4, 1)))], version)
    s = scene(tmp_path, SENSOR + '<shape type="serialized"><string name="filename" value="m.serialized"/></shape>'
              '<shape type="serialized"><string name="filename" value="m.serialized"/>'
              '<integer name="shape_index" value="1"/><transform name="to_world"><translate z="1"/></transform></shape>')
    a, b = s.shapes
    assert len(a.faces) == 1 and a.normals is None       # planar: recomputed normals are flat, dropped
    assert len(b.faces) == 2 and np.allclose(b.vertices[:, 2], 1) and np.allclose(b.normals, [0, 0, 1])
    with pytest.raises(VolclError, match="out of range"):
        scene(tmp_path, SENSOR + '<shape type="serialized"><string name="filename" value="m.serialized"/>'
              '<integer name="shape_index" value="2"/></shape>')


def test_corrupt_serialized_file(tmp_path):
    write_serialized(tmp_path / "m.serialized", [(np.eye(3), [[0, 1, 2]], None)])
    data = (tmp_path / "m.serialized").read_bytes()
    (tmp_path / "m.serialized").write_bytes(data[:20])
    with pytest.raises(VolclError, match="m.serialized"):
        scene(tmp_path, SENSOR + '<shape type="serialized"><string name="filename" value="m.serialized"/></shape>')


def test_mesh_without_normals_gets_mitsubas_smooth_normals(tmp_path):
    """A tetrahedron: each corner's normal is the angle-weighted mean of its three faces."""
    write(tmp_path / "t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    s = scene(tmp_path, SENSOR + '<shape type="obj"><string name="filename" value="t.obj"/></shape>'
              '<shape type="obj"><string name="filename" value="t.obj"/><boolean name="face_normals" value="true"/></shape>')
    smooth, flat = s.shapes
    assert flat.normals is None
    assert np.allclose(smooth.normals[0], -np.ones(3) / math.sqrt(3))    # symmetric corner at the origin
    assert np.allclose(np.linalg.norm(smooth.normals, axis=1), 1)


def test_cylinder(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="cylinder"><point name="p0" value="1, 0, 0"/>'
              '<point name="p1" value="1, 0, 3"/><float name="radius" value="0.5"/></shape>')
    c = s.shapes[0]
    assert c.kind == "cylinder"
    assert np.allclose(tf.apply_point(c.cylinder, [1, 0, 0]), [1.5, 0, 0])
    assert np.allclose(tf.apply_point(c.cylinder, [0, 0, 1]), [1, 0, 3])
    s = scene(tmp_path, SENSOR + '<shape type="cylinder"><transform name="to_world"><scale x="2"/></transform>'
              '<medium type="homogeneous" name="interior"/></shape>')
    assert any("unevenly" in w for w in s.warnings)


# -- spectra ------------------------------------------------------------------------------------------

def test_spectra_on_emitters_and_surfaces(tmp_path):
    write(tmp_path / "flat.spd", "# flat\n300 1\n900 1\n")
    s = scene(tmp_path, SENSOR + '<emitter type="point"><spectrum name="intensity" value="2"/></emitter>'
              '<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" value="0.4"/></bsdf></shape>'
              '<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" filename="flat.spd"/></bsdf></shape>')
    # Mitsuba 3.9.1: a uniform emission spectrum of 1 is xyz_to_srgb(1, 1, 1); a unit reflectance under
    # D65 is white to 0.1% (its 1000-point sum)
    assert np.allclose(s.emitters[0].value, 2 * np.array([1.204794, 0.948292, 0.908916]), atol=1e-5)
    assert np.allclose(s.shapes[0].bsdf.reflectance, 0.4)
    assert np.allclose(s.shapes[1].bsdf.reflectance, 0.999, atol=1.5e-3)


def test_out_of_gamut_spectrum_is_clamped_with_a_warning(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="cube"><bsdf type="diffuse">'
              '<spectrum name="reflectance" value="400:0, 520:1, 540:1, 560:0"/></bsdf></shape>')
    assert np.all(s.shapes[0].bsdf.reflectance >= 0) and np.all(s.shapes[0].bsdf.reflectance <= 1)
    assert any("outside the gamut" in w for w in s.warnings)


def test_blackbody_emitter(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="sphere"><emitter type="area"><spectrum type="blackbody" '
              'name="radiance"><float name="temperature" value="6500"/></spectrum></emitter></shape>')
    rgb = s.shapes[0].emitter_radiance
    assert np.all(rgb > 0) and any("spectral variants" in w for w in s.warnings)


def test_path_integrator_ignores_media_as_mitsubas_does(tmp_path):
    body = ('<integrator type="path"><integer name="max_depth" value="3"/></integrator>' + SENSOR +
            '<shape type="sphere"><bsdf type="null"/><medium type="homogeneous" name="interior"/></shape>')
    s = scene(tmp_path, body)
    assert s.media == [] and s.shapes[0].interior is None
    assert any("ignores participating media" in w for w in s.warnings)
    assert any("null surface as a bounce" in w for w in s.warnings)
