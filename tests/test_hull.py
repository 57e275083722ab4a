"""Shadow rays from surfaces leave out the faces of the scene's convex hull (volcl/hull.py): which
faces those are, when the second tree is used, and that using it leaves the image's expectation
as it was (and that the comparison sees a tree that leaves out a face it must not)."""
import itertools

import numpy as np
import pytest

import volcl
from volcl import hull
from volcl.renderer import Renderer
from volcl.wavefront import hull_skip, tiny_lanes

from imagestats import assert_same_image

# A closed room (a cube seen from inside) with a sphere and a panel in it, lit by an area light under
# the ceiling and a point light; the panel shades part of the floor from both.
ROOM = """<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="70"/>
        <transform name="to_world"><lookat origin="0, 0.2, 0.9" target="0, -0.2, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="cube">
        <bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.6, 0.5"/></bsdf></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" value="-0.4, -0.7, -0.3"/><float name="radius" value="0.3"/>
        <bsdf type="{sphere_bsdf}"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="-90"/><translate x="0.3" y="-0.4"/></transform>
        <bsdf type="twosided"><bsdf type="diffuse"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.25"/><rotate x="1" angle="90"/><translate x="0.2" y="0.95"/></transform>
        <emitter type="area"><rgb name="radiance" value="8"/></emitter>
    </shape>
    <emitter type="point" id="bulb"><point name="position" value="{bulb}"/><rgb name="intensity" value="1.5"/></emitter>
    {extra}
</scene>"""
INSIDE = "0.3, 0.5, 0.2"
OUTSIDE = "0.3, 0.5, 3"


def room(bulb=INSIDE, extra="", depth=6, sphere_bsdf="diffuse"):
    return volcl.load_string(ROOM.format(bulb=bulb, extra=extra, depth=depth, sphere_bsdf=sphere_bsdf))


def _cube():
    p = np.array(list(itertools.product([0.0, 1.0], repeat=3)))
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([[p[a], p[b], p[c]] for a, b, c, d in quads] + [[p[a], p[c], p[d]] for a, b, c, d in quads])


def test_the_walls_of_a_room_are_hull_faces_and_what_is_inside_is_not():
    inner = np.array([[[0.4, 0.4, 0.4], [0.6, 0.4, 0.4], [0.5, 0.6, 0.5]]])
    faces, (normals, offsets), tol = hull.hull_faces(np.concatenate([_cube(), inner]), [[0.5, 0.5, 0.5]], [0.2])
    assert faces.tolist() == [True] * 12 + [False]
    # the planes face out of the room: its centre is inside, a point beyond a wall is not
    assert hull.inside([[0.5, 0.5, 0.5], [1.0, 1.0, 1.0]], (normals, offsets), tol)
    assert not hull.inside([[1.5, 0.5, 0.5]], (normals, offsets), tol)


@pytest.mark.parametrize("what, extra, walls_out", [
    ("a ball through the top", dict(centers=[[0.5, 0.5, 0.9]], radii=[0.2]), {5}),
    ("a box through the bottom", dict(box_lo=[[0.2, 0.2, -0.5]], box_hi=[[0.3, 0.3, 0.1]]), {4}),
    ("a ball touching the top from inside", dict(centers=[[0.5, 0.5, 0.8]], radii=[0.2]), set()),
])
def test_what_pokes_out_of_a_wall_takes_that_wall_off_the_hull(what, extra, walls_out):
    faces, _, _ = hull.hull_faces(_cube(), **extra)
    # _cube's quad q (x = 0, x = 1, y = 0, y = 1, z = 0, z = 1) is its triangles q and q + 6
    assert set(np.flatnonzero(~faces)) == {k for q in walls_out for k in (q, q + 6)}, what


def test_a_flat_scene_has_no_hull_faces():
    faces, _, _ = hull.hull_faces(_cube()[[0, 6]])         # one quad: everything in one plane
    assert not faces.any()


def _trees(s):
    packed = s.packed
    leaves = packed.arrays["leaves"]
    codes = lambda rows: set(int(c) for c in rows["prim"][(rows["v"] != 0).any(axis=1)].ravel() if c >= 0)
    return packed, codes(leaves[:packed.scene_leaves]), codes(leaves[packed.scene_leaves:])


def test_the_shadow_tree_leaves_out_the_walls_only():
    packed, scene_tris, shadow_tris = _trees(room())
    walls = set(range(12))                          # the cube's triangles come first
    assert int(packed.params["shadow_root"]) > 0
    assert set(packed.hull_faces.tolist()) == walls
    assert scene_tris - shadow_tris == walls and shadow_tris <= scene_tris
    spheres = packed.arrays["leaves"]["prim"][packed.scene_leaves:]
    assert (spheres < 0).sum() == 1                 # the sphere stays in it


@pytest.mark.parametrize("what, kwargs", [
    ("a point light outside the room", dict(bulb=OUTSIDE)),
    ("a spot light outside the room", dict(extra='<emitter type="spot"><transform name="to_world"><lookat '
                                                 'origin="0, 3, 0" target="0, 0, 0"/></transform></emitter>')),
    ("instances", dict(extra='<shape type="shapegroup" id="g"><shape type="sphere"><float name="radius" '
                             'value="0.1"/></shape></shape><shape type="instance"><ref id="g"/></shape>')),
])
def test_what_keeps_the_whole_tree(what, kwargs):
    packed = room(**kwargs).packed
    assert int(packed.params["shadow_root"]) == 0, what
    assert len(packed.hull_faces) == 0


def test_lights_at_infinity_keep_the_shadow_tree():
    """Their shadow rays are traced in the whole scene by the kernels (surface_shadow_root); the
    tree stays for the other lights."""
    packed = room(extra='<emitter type="constant"><rgb name="radiance" value="0.1"/></emitter>').packed
    assert int(packed.params["shadow_root"]) > 0


def test_a_big_scene_gets_no_shadow_tree():
    s = room(extra='<shape type="sphere"><float name="radius" value="0.05"/></shape>' * (hull.MAX_PRIMITIVES + 1))
    assert int(s.packed.params["shadow_root"]) == 0
    assert s.packed.scene_leaves == len(s.packed.arrays["leaves"])


def test_moving_the_light_out_of_the_room_drops_the_tree(device):
    """The choice follows edits: the point light moved out (an edit that repacks the lights only)
    renders what loading it there renders, bit for bit."""
    s = room()
    volcl.render(s, spp=1, device=device)
    params = volcl.traverse(s)
    params["bulb.position"] = [0.3, 0.5, 3.0]
    assert "params" in params.update().arrays
    assert int(s.packed.params["shadow_root"]) == 0
    a, b = (volcl.render(x, spp=16, seed=4, device=device) for x in (s, room(bulb=OUTSIDE)))
    assert a.image.tobytes() == b.image.tobytes()


def test_the_surface_stage_skips_the_same_walls():
    s = room()
    count = tiny_lanes(s.packed, s.features)[0]
    assert count == 16                              # cube, panel and light: the stage tests it whole
    skip = hull_skip(s.packed, count)
    leaves = s.packed.arrays["leaves"][:s.packed.scene_leaves]
    codes = leaves["prim"][(leaves["v"] != 0).any(axis=1)]
    assert {int(codes[k]) for k in range(count) if (skip >> k) & 1} == set(range(12))


def _no_hull(monkeypatch):
    monkeypatch.setattr(hull, "hull_faces", lambda tri_v, *rest: (np.zeros(len(tri_v), bool),
                                                                    (np.zeros((0, 3)), np.zeros(0)), 0.0))


@pytest.mark.every_implementation
@pytest.mark.parametrize("engine", ["megakernel", "wavefront"])
def test_the_shadow_tree_keeps_the_image(device, monkeypatch, engine):
    """With and without the shadow tree (hull faces forced to none): independent renders of one
    expectation, on the megakernel and on the surface stage."""
    s = room()
    assert int(s.packed.params["shadow_root"]) > 0
    with_tree = Renderer(s, device=device, seed=1, engine=engine).render(1024)
    _no_hull(monkeypatch)
    whole = room()
    assert int(whole.packed.params["shadow_root"]) == 0
    without = Renderer(whole, device=device, seed=2, engine=engine).render(1024)
    assert_same_image(with_tree, without, what=f"{engine}: walls left out of shadow rays against traced")


@pytest.mark.every_implementation
def test_the_comparison_sees_a_tree_without_the_panel(device, monkeypatch):
    """Every triangle called a hull face: the panel no longer shades the floor, and the comparison
    above reports it."""
    truth = Renderer(room(), device=device, seed=1, engine="megakernel").render(1024)
    monkeypatch.setattr(hull, "hull_faces", lambda tri_v, *rest: (np.ones(len(tri_v), bool),
                                                                    (np.zeros((0, 3)), np.zeros(0)), 0.0))
    wrong = Renderer(room(), device=device, seed=2, engine="megakernel").render(1024)
    with pytest.raises(AssertionError, match="difference"):
        assert_same_image(wrong, truth)
    assert np.mean(wrong.image) > np.mean(truth.image)
