"""Instanced scenes (Mitsuba's shapegroup + instance) on the device: the two-level BVH's closest,
any-hit and shadow queries against a brute-force float64 intersection of the flattened geometry on
random rays (meshes, spheres and cylinders under rotations, non-uniform scales and shears), and the
world-space point and normal of each hit."""
import numpy as np
import pytest
import trimesh

from conftest import run_kernel
from test_traversal import moller_trumbore
from volcl.pack import Packer
from volcl.scene import load_string

pytestmark = pytest.mark.every_implementation

NO_HIT = 0x7fffffff


def matrix_xml(m):
    return "<transform name=\"to_world\"><matrix value=\"" + " ".join(f"{v:.9g}" for v in m.ravel()) + "\"/></transform>"


def random_affine(rng):
    """A rotation times a non-uniform scale times a shear, then a translation."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    scale = np.diag(rng.uniform(0.4, 1.6, 3))
    shear = np.eye(3)
    shear[0, 1], shear[1, 2] = rng.uniform(-0.5, 0.5, 2)
    m = np.eye(4)
    m[:3, :3] = q @ scale @ shear
    m[:3, 3] = rng.uniform(-2.5, 2.5, 3)
    return m


def instanced_scene(tmp_path, rng, n_inst=12):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.45)
    mesh.vertices += rng.normal(0, 0.02, mesh.vertices.shape)
    mesh.export(tmp_path / "blob.ply")
    instances = [random_affine(rng) for _ in range(n_inst)]
    instances[0][:3, 0] *= -1       # a mirror: normals stay the inverse transpose's (Mitsuba's rule)
    inst_xml = "\n".join(f"<shape type=\"instance\"><ref id=\"g\"/>{matrix_xml(m)}</shape>" for m in instances)
    xml = f"""<scene version="3.0.0">
      <shape type="shapegroup" id="g">
        <shape type="ply"><string name="filename" value="blob.ply"/>
          <transform name="to_world"><translate x="-0.6"/></transform><bsdf type="diffuse"/></shape>
        <shape type="sphere"><point name="center" x="0.5" y="0.2" z="0"/><float name="radius" value="0.3"/>
          <bsdf type="null"/></shape>
        <shape type="cylinder"><point name="p0" x="0" y="-0.5" z="0.4"/><point name="p1" x="0" y="0.5" z="0.4"/>
          <float name="radius" value="0.15"/><bsdf type="diffuse"/></shape>
      </shape>
      {inst_xml}
      <shape type="sphere"><point name="center" x="0" y="0" z="0"/><float name="radius" value="0.4"/>
        <bsdf type="diffuse"/></shape>
    </scene>"""
    return load_string(xml, base_dir=tmp_path), instances


def _sphere_t(o, d, c, r):
    """Both roots of |o + t d - c| = r for rays (o, d) with unnormalized d; inf where missed."""
    f = o - c
    a = np.einsum("rk,rk->r", d, d)
    b = np.einsum("rk,rk->r", f, d)
    cc = np.einsum("rk,rk->r", f, f) - r * r
    disc = b * b - a * cc
    sq = np.sqrt(np.maximum(disc, 0))
    t0, t1 = (-b - sq) / a, (-b + sq) / a
    return np.where(disc >= 0, t0, np.inf), np.where(disc >= 0, t1, np.inf), disc / (a * a)


def _triangles_t(o, d, tris):
    t, det, margin = moller_trumbore(o, d, tris)
    ok = (np.abs(det) > 1e-14) & (margin >= 0) & (t > 1e-7)
    return np.where(ok, t, np.inf), np.abs(margin)


@np.errstate(invalid="ignore", divide="ignore")
def flattened_hits(scene, instances, o, d):
    """Per ray: (t, shape index, instance (-1: the scene's own), world normal, ambiguous) of the
    nearest hit over every placed primitive, intersected in its own space in float64."""
    shapes = scene.shapes
    cands = []      # (t (rays,), shape, instance, normal function, ambiguous (rays,))
    placements = [(-1, np.eye(4))] + list(enumerate(instances))
    for k, m in placements:
        inv = np.linalg.inv(m)
        lo, ld = o @ inv[:3, :3].T + inv[:3, 3], d @ inv[:3, :3].T
        for si, s in enumerate(shapes):
            if (s.group is None) != (k < 0):
                continue
            if s.kind == "mesh":
                t, margin = _triangles_t(lo, ld, s.vertices[s.faces])
                j = t.argmin(1)
                tt = t[np.arange(len(o)), j]
                amb = (margin < 1e-4).any(1)
                tri = s.vertices[s.faces][j]
                n_obj = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            elif s.kind == "sphere":
                t0, t1, disc = _sphere_t(lo, ld, s.center, s.radius)
                tt = np.where(t0 > 1e-6, t0, np.where(t1 > 1e-6, t1, np.inf))
                amb = np.abs(disc) < 1e-4 * s.radius ** 2
                n_obj = lo + tt[:, None] * ld - s.center
            else:   # cylinder: the unit tube of frame s.cylinder
                ci = np.linalg.inv(s.cylinder)
                co, cd = lo @ ci[:3, :3].T + ci[:3, 3], ld @ ci[:3, :3].T
                a = cd[:, 0] ** 2 + cd[:, 1] ** 2
                b = co[:, 0] * cd[:, 0] + co[:, 1] * cd[:, 1]
                c = co[:, 0] ** 2 + co[:, 1] ** 2 - 1
                disc = b * b - a * c
                sq = np.sqrt(np.maximum(disc, 0))
                tt = np.full(len(o), np.inf)
                for root in ((-b + sq) / a, (-b - sq) / a):     # the nearer root wins, written last
                    z = co[:, 2] + root * cd[:, 2]
                    good = (disc >= 0) & (root > 1e-6) & (z >= 0) & (z <= 1)
                    tt = np.where(good, root, tt)
                amb = (np.abs(disc) < 1e-4 * a * a)
                for root in ((-b + sq) / a, (-b - sq) / a):
                    z = co[:, 2] + root * cd[:, 2]
                    amb |= (disc >= 0) & (np.abs(z - 0.5) > 0.5 - 1e-4) & (np.abs(z - 0.5) < 0.5 + 1e-4)
                lp = co + tt[:, None] * cd
                n_obj = np.column_stack([lp[:, 0], lp[:, 1], 0 * lp[:, 2]]) @ ci[:3, :3]
            n_world = n_obj @ inv[:3, :3]        # the inverse transpose
            n_world /= np.linalg.norm(n_world, axis=1, keepdims=True) + 1e-300
            cands.append((tt, si, k, n_world, amb))
    t_all = np.column_stack([c[0] for c in cands])
    order = np.argsort(t_all, axis=1)
    rows = np.arange(len(o))
    best, second = order[:, 0], order[:, 1]
    t_best, t_second = t_all[rows, best], t_all[rows, second]
    amb_all = np.column_stack([c[4] for c in cands])
    close = np.abs(t_second - t_best) < 1e-3 * np.maximum(t_best, 1e-3)
    ambiguous = amb_all.any(1) | close
    shape = np.array([c[1] for c in cands])[best]
    inst = np.array([c[2] for c in cands])[best]
    normals = np.stack([c[3] for c in cands], 1)[rows, best]
    return t_best, shape, inst, normals, ambiguous, t_all, cands


OUTPUTS = [(np.float32, ()), (np.int32, ()), (np.int32, ()), (np.float32, (3,)), (np.float32, (3,)),
           (np.int32, ()), (np.int32, ()), (np.int32, ())]


def trace(cl_env, test_program, arrays, o, d):
    prog = test_program("instance_tests.cl")
    inputs = [arrays[k] for k in ("nodes", "leaves", "triangles", "normals", "spheres", "cylinders", "instances")]
    return run_kernel(cl_env, prog, "trace_instanced", len(o), OUTPUTS,
                      inputs=inputs + [o.astype(np.float32), d.astype(np.float32)])


def prim_shape(arrays, prim):
    """The shape index of device primitive codes (as Hit.prim)."""
    from volcl import layout
    out = np.full(len(prim), -1)
    tri = (prim >= 0) & (prim != NO_HIT)
    out[tri] = arrays["triangles"]["shape"][prim[tri]]
    ana = prim < 0
    a = -prim[ana] - 1
    cyl = a >= layout.CYLINDER_CODE_BASE
    vals = np.where(cyl, arrays["cylinders"]["shape"][np.where(cyl, a - layout.CYLINDER_CODE_BASE, 0)],
                    arrays["spheres"]["shape"][np.where(cyl, 0, a)])
    out[ana] = vals
    return out


@pytest.mark.parametrize("seed", [1, 2])
def test_instanced_traversal_matches_flattened_brute_force(cl_env, test_program, tmp_path, seed):
    rng = np.random.default_rng(seed)
    scene, instances = instanced_scene(tmp_path, rng)
    assert len(scene.instances) == len(instances)
    arrays = Packer(scene).pack().arrays
    n = 3000
    o = rng.uniform(-4, 4, (n, 3))
    target = rng.uniform(-2.5, 2.5, (n, 3))
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o32, d32 = o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64)
    t_dev, prim, inst, p_dev, n_dev, occ, sh_prim, sh_inst = trace(cl_env, test_program, arrays, o32, d32)
    t_ref, shape_ref, inst_ref, n_ref, amb, t_all, cands = flattened_hits(scene, instances, o32, d32)
    hit_ref, hit_dev = np.isfinite(t_ref), np.isfinite(t_dev)
    assert hit_ref.sum() > n // 3, "the test scene should be hit by many rays"
    disagree = (hit_ref != hit_dev) & ~amb
    assert not disagree.any(), f"{disagree.sum()} rays disagree on hit/miss, e.g. {np.flatnonzero(disagree)[:5]}"
    both = hit_ref & hit_dev & ~amb
    assert both.sum() > 0.9 * hit_ref.sum(), "few rays should be too close to call"
    rel = np.abs(t_dev[both] - t_ref[both]) / np.maximum(t_ref[both], 1e-3)
    assert rel.max() < 1e-4, f"worst relative distance error {rel.max():.3g}"
    # the same primitive's shape and the same instance
    shape_dev = prim_shape(arrays, prim)
    assert np.array_equal(shape_dev[both], shape_ref[both])
    assert np.array_equal(inst[both], inst_ref[both])
    assert (inst[both] >= 0).sum() > n // 4 and (inst[both] == -1).sum() > 10, "both kinds of hits should occur"
    # world-space hit data: the point on the ray at t, the normal by the inverse transpose
    p_ref = o32 + t_ref[:, None] * d32
    assert np.abs(p_dev[both] - p_ref[both]).max() < 1e-3
    cos = np.einsum("rk,rk->r", n_dev[both], n_ref[both])
    assert cos.min() > 1 - 1e-4, f"worst normal cosine {cos.min()}"
    # any-hit agrees with closest-hit; the shadow query stops at an opaque hit or returns the nearest
    assert np.array_equal(occ.astype(bool), hit_dev)
    got = sh_prim != NO_HIT
    assert np.array_equal(got, hit_dev)
    opaque_shape = np.array([s.bsdf.kind != "null" for s in scene.shapes])
    sh_shape = prim_shape(arrays, sh_prim)
    nearest_opaque = both & opaque_shape[np.maximum(shape_ref, 0)]
    assert opaque_shape[sh_shape[nearest_opaque]].all()
    unblocked = got & ~opaque_shape[np.maximum(sh_shape, 0)]
    assert np.array_equal(sh_prim[unblocked], prim[unblocked]) and np.array_equal(sh_inst[unblocked], inst[unblocked])
    assert unblocked.sum() > 10, "the null spheres should be the nearest hit of some rays"
