"""Mitsuba's shapegroup and instance as the parser reads them (shapes kept once, in the group's
space; instances with their to_world), the warnings where volcl follows Mitsuba's rules, and an
identity instance rendering like the same shapes placed directly."""
import numpy as np
import pytest

from imagestats import assert_images_match
from volcl.renderer import Renderer
from volcl.scene import load_string

GROUP = ('<shape type="shapegroup" id="g">'
         '<shape type="sphere"><point name="center" x="0.3" y="0" z="0"/><float name="radius" value="0.4"/>'
         '<bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>'
         '<shape type="cube"><transform name="to_world"><scale value="0.3"/><translate x="-0.6"/></transform>'
         '<bsdf type="diffuse"/></shape></shape>')


def scene(body):
    return load_string(f'<scene version="3.0.0">{body}</scene>')


def test_group_shapes_are_kept_once_in_group_space():
    s = scene(GROUP + ''.join(f'<shape type="instance"><ref id="g"/><transform name="to_world">'
                              f'<scale x="2" y="1" z="0.5"/><translate x="{x}"/></transform></shape>' for x in range(5)))
    assert len(s.instances) == 5
    assert len(s.shapes) == 2 and all(sh.group is s.instances[0].group for sh in s.shapes)
    sphere = next(sh for sh in s.shapes if sh.kind == "sphere")
    assert np.allclose(sphere.center, [0.3, 0, 0]) and sphere.radius == pytest.approx(0.4)
    expected = np.diag([2.0, 1.0, 0.5, 1.0])
    expected[0, 3] = 3.0
    assert np.allclose(s.instances[3].to_world, expected)


def test_unused_group_renders_nothing_and_own_shapes_come_first():
    s = scene(GROUP + '<shape type="shapegroup" id="unused"><shape type="cube"/></shape>'
              '<shape type="rectangle"/><shape type="instance"><ref id="g"/></shape>')
    assert [sh.kind for sh in s.shapes] == ["mesh", "sphere", "mesh"]
    assert s.shapes[0].group is None and s.shapes[1].group is not None


def test_group_to_world_is_ignored_with_a_warning():
    s = scene('<shape type="shapegroup" id="g"><transform name="to_world"><translate x="5"/></transform>'
              '<shape type="cube"/></shape><shape type="instance"><ref id="g"/></shape>')
    assert any("shapegroup's to_world is ignored" in str(w) for w in s.warnings)
    assert np.allclose(s.shapes[0].vertices.mean(0), 0)


def test_nested_group_declared_inline_in_an_instance():
    s = scene('<shape type="instance"><shape type="shapegroup"><shape type="cube"/></shape></shape>')
    assert len(s.instances) == 1 and len(s.shapes) == 1


def test_scene_without_instances_has_no_instance_feature():
    from volcl.features import detect
    assert not detect(scene('<shape type="cube"/>'))["INSTANCES"]
    assert detect(scene(GROUP + '<shape type="instance"><ref id="g"/></shape>'))["INSTANCES"]


SETUP = ('<integrator type="path"><integer name="max_depth" value="3"/></integrator>'
         '<sensor type="perspective"><float name="fov" value="45"/><transform name="to_world">'
         '<lookat origin="0, 0.5, 3" target="0, 0, 0" up="0, 1, 0"/></transform>'
         '<film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="16"/>'
         '<rfilter type="box"/></film></sensor>'
         '<shape type="rectangle"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/>'
         '<translate y="1.5"/></transform><emitter type="area"><rgb name="radiance" value="6"/></emitter></shape>'
         '<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>'
         '<translate y="-0.5"/></transform><bsdf type="diffuse"/></shape>')


def test_identity_instance_renders_like_the_flat_shapes(device):
    flat_body = GROUP.replace('<shape type="shapegroup" id="g">', '')[:-len('</shape>')]
    flat = scene(SETUP + flat_body)
    inst = scene(SETUP + GROUP + '<shape type="instance"><ref id="g"/></shape>')
    assert not flat.instances and len(inst.instances) == 1
    a = Renderer(flat, device=device, seed=1).render(128)
    b = Renderer(inst, device=device, seed=2).render(128)
    assert_images_match(a, b, what="identity instance vs flat shapes")


def test_geometry_is_stored_once_however_many_instances():
    """What the pre-upload memory check sums (the packed buffers): the group's triangles once; each
    further instance adds its record and a top-level leaf slot, not a copy of the mesh."""
    from volcl import layout
    from volcl.pack import Packer

    def packed(n):
        body = ('<shape type="shapegroup" id="g"><shape type="cube"/><shape type="sphere"/></shape>'
                + ''.join(f'<shape type="instance"><ref id="g"/><transform name="to_world"><translate x="{3 * k}"/>'
                          f'</transform></shape>' for k in range(n)))
        return Packer(scene(body)).pack()
    one, many = packed(1), packed(64)
    assert len(many.arrays["triangles"]) == len(one.arrays["triangles"]) == 12
    assert len(many.arrays["spheres"]) == 1 and len(many.arrays["instances"]) == 64
    grown = sum(a.nbytes for a in many.arrays.values()) - sum(a.nbytes for a in one.arrays.values())
    per_instance = layout.INSTANCE.itemsize + layout.LEAF_PACKET.itemsize + layout.BVH_WIDE_NODE.itemsize
    assert grown <= 63 * per_instance, grown


def test_editing_an_instance_to_world_renders_what_loading_it_renders(device):
    """volcl.traverse: "<instance id>.to_world" moves one placement (bit for bit the image of the
    file that places it there); a singular matrix is refused."""
    import volcl
    placed = '<shape type="instance" id="second"><ref id="g"/><transform name="to_world">{}</transform></shape>'
    text = (SETUP.replace('value="20"', 'value="12"').replace('value="16"', 'value="10"') + GROUP
            + '<shape type="instance"><ref id="g"/><transform name="to_world"><translate x="-0.8"/></transform></shape>')
    edited = volcl.load_string('<scene version="3.0.0">' + text + placed.format('<translate x="0.8"/>') + '</scene>')
    before = volcl.render(edited, spp=4, seed=3, device=device)
    params = volcl.traverse(edited)
    assert "second.to_world" in params and "instance_0.to_world" in params
    m = np.diag([1.5, 0.6, 1.0, 1.0])
    m[:3, 3] = [0.7, 0.1, -0.2]
    params["second.to_world"] = m
    params.update()
    loaded = volcl.load_string('<scene version="3.0.0">' + text + placed.format(
        '<scale x="1.5" y="0.6" z="1"/><translate x="0.7" y="0.1" z="-0.2"/>') + '</scene>')
    a = volcl.render(edited, spp=4, seed=3, device=device)
    b = volcl.render(loaded, spp=4, seed=3, device=device)
    assert np.array_equal(a.image, b.image) and not np.array_equal(a.image, before.image)
    with pytest.raises(volcl.VolclError, match="singular"):
        params["second.to_world"] = np.diag([1.0, 0.0, 1.0, 1.0])


def test_instanced_medium_box_renders_like_the_flat_box(device):
    """A closed mesh holding a medium, instanced under a non-uniform scale and a mirror, renders like
    the same mesh placed by the same to_world directly: medium transitions follow the instance's
    normals (volpath, so the medium counts)."""
    box = ('<shape type="cube"><bsdf type="null"/><medium type="homogeneous" name="interior">'
           '<rgb name="sigma_t" value="1.5, 2.5, 4"/><rgb name="albedo" value="0.8"/></medium></shape>')
    m = '<transform name="to_world"><scale x="0.6" y="0.35" z="0.4"/><rotate y="1" angle="30"/></transform>'
    setup = SETUP.replace('type="path"', 'type="volpath"')
    flat = scene(setup + box.replace('<shape type="cube">', '<shape type="cube">' + m))
    inst = scene(setup + '<shape type="shapegroup" id="g">' + box + '</shape>'
                 f'<shape type="instance"><ref id="g"/>{m}</shape>')
    assert len(inst.instances) == 1 and not flat.instances
    a = Renderer(flat, device=device, seed=1).render(256)
    b = Renderer(inst, device=device, seed=2).render(256)
    assert_images_match(a, b, what="instanced medium box vs flat box")


def test_mirroring_instance_keeps_outward_normals(device):
    """Under a mirroring to_world Mitsuba's instance keeps the group's outward normals (the inverse
    transpose), whereas a mesh mirrored by its own to_world turns inside out (its winding is
    mirrored): the instance renders like the mirrored mesh with flip_normals, and warns."""
    box = ('<shape type="cube"><bsdf type="null"/><medium type="homogeneous" name="interior">'
           '<rgb name="sigma_t" value="1.5, 2.5, 4"/><rgb name="albedo" value="0.8"/></medium></shape>')
    m = '<transform name="to_world"><scale x="-0.6" y="0.35" z="0.4"/><rotate y="1" angle="30"/></transform>'
    setup = SETUP.replace('type="path"', 'type="volpath"')
    flipped = scene(setup + box.replace('<shape type="cube">', '<shape type="cube"><boolean name="flip_normals" '
                                        'value="true"/>' + m))
    inst = scene(setup + '<shape type="shapegroup" id="g">' + box + '</shape>'
                 f'<shape type="instance"><ref id="g"/>{m}</shape>')
    assert any("mirrors" in str(w) for w in inst.warnings)
    a = Renderer(flipped, device=device, seed=1).render(256)
    b = Renderer(inst, device=device, seed=2).render(256)
    assert_images_match(a, b, what="mirroring instance vs flipped mirrored box")


def test_mirrored_rectangle_keeps_its_normal_as_in_mitsuba():
    """Mitsuba's rectangle and disk are analytic, their normal to_world's inverse transpose of +z: a
    mirroring to_world (scale x=-1) leaves a rectangle facing +z, where a mirrored mesh (cube)
    turns inside out."""
    def normal(s):
        v = s.vertices[s.faces[0]]
        n = np.cross(v[1] - v[0], v[2] - v[0])
        return n / np.linalg.norm(n)
    mirror = '<transform name="to_world"><scale x="-1" y="1" z="1"/></transform>'
    for kind in ("rectangle", "disk"):
        flat = scene(f'<shape type="{kind}">{mirror}</shape>').shapes[0]
        assert normal(flat)[2] > 0.99, kind
        flipped = scene(f'<shape type="{kind}"><boolean name="flip_normals" value="true"/>{mirror}</shape>').shapes[0]
        assert normal(flipped)[2] < -0.99, kind
