"""Rough and layered bsdfs, textures and texture coordinates against Mitsuba 3 itself, on small
scenes written for the test (the harness of tests/test_mitsuba_agreement.py: one file for both
renderers, volcl's image within the standard error both renders' variances predict, over the image
and over 4 x 4 blocks). Optional: skipped without Mitsuba 3."""

import numpy as np
import pytest

from imagestats import assert_mean_matches
from test_mitsuba_agreement import LIGHT, PATH, SEEDS, VARIANT, mitsuba_references, reference_image, scene_xml, sensor
from volcl.renderer import Renderer
from volcl.scene import load

VOLPATH = '<integrator type="volpath"><integer name="max_depth" value="{depth}"/></integrator>'
ENV = '<emitter type="constant"><rgb name="radiance" value="0.3"/></emitter>'
CHECKER_FLOOR = ('<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>'
                 '<translate y="-1"/></transform><bsdf type="diffuse"><texture type="checkerboard" name="reflectance">'
                 '<transform name="to_uv"><scale value="6"/></transform></texture></bsdf></shape>')
VIEW = dict(origin="0, 0.5, 4")


def write_image(path, pixels, fmt="float"):
    import OpenImageIO as oiio
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()


def _files(folder):
    rng = np.random.default_rng(3)
    h, w = 8, 16
    grad = np.zeros((h, w, 3), np.float32)
    grad[..., 0] = np.linspace(0.05, 0.95, w)[None, :]
    grad[..., 1] = np.linspace(0.05, 0.95, h)[:, None]
    grad[..., 2] = 0.25
    write_image(folder / "grad.exr", grad)
    write_image(folder / "noise.png", (rng.random((5, 7, 3)) * 255).astype(np.uint8), "uint8")
    write_image(folder / "gray.png", (rng.random((6, 9, 1)) * 255).astype(np.uint8), "uint8")
    write_image(folder / "rough.png", (40 + rng.random((4, 4, 1)) * 160).astype(np.uint8), "uint8")
    y, x = np.mgrid[0:32, 0:32] / 32.0
    write_image(folder / "height.exr", (0.5 + 0.5 * np.sin(2 * np.pi * 3 * x) * np.cos(2 * np.pi * 2 * y))
                .astype(np.float32)[..., None])
    n = np.stack([0.3 * np.sin(2 * np.pi * 2 * x), 0.3 * np.cos(2 * np.pi * 3 * y), np.ones_like(x)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    write_image(folder / "normals.png", ((n * 0.5 + 0.5) * 255).round().astype(np.uint8), "uint8")
    (folder / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                                     "vt 0 0\nvt 0.7 0.1\nvt 0.9 0.8\nvt 0.1 0.6\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    (folder / "quad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                     "property float z\nproperty float u\nproperty float v\nelement face 2\n"
                                     "property list uchar int vertex_indices\nend_header\n"
                                     "-1 -1 0 0 0\n1 -1 0 0.7 0.1\n1 1 0 0.9 0.8\n-1 1 0 0.1 0.6\n3 0 1 2\n3 0 2 3\n")


def _sphere(bsdf, radius=0.8):
    return f'<shape type="sphere"><float name="radius" value="{radius}"/>{bsdf}</shape>'


def _cases():
    light = ENV + LIGHT.format(radiance=8).replace('<translate y="2"/>', '<translate y="2" x="0.5"/>')
    surf = PATH.format(depth=6) + sensor(**VIEW) + light + CHECKER_FLOOR
    vol = VOLPATH.format(depth=8) + sensor(**VIEW) + light + CHECKER_FLOOR
    s = {
        "roughconductor_beckmann_au": surf + _sphere('<bsdf type="roughconductor"><string name="material" value="Au"/>'
                                                     '<float name="alpha" value="0.2"/></bsdf>'),
        "roughconductor_ggx_anisotropic": surf + _sphere(
            '<bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha_u" value="0.05"/>'
            '<float name="alpha_v" value="0.4"/><string name="material" value="Cu"/></bsdf>'),
        "roughconductor_all_normals": surf + _sphere(
            '<bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha" value="0.5"/>'
            '<boolean name="sample_visible" value="false"/></bsdf>'),
        "roughconductor_textured_alpha": surf + _sphere(
            '<bsdf type="roughconductor"><texture type="bitmap" name="alpha"><string name="filename" value="rough.png"/>'
            '<boolean name="raw" value="true"/></texture><rgb name="specular_reflectance" value="0.9, 0.6, 0.3"/></bsdf>'),
        "roughdielectric_ggx": surf + _sphere('<bsdf type="roughdielectric"><string name="distribution" value="ggx"/>'
                                              '<float name="alpha" value="0.15"/></bsdf>'),
        "roughdielectric_all_normals": surf + _sphere(
            '<bsdf type="roughdielectric"><float name="alpha" value="0.3"/><boolean name="sample_visible" value="false"/>'
            '<float name="int_ior" value="1.33"/></bsdf>'),
        "rough_glass_with_medium": vol + _sphere(
            '<bsdf type="roughdielectric"><string name="distribution" value="ggx"/><float name="alpha" value="0.2"/>'
            '</bsdf><medium type="homogeneous" name="interior"><rgb name="sigma_t" value="0.4, 0.6, 1"/><float name="scale" value="4"/>'
            '<float name="albedo" value="0.9"/></medium>'),
        "plastic": surf + _sphere('<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.6, 0.2, 0.1"/></bsdf>'),
        "plastic_nonlinear": surf + _sphere('<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.6, 0.2, 0.1"/>'
                                            '<boolean name="nonlinear" value="true"/><float name="int_ior" value="1.8"/></bsdf>'),
        "roughplastic_ggx": surf + _sphere('<bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
                                           '<float name="alpha" value="0.2"/>'
                                           '<rgb name="diffuse_reflectance" value="0.2, 0.5, 0.7"/></bsdf>'),
        "roughplastic_textured": surf + _sphere(
            '<bsdf type="roughplastic"><float name="alpha" value="0.4"/><texture type="bitmap" name="diffuse_reflectance">'
            '<string name="filename" value="noise.png"/></texture><boolean name="nonlinear" value="true"/></bsdf>'),
        "twosided_roughplastic_back": surf + (
            '<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="200"/></transform>'
            '<bsdf type="twosided"><bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.7, 0.3, 0.2"/>'
            '</bsdf></bsdf></shape>'),
        "thindielectric": vol + _sphere('<bsdf type="thindielectric"><rgb name="specular_transmittance" value="0.9, 0.5, 0.3"/>'
                                        '</bsdf>'),
        "mask_checkerboard": vol + _sphere(
            '<bsdf type="mask"><texture type="checkerboard" name="opacity"><rgb name="color0" value="0.1"/>'
            '<rgb name="color1" value="0.9"/><transform name="to_uv"><scale x="8" y="4"/></transform></texture>'
            '<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.4, 0.2"/></bsdf></bsdf></bsdf>'),
        "bumpmap": surf + _sphere(
            '<bsdf type="bumpmap"><texture type="bitmap" name="height"><string name="filename" value="height.exr"/>'
            '<boolean name="raw" value="true"/></texture><float name="scale" value="0.5"/>'
            '<bsdf type="roughconductor"><float name="alpha" value="0.1"/></bsdf></bsdf>'),
        "normalmap": surf + _sphere(
            '<bsdf type="normalmap"><texture type="bitmap" name="normalmap"><string name="filename" value="normals.png"/>'
            '<boolean name="raw" value="true"/></texture><bsdf type="diffuse"/></bsdf>'),
    }
    plain = PATH.format(depth=2) + sensor() + '<emitter type="constant"><rgb name="radiance" value="1"/></emitter>'
    s["bitmap_nearest_rotated"] = plain + (
        '<shape type="rectangle"><transform name="to_world"><rotate z="1" angle="20"/></transform><bsdf type="diffuse">'
        '<texture type="bitmap" name="reflectance"><string name="filename" value="grad.exr"/>'
        '<string name="filter_type" value="nearest"/></texture></bsdf></shape>')
    s["bitmap_bilinear_mirror_to_uv"] = plain + (
        '<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="noise.png"/><string name="wrap_mode" value="mirror"/>'
        '<transform name="to_uv"><scale x="2.5" y="1.7"/><translate x="-0.3" y="0.2"/></transform></texture></bsdf></shape>')
    s["bitmap_clamp_gray"] = plain + (
        '<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="gray.png"/><string name="wrap_mode" value="clamp"/>'
        '<transform name="to_uv"><scale value="1.6"/><translate x="-0.3" y="-0.3"/></transform></texture></bsdf></shape>')
    s["checkerboard_sphere_nested"] = plain + (
        '<shape type="sphere"><transform name="to_world"><rotate x="1" angle="50"/><rotate y="1" angle="30"/>'
        '</transform><bsdf type="diffuse"><texture type="checkerboard" name="reflectance">'
        '<rgb name="color0" value="0.9, 0.2, 0.1"/><texture type="bitmap" name="color1">'
        '<string name="filename" value="grad.exr"/></texture>'
        '<transform name="to_uv"><scale x="6" y="4"/></transform></texture></bsdf></shape>')
    s["disk_cube_cylinder_uvs"] = plain + (
        '<shape type="disk"><transform name="to_world"><scale value="0.8"/><translate x="-0.9" y="0.5"/></transform>'
        '<bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><transform name="to_uv">'
        '<scale x="4" y="8"/></transform></texture></bsdf></shape>'
        '<shape type="cube"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="35"/>'
        '<rotate y="1" angle="25"/><translate x="0.9" y="0.5"/></transform><bsdf type="diffuse">'
        '<texture type="bitmap" name="reflectance"><string name="filename" value="gray.png"/>'
        '<string name="filter_type" value="nearest"/></texture></bsdf></shape>'
        '<shape type="cylinder"><point name="p0" value="-0.3, -1.2, 0"/><point name="p1" value="0.2, -0.3, 0.3"/>'
        '<float name="radius" value="0.4"/><bsdf type="diffuse"><texture type="checkerboard" name="reflectance">'
        '<transform name="to_uv"><scale x="8" y="3"/></transform></texture></bsdf></shape>')
    s["mesh_uvs_obj_ply"] = plain + (
        '<shape type="obj"><string name="filename" value="quad.obj"/><transform name="to_world"><scale value="0.8"/>'
        '<translate x="-0.85"/></transform><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="grad.exr"/></texture></bsdf></shape>'
        '<shape type="ply"><string name="filename" value="quad.ply"/><transform name="to_world"><scale value="0.8"/>'
        '<translate x="0.85"/></transform><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="grad.exr"/></texture></bsdf></shape>')
    return {name: scene_xml(body) for name, body in s.items()}


CASES = _cases()


@pytest.fixture(scope="module")
def mitsuba_images(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mitsuba_materials")
    _files(folder)
    jobs = []
    for name, text in CASES.items():
        (folder / f"{name}.xml").write_text(text)
        jobs.append({"scene": str(folder / f"{name}.xml"), "out": str(folder / name), "spp": 256,
                     "seeds": SEEDS, "variant": VARIANT})
    return folder, mitsuba_references(folder, jobs, timeout=3600)


@pytest.mark.parametrize("name", list(CASES))
def test_matches_mitsuba(mitsuba_images, device, name):
    folder, references = mitsuba_images
    mean, var = reference_image(references, str(folder / name))
    scene = load(folder / f"{name}.xml")
    result = Renderer(scene, device=device, seed=3).render(512)
    assert_mean_matches(result, mean, blocks=4, what=name, expected_variance=var)
