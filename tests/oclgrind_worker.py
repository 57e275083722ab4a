"""Renders one tiny scene of a feature family on the only OpenCL device present; run by
tests/test_oclgrind.py under `oclgrind`, which simulates that device and logs every uninitialized
read, out-of-bounds access and data race. Usage: python oclgrind_worker.py FAMILY.

Also usable by hand: `VOLCL_BUILD_OPTIONS=-cl-opt-disable oclgrind --uninitialized python
tests/oclgrind_worker.py fog`."""
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

from scenebuild import (camera, constant_env, diffuse, furnace, look_at, medium, quad_mesh,  # noqa: E402
                        scene, sphere)
from volcl import device as devmod, packets, wavefront  # noqa: E402
from volcl.features import all_features  # noqa: E402
from volcl.renderer import Renderer  # noqa: E402
from volcl.scene import load  # noqa: E402
from volcl.scene.model import Bsdf, Emitter, Shape, rgb  # noqa: E402

SCENES = HERE.parent / "scenes"


def shipped(name):
    return lambda: load(SCENES / f"{name}.xml")


def lights():
    """Every kind of light at once over diffuse, conductor and dielectric surfaces."""
    fv, ff = quad_mesh((0, -1, 0), (3, 0, 0), (0, 0, -3))          # floor facing +y
    lv, lf = quad_mesh((0, 2, 0), (0.5, 0, 0), (0, 0, 0.5))        # area light facing -y
    shapes = [Shape("mesh", diffuse(0.6), vertices=fv, faces=ff),
              Shape("mesh", diffuse(0.0), vertices=lv, faces=lf, emitter_radiance=rgb(5.0)),
              sphere((-0.6, -0.5, 0), 0.5, Bsdf("conductor", reflectance=rgb(0.9))),
              sphere((0.6, -0.5, 0), 0.5, Bsdf("dielectric", int_ior=1.5, ext_ior=1.0))]
    emitters = [Emitter("point", rgb(3.0), position=np.array([1.0, 1.5, 1.0])),
                Emitter("directional", rgb(1.0), direction=np.array([0.3, -1.0, -0.2])),
                constant_env(0.2)]
    return scene(shapes, emitters, cam=camera(8, 8, fov=50, to_world=look_at((0, 0.5, 4), (0, -0.5, 0))))


def emissive_media():
    """A chromatic, anisotropic, emissive medium in a closed emitting box."""
    return furnace(0.3, radiance=0.5, medium=medium([1.0, 2.0, 0.5], [0.3, 0.6, 0.0], g=0.4, radiance=0.7))


def emission_nee_grid():
    """Next-event estimation towards a temperature grid (dense) behind a null boundary, from the
    surfaces of a dark room and from the grid's own scattering vertices."""
    from scenebuild import box_mesh, grid, hetero_medium
    from volcl.scene import transform as tf
    x = (np.arange(6) + 0.5) / 6 * 2 - 1
    r = np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2)
    to_world = tf.translate([-0.3, -0.6, -0.3]) @ tf.scale([0.6] * 3)
    med = hetero_medium(grid(np.clip(1.2 - r, 0, None) * 5, to_world), 0.4)
    med.emission_kind, med.emission_volume = "temperature", grid(np.clip(4000 * (1 - r), 0, None), to_world)
    med.emission_scale = 4.0
    v, f = box_mesh(inward=True)
    bv, bf = box_mesh(0.3, inward=False)
    shapes = [Shape("mesh", diffuse(0.6), vertices=v, faces=f),
              Shape("mesh", Bsdf("null"), vertices=bv + [0, -0.3, 0], faces=bf, interior=med)]
    return scene(shapes, cam=camera(8, 8, fov=70, to_world=tf.translate([0, 0.2, -0.9])))


SENSOR = """<sensor type="{kind}">{extra}
    <transform name="to_world"><lookat origin="0, 0.5, 4" target="0, -0.3, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
</sensor>"""
ROOM = """<shape type="rectangle"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/>
    <translate y="2"/></transform><emitter type="area"><rgb name="radiance" value="8"/></emitter></shape>
<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>
    <translate y="-1"/></transform><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf>
</shape>"""


def mitsuba(body):
    from volcl.scene import load_string
    return lambda: load_string(f'<scene version="3.0.0">{body}</scene>')


CYLINDERS = mitsuba(SENSOR.format(kind="perspective", extra='<float name="fov" value="45"/>') + ROOM + """
<shape type="cylinder"><float name="radius" value="0.3"/><point name="p0" value="-0.6, -1, 0"/>
    <point name="p1" value="-0.6, 0.2, 0"/><bsdf type="diffuse"/></shape>
<shape type="cylinder"><float name="radius" value="0.3"/><point name="p0" value="0.6, -1, 0"/>
    <point name="p1" value="0.6, 0.2, 0.3"/><bsdf type="dielectric"/></shape>""")
THINLENS = mitsuba(SENSOR.format(kind="thinlens", extra='<float name="fov" value="45"/><float name="aperture_radius" '
                                 'value="0.2"/><float name="focus_distance" value="3.5"/>') + ROOM
                   + '<shape type="sphere"><float name="radius" value="0.4"/></shape>')
ORTHOGRAPHIC = mitsuba(SENSOR.format(kind="orthographic", extra="").replace("<lookat", '<scale x="1.5" y="1.5"/><lookat')
                       + ROOM + '<shape type="sphere"><float name="radius" value="0.4"/></shape>')
DIRECT = mitsuba('<integrator type="direct"><integer name="emitter_samples" value="2"/>'
                 '<integer name="bsdf_samples" value="1"/></integrator>'
                 + SENSOR.format(kind="perspective", extra='<float name="fov" value="45"/>') + ROOM
                 + '<emitter type="point"><point name="position" value="-1, 1, 1"/><rgb name="intensity" value="1"/>'
                 '</emitter><shape type="sphere"><float name="radius" value="0.4"/><bsdf type="dielectric"/></shape>'
                 '<emitter type="constant"><rgb name="radiance" value="0.05"/></emitter>')

# a shape group (a mesh with a null-bsdf sphere and a checkerboard, for uvs through the instance) placed
# twice, once under a non-uniform scale and a shear, next to a shape of the scene's own
INSTANCES = mitsuba(SENSOR.format(kind="perspective", extra='<float name="fov" value="45"/>') + ROOM + """
<shape type="shapegroup" id="g">
    <shape type="cube"><transform name="to_world"><scale value="0.3"/></transform>
        <bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/></bsdf></shape>
    <shape type="sphere"><point name="center" value="0.5, 0, 0"/><float name="radius" value="0.3"/>
        <bsdf type="null"/></shape>
</shape>
<shape type="instance"><ref id="g"/><transform name="to_world"><translate x="-0.6"/></transform></shape>
<shape type="instance"><ref id="g"/><transform name="to_world">
    <matrix value="1.5 0.3 0 0.5  0 0.6 0 0  0 0 1 0.2  0 0 0 1"/></transform></shape>
<shape type="sphere"><point name="center" value="0, 0.6, 0"/><float name="radius" value="0.2"/></shape>""")


def phase_blends():
    """Nested blends of Rayleigh, Draine, a table and HG, in a medium furnace."""
    from volcl.scene.model import Phase
    inner = Phase("blend", weight=0.6, phases=(Phase("rayleigh"), Phase("tabulated", values=np.array([0.2, 1.0, 3.0]))))
    outer = Phase("blend", weight=0.3, phases=(Phase("draine", g=0.5, alpha=1.0), inner))
    fog = medium(1.5, 0.9)
    fog.phase = outer
    return furnace(0.5, medium=fog)


# the wavefront renderer's two lanes stages (which "auto" takes on CPUs only): the floor, the panel
# light, a point light and a glass sphere, for the stages' table reads (triangles, spheres, light
# triangles) and the path rows; few triangles and bounces, since every step is two launches of
# kernels that test every primitive for every path, which the simulator takes long over
WAVEFRONT_BODY = (SENSOR.format(kind="perspective", extra='<float name="fov" value="45"/>{medium}') + ROOM
                  + '<emitter type="point"><point name="position" value="-1, 1, 1"/><rgb name="intensity" value="2"/>'
                  '</emitter><shape type="sphere"><float name="radius" value="0.4"/><bsdf type="dielectric"/></shape>')
WAVEFRONT_SURFACE = mitsuba('<integrator type="path"><integer name="max_depth" value="4"/></integrator>'
                            + WAVEFRONT_BODY.format(medium=""))
WAVEFRONT_MEDIUM = mitsuba('<integrator type="volpath"><integer name="max_depth" value="4"/></integrator>'
                           '<medium type="homogeneous" id="fog"><rgb name="sigma_t" value="0.3"/>'
                           '<rgb name="albedo" value="0.8"/></medium>' + WAVEFRONT_BODY.format(medium='<ref id="fog"/>'))


def wavefront_surface_stage():
    return WAVEFRONT_SURFACE(), None, "wavefront"


def wavefront_medium_stage():
    return WAVEFRONT_MEDIUM(), None, "wavefront"


def wavefront_medium_loop():
    """The medium stage as PoCL builds it: its paths in a loop of each work-item (VOLCL_WF_LOOP)."""
    return WAVEFRONT_MEDIUM(), None, "wavefront loop"


# the same with a checkered floor, which the lanes' vector step evaluates itself (lanes_color_at)
PACKET_SURFACE = mitsuba('<integrator type="path"><integer name="max_depth" value="4"/></integrator>'
                         + WAVEFRONT_BODY.format(medium="").replace(
                             '<rgb name="reflectance" value="0.7, 0.5, 0.3"/>',
                             '<texture type="checkerboard" name="reflectance"><transform name="to_uv">'
                             '<scale value="4"/></transform></texture>'))


def packet_renderer():
    """The surface stage's scene with a checkered floor through the packet renderer
    (kernels/packets.cl): its lanes' queries, the vector step's table reads, the shadow rays left
    for the next step, and lanes that start samples while others finish."""
    return PACKET_SURFACE(), None, "packet"


def packet_rough_step():
    """textured_cbox through the packet renderer with its rough plastic floor's lanes in the vector
    step (kernels/lanes_rough.h): the bitmap's texel and lookup-table reads, the transmittance
    table's, and the packed entries of both steps."""
    return load(SCENES / "textured_cbox.xml"), None, "packet rough"


def every_feature():
    """The fog scene on the program with every feature compiled in."""
    return load(SCENES / "fog.xml"), all_features()


FAMILIES = {
    "surfaces": shipped("cbox"),               # spheres, diffuse, dielectric, conductor, area lights
    "shading_normals": shipped("report_nomedium"),
    "lights": lights,                          # point, directional, constant environment, area
    "media": shipped("fog"),                   # homogeneous HG medium, medium boundaries
    "chromatic_media": shipped("underwater"),
    "null_boundaries": shipped("smoke_sphere"),
    "camera_in_bounded_medium": shipped("inside_fog"),
    "emissive_media": emissive_media,          # homogeneous emission, and NEE towards it (the camera's medium)
    "emission_nee_grid": emission_nee_grid,
    "grid_media": shipped("smoke_grid"),
    "equiangular": shipped("point_in_fog"),
    "phase_families_mie": shipped("fog_mie"),
    "phase_families_fournier_forand": shipped("underwater_ff"),
    "phase_families_blends": phase_blends,
    "cylinders": CYLINDERS,
    "instances": INSTANCES,                    # shapegroup + instance: the two-level BVH
    "thinlens_camera": THINLENS,
    "orthographic_camera": ORTHOGRAPHIC,
    "direct_integrator": DIRECT,
    "envmap": shipped("cloud_sky"),            # envmap lookups and sampling, a grid medium under it
    "rough_glass_textures": shipped("rough_glass_medium"),   # roughdielectric, checkerboard, envmap
    "rough_bsdfs_bitmaps_bump_maps": shipped("textured_cbox"),  # roughconductor/plastic, bitmaps, bump and normal maps
    "every_feature": every_feature,
    "wavefront_surface_stage": wavefront_surface_stage,
    "wavefront_medium_stage": wavefront_medium_stage,
    "wavefront_medium_loop": wavefront_medium_loop,
    "packet_renderer": packet_renderer,
    "packet_rough_step": packet_rough_step,
}


def main(family, size=8, spp=1):
    made = FAMILIES[family]()
    sc, features, engine = (made + ("megakernel",))[:3] if isinstance(made, tuple) else (made, None, "megakernel")
    sc.camera.width = sc.camera.height = size
    devices = devmod.list_devices()
    assert len(devices) == 1, f"expected only the simulated device, found {[d.name for d in devices]}"
    r = Renderer(sc, device=devices[0], features=features, seed=5, engine="megakernel")
    if engine.startswith("wavefront"):
        # (the simulated device is not a CPU, which the wavefront renderer asks for, but runs it);
        # a look at the paths' flags after every step, not every 8: each launch takes the simulator
        # about a second, and the steps past the last path's end took most of the time (50 s
        # against 12 s for the surface stage's family)
        wavefront.CHECK_EVERY = 1
        loop = wavefront.LOOP_PATHS if engine.endswith("loop") else 0
        r.wavefront = wavefront.Wavefront(r.device, r.features, r.packed, r.group_items, loop=loop)
    if engine.startswith("packet"):
        # (the simulated device is not a CPU either); two passes in one launch, so that lanes start
        # a second sample while others still finish their first
        r.wavefront = packets.Packets(r.device, r.features, r.packed, vector_step=True,
                                      bsdf_steps=engine.endswith("rough"))
        assert bool(r.wavefront.bsdf_steps) == engine.endswith("rough")
        spp = 2
    res = r.render(spp)
    print(f"{family}: {res.device}, {size}x{size}, {spp} spp, invalid {res.invalid}, "
          f"mean {res.image.mean():.4g}")
    return 0 if res.invalid == 0 and np.isfinite(res.image).all() else 3


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
