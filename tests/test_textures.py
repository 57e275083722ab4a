"""Textures (kernels/textures.h) and texture coordinates (kernels/texcoords.h) against numpy
references written from Mitsuba 3.9's definitions:

- bitmap lookups: nearest (floor(uv * size)) and bilinear (between texel centres, at uv * size -
  1/2), every wrap mode (repeat, mirror, clamp), to_uv, one and three channels, colour and float
  reads (luminance), exactly the texel's value at its centre;
- checkerboards, nested, with Mitsuba's colour/float swap;
- the bump map gradient, Mitsuba's formula;
- texture coordinates and dp/du, dp/dv where rays hit rectangles, cubes, disks, spheres,
  cylinders and meshes (OBJ v flipped, barycentric uvs without any, flip_normals);
- reading images: sRGB decoding, alpha and grey channels, 2x2 padding, texel offsets in the
  packed buffer.
"""
import numpy as np
import pytest

from conftest import run_kernel
from volcl import pack
from volcl.pack_materials import MaterialPacker
from volcl.scene import load_string
from volcl.scene.model import Bsdf, Texture, rgb

pytestmark = pytest.mark.every_implementation

f32 = np.float32
LUM = np.array([0.212671, 0.715160, 0.072169])


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("texture_tests.cl")


def lookups(cl_env, prog, tex, uv):
    """(colour, float, gradient) of texture `tex` at uvs (n, 2)."""
    arrays = MaterialPacker([Bsdf("diffuse", reflectance=tex)]).arrays()
    uv = np.ascontiguousarray(uv, np.float32)
    return run_kernel(cl_env, prog, "texture_lookups", len(uv), [(f32, (3,)), (f32, ()), (f32, (2,))], np.int32(0),
                      inputs=[arrays["textures"], arrays["texels"], uv])


# ---- numpy reference ----------------------------------------------------------------------------

def wrap_ref(i, n, mode):
    if mode == "clamp":
        return np.clip(i, 0, n - 1)
    if mode == "repeat":
        return np.mod(i, n)
    m = np.mod(i, 2 * n)          # mirror: 0 .. n-1, n-1 .. 0, repeated
    return np.where(m < n, m, 2 * n - 1 - m)


def bitmap_ref(data, uv, filter="bilinear", wrap="repeat", to_uv=np.eye(3)):
    h, w, _ = data.shape
    p = uv @ to_uv[:2, :2].T + to_uv[:2, 2]
    x, y = p[:, 0] * w, p[:, 1] * h
    if filter == "nearest":
        return data[wrap_ref(np.floor(y).astype(int), h, wrap), wrap_ref(np.floor(x).astype(int), w, wrap)]
    x, y = x - 0.5, y - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]

    def at(xx, yy):
        return data[wrap_ref(yy, h, wrap), wrap_ref(xx, w, wrap)]
    return ((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0))
            + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1)))


def as_float(rgb_values, channels):
    return rgb_values[:, 0] if channels == 1 else rgb_values @ LUM


def test_uv_conventions(cl_env, prog):
    """Explicitly: u along the width, v down the rows from the file's first row; a texel's centre
    reads its value exactly; nearest takes floor(uv * size)."""
    data = np.arange(12, dtype=np.float32).reshape(3, 4, 1)
    tex = Texture("bitmap", data=data, filter="bilinear")
    centres = np.array([[(x + 0.5) / 4, (y + 0.5) / 3] for y in range(3) for x in range(4)])
    colour, value, _ = lookups(cl_env, prog, tex, centres)
    np.testing.assert_array_equal(value, np.arange(12, dtype=np.float32))
    np.testing.assert_array_equal(colour, np.repeat(np.arange(12, dtype=np.float32)[:, None], 3, 1))
    tex.filter = "nearest"
    _, value, _ = lookups(cl_env, prog, tex, np.array([[0.0, 0.0], [0.2499, 0.0], [0.25, 0.0], [0.0, 1 / 3 + 1e-6]]))
    np.testing.assert_array_equal(value, [0, 0, 1, 4])


@pytest.mark.parametrize("filter", ["bilinear", "nearest"])
@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
@pytest.mark.parametrize("channels", [1, 3])
def test_bitmap_lookups_match_reference(cl_env, prog, filter, wrap, channels):
    rng = np.random.default_rng(11)
    data = rng.random((5, 7, channels)).astype(np.float32)
    to_uv = np.array([[1.7, 0.4, -0.3], [-0.2, 2.3, 0.15], [0, 0, 1]])
    tex = Texture("bitmap", data=data, filter=filter, wrap=wrap, to_uv=to_uv)
    uv = rng.uniform(-2.5, 3.5, (20000, 2))
    colour, value, _ = lookups(cl_env, prog, tex, uv)
    want = bitmap_ref(data.astype(np.float64), uv, filter, wrap, to_uv)
    if channels == 1:
        want = np.repeat(want, 3, 1)
    # float32 texel coordinates: floor() may round the other way within a few ulps of an edge
    p = uv @ to_uv[:2, :2].T + to_uv[:2, 2]
    shift = 0.0 if filter == "nearest" else 0.5
    frac = np.abs((p * [7, 5] - shift) - np.round(p * [7, 5] - shift))
    clear = (frac > 1e-5).all(1)
    np.testing.assert_allclose(colour[clear], want[clear], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(value[clear], as_float(want[clear], 3) if channels == 3 else want[clear, 0],
                               rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("wrap", ["repeat", "mirror"])
def test_byte_coded_texels_read_the_same_bits(cl_env, prog, channels, wrap, monkeypatch):
    """A bitmap of at most 256 distinct values (an 8-bit image, sRGB-decoded: values that are not
    multiples of anything) is stored as bytes into a table of its values: every lookup, colour,
    float and bump gradient, gives the float32 storage's bits; one value more keeps floats."""
    import volcl.pack_materials as pm
    from volcl.scene.images import srgb_decode
    rng = np.random.default_rng(14 + channels)
    data = srgb_decode(rng.integers(0, 256, (37, 29, channels)) / 255.0).astype(np.float32)
    tex = Texture("bitmap", data=data, wrap=wrap, to_uv=np.array([[1.3, 0.2, 0.1], [-0.1, 1.7, 0], [0, 0, 1]]))
    arrays = MaterialPacker([Bsdf("diffuse", reflectance=tex)]).arrays()
    r = arrays["textures"][0]
    assert r["lut"] >= 0 and arrays["texels"].nbytes < data.nbytes / 2
    uv = rng.uniform(-1.5, 2.5, (20000, 2))
    coded = lookups(cl_env, prog, tex, uv)
    monkeypatch.setattr(pm, "BYTE_CODED_MIN_SIZE", 10 ** 9)   # the same texture as floats
    assert MaterialPacker([Bsdf("diffuse", reflectance=tex)]).arrays()["textures"][0]["lut"] == -1
    plain = lookups(cl_env, prog, tex, uv)
    for a, b in zip(coded, plain):
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32))


def test_byte_coding_only_where_it_is_exact():
    from volcl.pack_materials import byte_coded
    rng = np.random.default_rng(15)
    values = rng.random(256).astype(np.float32)
    data = values[rng.integers(0, 256, (40, 40, 3))]
    lut, words = byte_coded(data)
    codes = words.view(np.uint8)[:data.size]
    assert np.array_equal(lut[codes].view(np.uint32), data.reshape(-1).view(np.uint32))
    data[0, 0, 0] = np.float32(2.0)                   # a 257th value
    assert byte_coded(data) is None
    assert byte_coded(values[:3][rng.integers(0, 3, (8, 8, 1))]) is None    # too small to pay


def test_checkerboard_nested_and_swapped(cl_env, prog):
    """color0 where the fractional parts of u and v lie on the same side of 1/2 (colour reads),
    color1 there for float reads (Mitsuba's eval_1); a nested bitmap is read at the same uv."""
    rng = np.random.default_rng(12)
    data = rng.random((4, 4, 3)).astype(np.float32)
    inner = Texture("bitmap", data=data, filter="nearest")
    tex = Texture("checkerboard", color0=rgb([0.9, 0.1, 0.2]), color1=inner,
                  to_uv=np.array([[3.0, 0, 0], [0, 2.0, 0], [0, 0, 1]]))
    uv = rng.uniform(-1, 2, (5000, 2))
    colour, value, _ = lookups(cl_env, prog, tex, uv)
    p = uv * [3, 2]
    same = (p[:, 0] - np.floor(p[:, 0]) > 0.5) == (p[:, 1] - np.floor(p[:, 1]) > 0.5)
    leaf = bitmap_ref(data.astype(np.float64), uv, "nearest")
    want = np.where(same[:, None], [0.9, 0.1, 0.2], leaf)
    want_float = np.where(same, leaf @ LUM, np.mean([0.9, 0.1, 0.2]))
    np.testing.assert_allclose(colour, want, rtol=1e-6)
    np.testing.assert_allclose(value, want_float, rtol=1e-5)


def test_bump_gradient_is_mitsubas(cl_env, prog):
    """eval_1_grad: the bilinear interpolant's derivatives in texels, through to_uv's transpose,
    times the resolution; for a to_uv without rotation, the true gradient (finite differences)."""
    rng = np.random.default_rng(13)
    data = rng.random((6, 9, 1)).astype(np.float32)
    for to_uv in (np.array([[2.0, 0, 0.1], [0, 1.5, 0], [0, 0, 1]]), np.array([[1.2, 0.7, 0], [-0.4, 0.9, 0.3], [0, 0, 1]])):
        tex = Texture("bitmap", data=data, to_uv=to_uv)
        uv = rng.uniform(0, 1, (2000, 2))
        _, _, grad = lookups(cl_env, prog, tex, uv)
        h, w = 6, 9
        p = uv @ to_uv[:2, :2].T + to_uv[:2, 2]
        x, y = p[:, 0] * w - 0.5, p[:, 1] * h - 0.5
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0

        def at(xx, yy):
            return data[np.mod(yy, h), np.mod(xx, w), 0].astype(np.float64)
        dx = (1 - fy) * (at(x0 + 1, y0) - at(x0, y0)) + fy * (at(x0 + 1, y0 + 1) - at(x0, y0 + 1))
        dy = (1 - fx) * (at(x0, y0 + 1) - at(x0, y0)) + fx * (at(x0 + 1, y0 + 1) - at(x0 + 1, y0))
        m = to_uv[:2, :2]
        want = np.stack([m[0, 0] * dx + m[1, 0] * dy, m[0, 1] * dx + m[1, 1] * dy], 1) * [w, h]
        np.testing.assert_allclose(grad, want, rtol=1e-4, atol=1e-4)
        if to_uv[0, 1] == 0:
            eps = 1e-6
            fd = np.stack([(bitmap_ref(data.astype(np.float64), uv + [eps, 0], to_uv=to_uv)
                            - bitmap_ref(data.astype(np.float64), uv - [eps, 0], to_uv=to_uv))[:, 0],
                           (bitmap_ref(data.astype(np.float64), uv + [0, eps], to_uv=to_uv)
                            - bitmap_ref(data.astype(np.float64), uv - [0, eps], to_uv=to_uv))[:, 0]], 1) / (2 * eps)
            smooth = np.ones(len(uv), bool)   # away from texel-centre lines, where the interpolant kinks
            frac = np.stack([x - np.round(x), y - np.round(y)], 1)
            smooth &= (np.abs(frac) > 1e-3).all(1)
            np.testing.assert_allclose(grad[smooth], fd[smooth], rtol=1e-3, atol=1e-3)


def test_packed_texels_offsets():
    """Two bitmaps and a checkerboard share one texel buffer; each descriptor finds its own."""
    a = Texture("bitmap", data=np.ones((2, 3, 1), np.float32))
    b = Texture("bitmap", data=np.full((4, 2, 3), 2.0, np.float32))
    c = Texture("checkerboard", color0=a, color1=rgb(0.3))
    arrays = MaterialPacker([Bsdf("diffuse", reflectance=c), Bsdf("roughconductor", specular_reflectance=b)]).arrays()
    t, texels = arrays["textures"], arrays["texels"]
    assert len(t) == 3 and len(texels) == 6 + 24
    by_size = {(int(r["width"]), int(r["height"])): r for r in t if r["type"] == 0}
    assert texels[by_size[(3, 2)]["data"]:][:6].tolist() == [1.0] * 6
    assert texels[by_size[(2, 4)]["data"]:][:24].tolist() == [2.0] * 24
    checker = t[t["type"] == 1][0]
    assert checker["child1"] == -1 and np.isclose(checker["mean1"], 0.3)
    assert t[checker["child0"]]["width"] == 3


# ---- texture coordinates of shapes ------------------------------------------------------------

TEXTURED = '<bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/></bsdf>'


def surface_uvs(cl_env, prog, scene, o, d):
    p = pack.pack(scene)
    a = p.arrays
    o = np.ascontiguousarray(np.broadcast_to(o, d.shape), np.float32)
    d = np.ascontiguousarray(d, np.float32)
    return run_kernel(cl_env, prog, "surface_uvs", len(d), [(f32, (2,)), (f32, (3,)), (f32, (3,)), (np.int32, ())],
                      inputs=[a[k] for k in ("nodes", "leaves", "triangles", "normals", "spheres", "cylinders",
                                             "shapes", "tri_uvs", "uv_maps")] + [o, d])


def rays_towards(rng, n, origin, spread, target=(0, 0, 0)):
    t = np.asarray(target) + rng.uniform(-spread, spread, (n, 3))
    d = t - np.asarray(origin, float)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def scene_of(shape_xml, tmp_path=None):
    return load_string(f'<scene version="3.0.0">{shape_xml}</scene>', base_dir=tmp_path)


def hit_points(o, d, t_fn):
    return o + t_fn(o, d)[:, None] * d


def check_uv(cl_env, prog, scene, o, d, expected_fn, what):
    uv, dpdu, dpdv, hit = surface_uvs(cl_env, prog, scene, o, d)
    ok = hit >= 0
    assert ok.mean() > 0.3, f"{what}: too few hits"
    want_uv, want_du, want_dv = expected_fn(d[ok])
    np.testing.assert_allclose(uv[ok], want_uv, atol=2e-5, err_msg=f"{what}: uv")
    scale = np.abs(want_du).max() + np.abs(want_dv).max()
    np.testing.assert_allclose(dpdu[ok], want_du, atol=1e-4 * scale, err_msg=f"{what}: dp/du")
    np.testing.assert_allclose(dpdv[ok], want_dv, atol=1e-4 * scale, err_msg=f"{what}: dp/dv")


def _rot(axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) * c + s * k + (1 - c) * np.outer(a, a)


def test_sphere_uvs(cl_env, prog):
    """u = phi / 2 pi, v = theta / pi in the unit sphere's frame (rotation included)."""
    rng = np.random.default_rng(21)
    xml = ('<shape type="sphere"><point name="center" value="0.2, -0.1, 0.3"/><float name="radius" value="0.7"/>'
           '<transform name="to_world"><rotate x="1" angle="30"/><rotate y="1" angle="-50"/><translate z="0.1"/>'
           f'</transform>{TEXTURED}</shape>')
    sc = scene_of(xml)
    shape = sc.shapes[0]
    M = shape.to_world @ np.diag([1, 1, 1, 1.0])
    center_local, radius = shape.local
    frame = shape.to_world @ np.block([[np.eye(3) * radius, np.asarray(center_local)[:, None]], [np.zeros((1, 3)), 1]])
    inv = np.linalg.inv(frame)
    o = np.array([0.3, 0.5, 4.0])
    d = rays_towards(rng, 4000, o, 0.6, target=shape.center)

    def expected(dd):
        oc = o - shape.center
        b = dd @ oc
        t = -b - np.sqrt(b * b - (oc @ oc - shape.radius ** 2))
        p = o + t[:, None] * dd
        lp = p @ inv[:3, :3].T + inv[:3, 3]
        lp /= np.linalg.norm(lp, axis=1, keepdims=True)
        phi = np.mod(np.arctan2(lp[:, 1], lp[:, 0]), 2 * np.pi)
        theta = np.arccos(np.clip(lp[:, 2], -1, 1))
        rd = np.hypot(lp[:, 0], lp[:, 1])
        du = np.stack([-lp[:, 1], lp[:, 0], 0 * rd], 1) @ frame[:3, :3].T * 2 * np.pi
        dv = np.stack([lp[:, 2] * lp[:, 0] / rd, lp[:, 2] * lp[:, 1] / rd, -rd], 1) @ frame[:3, :3].T * np.pi
        return np.stack([phi / (2 * np.pi), theta / np.pi], 1), du, dv
    # the seam at phi = 0 (u jumps from 1 to 0): keep rays off it
    uv, _, _, hit = surface_uvs(cl_env, prog, sc, o, d)
    keep = (hit < 0) | ((uv[:, 0] > 1e-3) & (uv[:, 0] < 1 - 1e-3))
    check_uv(cl_env, prog, sc, o, d[keep], expected, "sphere")
    del M


def test_rectangle_disk_cube_and_cylinder_uvs(cl_env, prog):
    rng = np.random.default_rng(22)
    rot = '<rotate x="1" angle="20"/><rotate z="1" angle="35"/>'
    o = np.array([0.0, 0.0, 5.0])
    # rectangle: ((x + 1) / 2, (y + 1) / 2), dp/du = M (2, 0, 0)
    sc = scene_of(f'<shape type="rectangle"><transform name="to_world"><scale x="1.5" y="0.8"/>{rot}</transform>{TEXTURED}</shape>')
    M = sc.shapes[0].to_world
    inv = np.linalg.inv(M)

    def plane_point(dd):
        n = M[:3, 2]
        t = ((M[:3, 3] - o) @ n) / (dd @ n)
        return o + t[:, None] * dd

    def rect(dd):
        lp = plane_point(dd) @ inv[:3, :3].T + inv[:3, 3]
        return (lp[:, :2] + 1) / 2, np.broadcast_to(M[:3, 0] * 2, (len(dd), 3)), np.broadcast_to(M[:3, 1] * 2, (len(dd), 3))
    check_uv(cl_env, prog, sc, o, rays_towards(rng, 3000, o, 1.2), rect, "rectangle")

    # disk: (r, phi / 2 pi), dp/du = M (cos, sin, 0), dp/dv = M (-sin, cos, 0) 2 pi r
    sc = scene_of(f'<shape type="disk"><transform name="to_world"><scale x="1.2" y="0.9"/>{rot}</transform>{TEXTURED}</shape>')
    M = sc.shapes[0].to_world
    inv = np.linalg.inv(M)

    def disk(dd):
        lp = plane_point(dd) @ inv[:3, :3].T + inv[:3, 3]
        r = np.hypot(lp[:, 0], lp[:, 1])
        c, s = lp[:, 0] / r, lp[:, 1] / r
        phi = np.mod(np.arctan2(lp[:, 1], lp[:, 0]), 2 * np.pi)
        du = np.stack([c, s, 0 * r], 1) @ M[:3, :3].T
        dv = np.stack([-s, c, 0 * r], 1) @ M[:3, :3].T * (2 * np.pi * r)[:, None]
        return np.stack([r, phi / (2 * np.pi)], 1), du, dv
    d = rays_towards(rng, 4000, o, 0.9)
    uv, _, _, hit = surface_uvs(cl_env, prog, sc, o, d)
    keep = (hit < 0) | ((uv[:, 1] > 1e-3) & (uv[:, 1] < 1 - 1e-3))
    check_uv(cl_env, prog, sc, o, d[keep], disk, "disk")

    # cylinder: (phi / 2 pi, z), dp/du = M 2 pi (-y, x, 0), dp/dv = M (0, 0, 1)
    sc = scene_of('<shape type="cylinder"><point name="p0" value="-0.3, -1, 0.1"/><point name="p1" value="0.2, 1, -0.2"/>'
                  f'<float name="radius" value="0.5"/>{TEXTURED}</shape>')
    C = sc.shapes[0].cylinder
    inv = np.linalg.inv(C)

    def cyl(dd):
        lo, ld = inv[:3, :3] @ o + inv[:3, 3], dd @ inv[:3, :3].T
        a = ld[:, 0] ** 2 + ld[:, 1] ** 2
        b = lo[0] * ld[:, 0] + lo[1] * ld[:, 1]
        cc = lo[0] ** 2 + lo[1] ** 2 - 1
        t = (-b - np.sqrt(b * b - a * cc)) / a
        lp = lo + t[:, None] * ld
        phi = np.mod(np.arctan2(lp[:, 1], lp[:, 0]), 2 * np.pi)
        du = np.stack([-lp[:, 1], lp[:, 0], 0 * t], 1) @ C[:3, :3].T * 2 * np.pi
        return np.stack([phi / (2 * np.pi), lp[:, 2]], 1), du, np.broadcast_to(C[:3, 2], (len(dd), 3))
    d = rays_towards(rng, 4000, o, 0.4)
    uv, _, _, hit = surface_uvs(cl_env, prog, sc, o, d)
    keep = (hit < 0) | ((uv[:, 0] > 1e-3) & (uv[:, 0] < 1 - 1e-3))
    check_uv(cl_env, prog, sc, o, d[keep], cyl, "cylinder")

    # cube: Mitsuba's per-face uvs; the front face (+z) maps x -> 1 - ... as its corner table says
    sc = scene_of(f'<shape type="cube">{TEXTURED}</shape>')
    front = np.array([[1, -1, 1, 0, 1], [1, 1, 1, 1, 1], [-1, 1, 1, 1, 0], [-1, -1, 1, 0, 0]], float)

    def cube(dd):
        t = (1 - o[2]) / dd[:, 2]
        p = o + t[:, None] * dd
        # uv is affine on the face: u = (y + 1) / 2, v = (x + 1) / 2 from the corner table above
        for x, y, _, u, v in front:
            assert np.isclose((y + 1) / 2, u) and np.isclose((x + 1) / 2, v)
        return (np.stack([(p[:, 1] + 1) / 2, (p[:, 0] + 1) / 2], 1), np.broadcast_to([0.0, 2.0, 0.0], (len(dd), 3)),
                np.broadcast_to([2.0, 0.0, 0.0], (len(dd), 3)))
    check_uv(cl_env, prog, sc, o, rays_towards(rng, 3000, o, 0.8), cube, "cube front face")


@pytest.mark.parametrize("flip_normals", [False, True])
def test_mesh_uvs_obj_flip_and_barycentric(cl_env, prog, tmp_path, flip_normals):
    """OBJ texture coordinates get v -> 1 - v (flip_tex_coords, default true); PLY's are kept; a
    mesh without any reads (b1, b2) of its file's triangle, whatever flip_normals does."""
    (tmp_path / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                                       "vt 0 0\nvt 0.5 0\nvt 0.5 0.25\nvt 0 0.25\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    (tmp_path / "tri.obj").write_text("v -1 -1 0\nv 1 -1 0\nv -1 1 0\nf 1 2 3\n")
    o = np.array([0.0, 0.0, 3.0])
    rng = np.random.default_rng(23)
    flip = f'<boolean name="flip_normals" value="{str(flip_normals).lower()}"/>'
    for flip_tex, vflip in (("", True), ('<boolean name="flip_tex_coords" value="false"/>', False)):
        sc = scene_of(f'<shape type="obj"><string name="filename" value="quad.obj"/>{flip}{flip_tex}{TEXTURED}</shape>',
                      tmp_path)

        def quad(dd):
            p = o + ((0 - o[2]) / dd[:, 2])[:, None] * dd
            u, v = (p[:, 0] + 1) / 4, (p[:, 1] + 1) / 8
            v = 1 - v if vflip else v
            return (np.stack([u, v], 1), np.broadcast_to([4.0, 0, 0], (len(dd), 3)),
                    np.broadcast_to([0, -8.0 if vflip else 8.0, 0], (len(dd), 3)))
        check_uv(cl_env, prog, sc, o, rays_towards(rng, 2000, o, 0.9), quad, f"obj quad (v flipped: {vflip})")
    sc = scene_of(f'<shape type="obj"><string name="filename" value="tri.obj"/>{flip}{TEXTURED}</shape>', tmp_path)

    def tri(dd):
        p = o + ((0 - o[2]) / dd[:, 2])[:, None] * dd
        b1, b2 = (p[:, 0] + 1) / 2, (p[:, 1] + 1) / 2
        return (np.stack([b1, b2], 1), np.broadcast_to([2.0, 0, 0], (len(dd), 3)),
                np.broadcast_to([0, 2.0, 0], (len(dd), 3)))
    check_uv(cl_env, prog, sc, o, rays_towards(rng, 2000, o, 0.6, target=(-0.4, -0.4, 0)), tri, "barycentric")


# ---- reading images -------------------------------------------------------------------------------

def write(path, pixels, fmt):
    import OpenImageIO as oiio
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.attribute("oiio:UnassociatedAlpha", 1)     # store the colours as given
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()


def bitmap_scene(tmp_path, name, extra=""):
    return scene_of(f'<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
                    f'<string name="filename" value="{name}"/>{extra}</texture></bsdf></shape>', tmp_path)


def test_bitmap_reading(tmp_path):
    """8-bit images are sRGB-decoded unless raw; alpha is dropped; grey with alpha keeps one
    channel; a 1 x 3 image is padded to 2 x 3 by repeating its row (Mitsuba's pad_to)."""
    rgba = np.array([[[0, 128, 255, 7], [64, 32, 16, 200]]], np.uint8)         # 1 x 2 RGBA
    write(tmp_path / "rgba.png", rgba, "uint8")
    tex = bitmap_scene(tmp_path, "rgba.png").shapes[0].bsdf.reflectance
    assert tex.data.shape == (2, 2, 3)
    x = rgba[..., :3] / 255.0
    srgb = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(tex.data[0], srgb[0], rtol=1e-6)
    np.testing.assert_array_equal(tex.data[1], tex.data[0])
    raw = bitmap_scene(tmp_path, "rgba.png", '<boolean name="raw" value="true"/>').shapes[0].bsdf.reflectance
    np.testing.assert_allclose(raw.data[0], x[0], rtol=1e-6)
    ya = np.array([[[10, 99]], [[250, 1]], [[128, 0]]], np.uint8)                # 3 x 1 grey + alpha
    write(tmp_path / "ya.png", ya, "uint8")
    tex = bitmap_scene(tmp_path, "ya.png").shapes[0].bsdf.reflectance
    assert tex.data.shape == (3, 2, 1)
    np.testing.assert_array_equal(tex.data[:, 1], tex.data[:, 0])
