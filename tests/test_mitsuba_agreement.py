"""Each Mitsuba element volcl reads since it opens real Mitsuba files, against Mitsuba 3 itself: small
scenes written for the test, one file for both renderers, and volcl's image must match Mitsuba's
within the standard error both renders' variances predict (Mitsuba's from the spread of several
seeds), per channel over the image and over 4 x 4 blocks.

Optional: skipped without Mitsuba 3 (the interpreter in $VOLCL_MITSUBA_PYTHON, or
/work/mitsuba-venv/bin/python). Mitsuba runs once for all the scenes, in a subprocess
(tests/mitsuba_runner.py), never inside volcl's process.
"""
import json
import os
import struct
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

from imagestats import assert_mean_matches
from volcl.image import read_image
from volcl.renderer import Renderer
from volcl.scene import load

HERE = Path(__file__).resolve().parent
DEFAULT_MITSUBA = Path("/work/mitsuba-venv/bin/python")
VARIANT = "llvm_ad_rgb"
SEEDS = list(range(16))


def mitsuba_python():
    env = os.environ.get("VOLCL_MITSUBA_PYTHON")
    if env:
        return env
    return str(DEFAULT_MITSUBA) if DEFAULT_MITSUBA.is_file() else None


def mitsuba_references(folder: Path, jobs: list, timeout: float = 1800):
    """Mitsuba renders `jobs` (dicts of scene, out, spp, seeds, variant[, defines]) in its own
    interpreter (tests/mitsuba_runner.py); the calling test skips without Mitsuba. Returns
    (status line by output, Mitsuba's stderr)."""
    python = mitsuba_python()
    if python is None or subprocess.run([python, "-c", "import mitsuba"], capture_output=True).returncode != 0:
        pytest.skip("Mitsuba 3 not found (set VOLCL_MITSUBA_PYTHON to a Python that has it)")
    (folder / "jobs.json").write_text(json.dumps(jobs))
    proc = subprocess.run([python, str(HERE / "mitsuba_runner.py"), str(folder / "jobs.json")],
                          capture_output=True, text=True, timeout=timeout)
    status = {line.split()[1].rstrip(":"): line for line in proc.stdout.splitlines()
              if line.startswith(("done", "failed"))}
    return status, proc.stderr


def reference_image(references, out: str):
    """(mean, variance of the mean) of Mitsuba's seeds for the job writing `out`; fails, with what
    Mitsuba said, where it could not render it."""
    status, stderr = references
    assert status.get(out, "").startswith("done"), f"Mitsuba could not render {out}: {status.get(out)} {stderr[-2000:]}"
    mean, _ = read_image(out + "_mean.exr")
    var, _ = read_image(out + "_var.exr")
    return mean[..., :3], var[..., :3]


def sensor(width=24, height=24, spp=64, origin="0, 0, 4", target="0, 0, 0", up="0, 1, 0", fov=40,
           kind="perspective", extra=""):
    fov_xml = f'<float name="fov" value="{fov}"/>' if kind != "orthographic" else ""
    return f'''<sensor type="{kind}">{fov_xml}{extra}
        <transform name="to_world"><lookat origin="{origin}" target="{target}" up="{up}"/></transform>
        <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{height}"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    </sensor>'''


def scene_xml(body, version="3.0.0"):
    return f'<scene version="{version}">\n{body}\n</scene>\n'


PATH = '<integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>'
LIGHT = ('<shape type="rectangle"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/>'
         '<translate y="2"/></transform><emitter type="area"><rgb name="radiance" value="{radiance}"/>'
         '</emitter></shape>')
FLOOR = ('<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>'
         '<translate y="-1"/></transform><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/>'
         '</bsdf></shape>')


def write_serialized(path, meshes, version=4):
    """A Mitsuba .serialized file of (vertices, faces[, normals]) meshes, as Mitsuba writes them."""
    blobs, offsets = [], []
    for vertices, faces, normals in meshes:
        flags = 0x1000 | (0x1 if normals is not None else 0)
        body = struct.pack("<I", flags) + (b"mesh\0" if version == 4 else b"")
        body += struct.pack("<QQ", len(vertices), len(faces))
        body += np.asarray(vertices, "<f4").tobytes()
        if normals is not None:
            body += np.asarray(normals, "<f4").tobytes()
        body += np.asarray(faces, "<u4").tobytes()
        blobs.append(struct.pack("<HH", 0x041C, version) + zlib.compress(body))
    data = b""
    for blob in blobs:
        offsets.append(len(data))
        data += blob
    data += b"".join(struct.pack("<Q" if version == 4 else "<I", o) for o in offsets)
    data += struct.pack("<I", len(blobs))
    Path(path).write_bytes(data)


def uv_sphere(rows=6, cols=8):
    """A coarse unit sphere as shared-vertex triangles (no normals in the file)."""
    verts = [[0, 0, 1]]
    for i in range(1, rows):
        th = np.pi * i / rows
        verts += [[np.sin(th) * np.cos(2 * np.pi * j / cols), np.sin(th) * np.sin(2 * np.pi * j / cols),
                   np.cos(th)] for j in range(cols)]
    verts.append([0, 0, -1])
    faces = []
    ring = lambda i, j: 1 + (i - 1) * cols + j % cols     # noqa: E731
    for j in range(cols):
        faces.append([0, ring(1, j), ring(1, j + 1)])
        faces.append([len(verts) - 1, ring(rows - 1, j + 1), ring(rows - 1, j)])
    for i in range(1, rows - 1):
        for j in range(cols):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            faces += [[a, c, d], [a, d, b]]
    return np.array(verts, float), np.array(faces)


def write_obj(path, vertices, faces, normals=None):
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in vertices]
    if normals is not None:
        lines += [f"vn {x:.7g} {y:.7g} {z:.7g}" for x, y, z in normals]
        lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in faces]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    Path(path).write_text("\n".join(lines) + "\n")


def write_image(path, pixels, fmt=None):
    import OpenImageIO as oiio
    pixels = np.ascontiguousarray(pixels)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt or oiio.FLOAT))
    out.write_image(pixels)
    out.close()


def sky_image(h=16, w=32):
    """A sky over a dark ground with a small bright sun: texels with real contrast."""
    theta = (np.arange(h)[:, None] + 0.5) / h * np.pi
    phi = (np.arange(w)[None, :] + 0.5) / w * 2 * np.pi
    up = np.clip(np.cos(theta), 0, None)
    sky = (0.3 + 1.5 * up + 0.4 * np.cos(phi) * up)[..., None] * np.array([0.5, 0.7, 1.0])
    sky = np.where(theta[..., None] < np.pi / 2, sky, np.array([0.15, 0.1, 0.05]))
    sky[h // 4, (2 * w) // 3] = [60.0, 50.0, 40.0]
    return sky.astype(np.float32)


def _files(folder):
    """Meshes, includes, spectra and images the scenes below refer to."""
    import OpenImageIO as oiio
    write_image(folder / "sky.exr", sky_image())
    codes = (np.clip(sky_image(16, 24) / 2.0, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)     # 3:2, sRGB
    write_image(folder / "sky_3x2.png", codes, oiio.UINT8)
    v, f = uv_sphere()
    write_obj(folder / "coarse_sphere.obj", v, f)
    write_obj(folder / "coarse_sphere_normals.obj", v, f, normals=v / np.linalg.norm(v, axis=1, keepdims=True))
    write_serialized(folder / "two.serialized", [(v * 0.5, f, None), (v, f, v)])
    box_v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4)]    # open at +z
    box_f = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    write_obj(folder / "open_box.obj", box_v, box_f)
    (folder / "parts").mkdir(exist_ok=True)
    (folder / "assets").mkdir(exist_ok=True)
    write_obj(folder / "assets" / "found_by_path.obj", v * 0.8, f)
    (folder / "parts" / "lights.xml").write_text(scene_xml(
        '<default name="glow" value="6"/>' + LIGHT.format(radiance="$glow"), "2.1.0"))
    (folder / "parts" / "material.xml").write_text(
        '<bsdf version="3.0.0" type="diffuse" id="included_bsdf"><rgb name="reflectance" value="0.3, 0.6, 0.2"/></bsdf>\n')
    (folder / "green.spd").write_text("# a file of wavelength value lines\n400 0.05\n500 0.6\n600 0.2\n700 0.1\n")


def _cases():
    """name -> (scene file text, volcl spp, Mitsuba spp per seed, Mitsuba variant)."""
    s = {}
    s["rotate_axis_as_given"] = scene_xml(PATH.format(depth=3) + sensor() + LIGHT.format(radiance=8) + FLOOR + (
        '<shape type="obj"><string name="filename" value="coarse_sphere_normals.obj"/><transform name="to_world">'
        '<scale value="0.6"/><rotate x="0" y="1" z="1" angle="40"/></transform></shape>'))
    s["emitter_default_black"] = scene_xml(PATH.format(depth=4) + sensor(origin="0, 0.5, 4", target="0, 1, 0")
                                           + LIGHT.format(radiance=5) + FLOOR + (
        '<shape type="rectangle"><transform name="to_world"><scale value="0.6"/><translate y="1" z="-0.5"/>'
        '</transform><emitter type="area"><rgb name="radiance" value="0.2, 0.4, 0.1"/></emitter></shape>'))
    s["spectra"] = scene_xml(PATH.format(depth=3) + sensor() + (
        '<shape type="rectangle"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/>'
        '<translate y="2"/></transform><emitter type="area">'
        '<spectrum name="radiance" value="400:2, 500:8, 600:5, 700:9"/></emitter></shape>'
        '<emitter type="point"><point name="position" value="1, 1, 1"/><spectrum name="intensity" value="2"/></emitter>'
        '<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>'
        '<translate y="-1"/></transform><bsdf type="diffuse"><spectrum name="reflectance" '
        'value="400:0.1, 450:0.7, 550:0.2, 650:0.9, 700:0.4"/></bsdf></shape>'
        '<shape type="sphere"><float name="radius" value="0.5"/><bsdf type="diffuse">'
        '<spectrum name="reflectance" filename="green.spd"/></bsdf></shape>'))
    s["blackbody"] = scene_xml(PATH.format(depth=3) + sensor() + FLOOR + (
        '<shape type="sphere"><float name="radius" value="0.4"/><emitter type="area">'
        '<spectrum type="blackbody" name="radiance"><float name="temperature" value="4500"/></spectrum>'
        '</emitter></shape>'.replace("</emitter>", "</emitter>").replace(
            '<shape type="sphere">', '<shape type="sphere"><point name="center" value="0, 0.2, 0"/>')))
    direct = ('<integrator type="direct"><integer name="emitter_samples" value="{e}"/>'
              '<integer name="bsdf_samples" value="{b}"/></integrator>')
    direct_scene = (sensor() + LIGHT.format(radiance=6) + FLOOR
                    + '<emitter type="point"><point name="position" value="-1, 1, 1"/><rgb name="intensity" value="1"/></emitter>'
                    + '<shape type="sphere"><float name="radius" value="0.5"/><bsdf type="dielectric"/></shape>'
                    + '<emitter type="constant"><rgb name="radiance" value="0.05"/></emitter>')
    for e, b in ((1, 1), (3, 0), (0, 2), (2, 3)):
        s[f"direct_e{e}_b{b}"] = scene_xml(direct.format(e=e, b=b) + direct_scene)
    s["moment_wrapper"] = scene_xml('<integrator type="moment"><integrator type="volpath"><integer name="max_depth" '
                                    'value="3"/></integrator></integrator>' + sensor() + LIGHT.format(radiance=8) + FLOOR)
    s["thinlens"] = scene_xml(PATH.format(depth=3) + sensor(kind="thinlens", extra=(
        '<float name="aperture_radius" value="0.25"/><float name="focus_distance" value="2.5"/>'))
        + LIGHT.format(radiance=8) + FLOOR + '<shape type="sphere"><float name="radius" value="0.3"/></shape>')
    s["orthographic"] = scene_xml(PATH.format(depth=3) + sensor(kind="orthographic", width=32, height=24).replace(
        '<lookat', '<scale x="1.5" y="1.5"/><lookat') + LIGHT.format(radiance=8) + FLOOR
        + '<shape type="sphere"><float name="radius" value="0.5"/></shape>')
    s["principal_point"] = scene_xml(PATH.format(depth=3) + sensor(extra=(
        '<float name="principal_point_offset_x" value="0.15"/><float name="principal_point_offset_y" value="-0.1"/>'))
        + LIGHT.format(radiance=8) + FLOOR + '<shape type="sphere"><float name="radius" value="0.5"/></shape>')
    s["focal_length"] = scene_xml(PATH.format(depth=3) + sensor().replace('<float name="fov" value="40"/>',
                                                                          '<string name="focal_length" value="35mm"/>')
                                  + LIGHT.format(radiance=8) + FLOOR)
    s["cylinders"] = scene_xml(PATH.format(depth=4) + sensor(origin="1, 1.5, 4") + LIGHT.format(radiance=6) + FLOOR + (
        '<shape type="cylinder"><point name="p0" value="-0.8, -1, 0"/><point name="p1" value="-0.6, 0.5, 0.2"/>'
        '<float name="radius" value="0.3"/><bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf></shape>'
        '<shape type="cylinder"><transform name="to_world"><scale x="0.2" y="0.2" z="1.2"/><rotate x="1" angle="-90"/>'
        '<translate x="0.7" y="-1"/></transform><emitter type="area"><rgb name="radiance" value="2, 1, 0.5"/>'
        '</emitter></shape>'))
    s["serialized"] = scene_xml(PATH.format(depth=3) + sensor() + LIGHT.format(radiance=8) + FLOOR + (
        '<shape type="serialized"><string name="filename" value="two.serialized"/><transform name="to_world">'
        '<translate x="-0.6"/></transform></shape>'
        '<shape type="serialized"><string name="filename" value="two.serialized"/><integer name="shape_index" value="1"/>'
        '<transform name="to_world"><scale value="0.4"/><translate x="0.7"/></transform></shape>'))
    s["smooth_normals_recomputed"] = scene_xml(PATH.format(depth=3) + sensor() + LIGHT.format(radiance=8) + FLOOR + (
        '<shape type="obj"><string name="filename" value="coarse_sphere.obj"/><transform name="to_world">'
        '<scale value="0.7"/></transform></shape>'))
    s["dielectric_shading_normals"] = scene_xml(PATH.format(depth=8) + sensor() + LIGHT.format(radiance=8) + FLOOR + (
        '<shape type="obj"><string name="filename" value="coarse_sphere_normals.obj"/><transform name="to_world">'
        '<scale value="0.8"/></transform><bsdf type="dielectric"><string name="int_ior" value="acrylic glass"/>'
        '</bsdf></shape>'))
    s["open_mesh_medium"] = scene_xml('<integrator type="volpath"><integer name="max_depth" value="12"/></integrator>'
                                      + sensor(origin="0.5, 0.5, 4") + LIGHT.format(radiance=8) + FLOOR + (
        '<shape type="obj"><string name="filename" value="open_box.obj"/><transform name="to_world">'
        '<scale value="0.7"/></transform><bsdf type="null"/><medium type="homogeneous" name="interior">'
        '<rgb name="sigma_t" value="1, 0.5, 0.25"/><float name="scale" value="2"/><float name="albedo" value="0.8"/></medium></shape>'))
    s["files_and_references"] = scene_xml(
        '<path value="assets"/>' + PATH.format(depth=3) + sensor()
        + '<include filename="parts/lights.xml"/><include filename="parts/material.xml"/>'
        + FLOOR + '<shape type="obj"><string name="filename" value="found_by_path.obj"/><ref id="later"/></shape>'
        + '<alias id="included_bsdf" as="aliased"/>'
        + '<shape type="sphere"><float name="radius" value="0.3"/><point name="center" value="0.8, 0, 0.5"/>'
          '<ref id="aliased"/></shape>'
        + '<bsdf type="diffuse" id="later"><rgb name="reflectance" value="0.2, 0.3, 0.8"/></bsdf>', version="2.1.0")
    s["hide_emitters_path"] = scene_xml('<integrator type="path"><integer name="max_depth" value="3"/>'
                                        '<boolean name="hide_emitters" value="true"/></integrator>'
                                        + sensor(origin="0, 2.3, 3", target="0, 1.8, 0") + LIGHT.format(radiance=8)
                                        + FLOOR + '<emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>'
                                        + '<shape type="sphere"><float name="radius" value="0.5"/></shape>')
    s["path_ignores_media"] = scene_xml(PATH.format(depth=-1) + sensor() + LIGHT.format(radiance=8) + FLOOR + (
        '<shape type="sphere"><float name="radius" value="0.7"/><bsdf type="null"/>'
        '<medium type="homogeneous" name="interior"><float name="sigma_t" value="3"/></medium></shape>'))
    env = ('<emitter type="envmap"><string name="filename" value="{file}"/><float name="scale" value="{scale}"/>'
           '<transform name="to_world">{frame}</transform></emitter>')
    sky = env.format(file="sky.exr", scale=1.5, frame='<rotate y="1" angle="70"/><rotate x="1" angle="-10"/>')
    s["envmap_surfaces"] = scene_xml(PATH.format(depth=4) + sensor(origin="0, 1, 4") + sky + FLOOR + (
        '<shape type="sphere"><point name="center" value="-0.6, 0, 0"/><float name="radius" value="0.5"/></shape>'
        '<shape type="sphere"><point name="center" value="0.6, 0, 0.2"/><float name="radius" value="0.45"/>'
        '<bsdf type="dielectric"/></shape>'))
    s["envmap_medium"] = scene_xml('<integrator type="volpath"><integer name="max_depth" value="24"/></integrator>'
                                   + sensor(origin="0, 0.8, 4") + sky + FLOOR + (
        '<shape type="sphere"><float name="radius" value="0.8"/><bsdf type="null"/>'
        '<medium type="homogeneous" name="interior"><rgb name="sigma_t" value="0.25, 0.5, 1"/><float name="scale" value="4"/>'
        '<float name="albedo" value="0.9"/><phase type="hg"><float name="g" value="0.5"/></phase></medium></shape>'))
    s["envmap_png_3x2_mirrored"] = scene_xml(PATH.format(depth=3) + sensor() + env.format(
        file="sky_3x2.png", scale=1.0, frame='<scale x="-1"/><rotate z="1" angle="30"/>') + (
        '<shape type="sphere"><float name="radius" value="0.7"/><bsdf type="diffuse">'
        '<rgb name="reflectance" value="0.8, 0.6, 0.4"/></bsdf></shape>'))
    s["envmap_direct"] = scene_xml(direct.format(e=2, b=1) + sensor(origin="0, 1, 4") + sky + FLOOR
                                   + '<shape type="sphere"><float name="radius" value="0.6"/></shape>')
    s["envmap_hidden"] = scene_xml('<integrator type="volpath"><integer name="max_depth" value="6"/>'
                                   '<boolean name="hide_emitters" value="true"/></integrator>'
                                   + sensor(origin="0, 1, 4") + sky + FLOOR
                                   + '<shape type="sphere"><float name="radius" value="0.6"/></shape>')
    spot = ('<emitter type="spot"><rgb name="intensity" value="{i}"/><float name="cutoff_angle" value="{c}"/>'
            '<float name="beam_width" value="{b}"/><transform name="to_world"><lookat origin="{o}" target="{t}"/>'
            '</transform></emitter>')
    s["spot_surfaces"] = scene_xml(PATH.format(depth=3) + sensor(origin="0, 1.5, 4") + FLOOR
                                   + spot.format(i="30, 20, 10", c=35, b=20, o="0.5, 1.5, 0.5", t="-0.2, -1, 0")
                                   + spot.format(i="8", c=15, b=15, o="-1, 1, 1", t="0.3, -1, -0.3")
                                   + '<shape type="sphere"><float name="radius" value="0.4"/></shape>')
    s["spot_in_fog"] = scene_xml('<integrator type="volpath"><integer name="max_depth" value="12"/></integrator>'
                                 + sensor(origin="0, 0.5, 4") + FLOOR
                                 + spot.format(i="20", c=30, b=25, o="0, 0.8, 0", t="0.3, -1, 0") + (
        '<shape type="cube"><transform name="to_world"><scale x="2" y="1.1" z="1.5"/><translate y="0.2"/>'
        '</transform><bsdf type="null"/><medium type="homogeneous" name="interior">'
        '<rgb name="sigma_t" value="0.3"/><float name="albedo" value="0.9"/></medium></shape>'))
    # Mitsuba's projection texture: a checkerboard in the spot's cone (the uvs of its square)
    slide = ('<texture type="checkerboard" name="texture"><rgb name="color0" value="1, 0.7, 0.3"/>'
             '<rgb name="color1" value="0.1, 0.3, 0.9"/><transform name="to_uv"><scale value="4"/></transform>'
             '</texture></emitter>')
    s["spot_textured"] = scene_xml(PATH.format(depth=3) + sensor(origin="0, 1.5, 4") + FLOOR
                                   + spot.format(i="30", c=35, b=25, o="0.3, 1.5, 0.5", t="-0.1, -1, 0")
                                   .replace("</emitter>", slide))
    s["spot_textured_in_fog"] = s["spot_in_fog"].replace("</emitter>", slide, 1)
    spp = {"blackbody": 256}
    return {name: (text, spp.get(name, 512), 256, "llvm_ad_spectral" if name == "blackbody" else VARIANT)
            for name, text in s.items()}


CASES = _cases()


@pytest.fixture(scope="module")
def mitsuba_images(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mitsuba_agreement")
    _files(folder)
    jobs = []
    for name, (text, _, spp, variant) in CASES.items():
        (folder / f"{name}.xml").write_text(text)
        jobs.append({"scene": str(folder / f"{name}.xml"), "out": str(folder / name), "spp": spp,
                     "seeds": SEEDS, "variant": variant})
    return folder, mitsuba_references(folder, jobs)


@pytest.mark.parametrize("name", list(CASES))
def test_matches_mitsuba(mitsuba_images, device, name):
    folder, references = mitsuba_images
    mean, var = reference_image(references, str(folder / name))
    scene = load(folder / f"{name}.xml")
    result = Renderer(scene, device=device, seed=3).render(CASES[name][1])
    # Mitsuba's variance is that of the mean of its seeds' images; its renders share nothing
    assert_mean_matches(result, mean, blocks=4, what=name, expected_variance=var)
