"""Renders scenes with Mitsuba 3 for tests/test_mitsuba_agreement.py, in the interpreter that has
Mitsuba (it needs neither volcl nor numpy).

    python mitsuba_runner.py JOBS.json

JOBS.json is a list of {"scene", "out", "spp", "seeds", "variant", "defines"}. Each scene is loaded
once and rendered with every seed; the script writes OUT_mean.exr (the mean of the renders) and
OUT_var.exr (the estimated variance of that mean, from the spread of the renders), and prints
`done NAME` per job or `failed NAME: message`.
"""
import json
import sys


def main(path):
    import drjit as dr
    import mitsuba as mi
    jobs = json.load(open(path))
    for job in jobs:
        try:
            mi.set_variant(job["variant"])
            scene = mi.load_file(job["scene"], **job.get("defines", {}))
            total = total_sq = None
            seeds = job["seeds"]
            for seed in seeds:
                img = mi.render(scene, spp=job["spp"], seed=seed)
                img = mi.TensorXf(img)
                total = img if total is None else total + img
                total_sq = img * img if total_sq is None else total_sq + img * img
            k = len(seeds)
            mean = total / k
            var = dr.maximum(total_sq / k - mean * mean, 0.0) / (k - 1)
            mi.Bitmap(mean).write(job["out"] + "_mean.exr")
            mi.Bitmap(var).write(job["out"] + "_var.exr")
            print("done", job["out"], flush=True)
        except Exception as exc:          # reported per job; the test that needs it fails with this
            print("failed", job["out"] + ":", str(exc).replace("\n", " ")[:2000], flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
