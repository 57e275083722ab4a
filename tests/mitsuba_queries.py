"""Asks Mitsuba 3 what its emitters return, for tests/test_envmap.py, in the interpreter that has
Mitsuba (it needs neither volcl nor numpy).

    python mitsuba_queries.py QUERIES.json OUT.json

QUERIES.json: {"variant": ..., "envmap": {"filename", "scale", "to_world" (4x4 rows), "dirs"
(world directions pointing away from the scene)}, "spot": {"intensity", "cutoff_angle",
"beam_width", "to_world", "points" (receiving points)}}. OUT.json: the envmap's eval() and
pdf_direction() along each direction, and the spot's sample_direction() value at each point
(intensity x falloff / distance^2).
"""
import json
import sys


def main(queries_path, out_path):
    import drjit as dr
    import mitsuba as mi
    q = json.load(open(queries_path))
    mi.set_variant(q["variant"])
    out = {}

    def vectors(rows):
        return mi.Vector3f([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows])

    def columns(v):
        return [list(map(float, v.x)), list(map(float, v.y)), list(map(float, v.z))]

    env = q.get("envmap")
    if env:
        emitter = mi.load_dict({"type": "envmap", "filename": env["filename"], "scale": env["scale"],
                                "to_world": mi.ScalarTransform4f(mi.ScalarMatrix4f(env["to_world"]))})
        d = vectors(env["dirs"])
        n = len(env["dirs"])
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = -d
        value = emitter.eval(si)
        ds = dr.zeros(mi.DirectionSample3f, n)
        ds.d = d
        pdf = emitter.pdf_direction(dr.zeros(mi.Interaction3f, n), ds)
        out["envmap"] = {"value": columns(value), "pdf": list(map(float, pdf))}
    spot = q.get("spot")
    if spot:
        emitter = mi.load_dict({"type": "spot", "intensity": {"type": "rgb", "value": spot["intensity"]},
                                "cutoff_angle": spot["cutoff_angle"], "beam_width": spot["beam_width"],
                                "to_world": mi.ScalarTransform4f(mi.ScalarMatrix4f(spot["to_world"]))})
        n = len(spot["points"])
        it = dr.zeros(mi.Interaction3f, n)
        it.p = mi.Point3f(vectors(spot["points"]))
        _, value = emitter.sample_direction(it, mi.Point2f(0.5, 0.5))
        out["spot"] = {"value": columns(value)}
    json.dump(out, open(out_path, "w"))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
