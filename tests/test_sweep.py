"""Sweeps (volcl.sweep): -D ranges and sweep files made into the jobs of a batch, and their output names."""
from pathlib import Path

import pytest

from volcl import sweep
from volcl.batch import make_jobs
from volcl.errors import VolclError
from volcl.options import OutputOptions, SceneOptions


def names(jobs):
    return [str(j.output) for j in jobs]


def test_ranges_expand_into_every_combination_named_by_what_varies():
    sets = sweep.expand({"frame": "8..11:2", "g": "0.3", "depth": "1..2"})
    assert sets == [{"frame": "8", "g": "0.3", "depth": "1"}, {"frame": "8", "g": "0.3", "depth": "2"},
                    {"frame": "10", "g": "0.3", "depth": "1"}, {"frame": "10", "g": "0.3", "depth": "2"}]
    assert sweep.varying(sets) == ["frame", "depth"]
    jobs = make_jobs(["a/shot.xml"], SceneOptions(defines={"frame": "8..11:2", "depth": "1..2"}), OutputOptions())
    assert names(jobs) == ["shot_frame_08_depth_1.exr", "shot_frame_08_depth_2.exr",
                           "shot_frame_10_depth_1.exr", "shot_frame_10_depth_2.exr"]
    assert jobs[2].defines == {"frame": "10", "depth": "1"} and jobs[2].label == "a/shot.xml [frame=10 depth=1]"
    # -o of a single scene is the pattern; without a sweep nothing changes
    jobs = make_jobs(["shot.xml"], SceneOptions(defines={"frame": "1..3"}), OutputOptions(output=Path("out/f.png")))
    assert names(jobs) == ["out/f_frame_1.png", "out/f_frame_2.png", "out/f_frame_3.png"]
    jobs = make_jobs(["x/a.xml", "y/a.xml"], SceneOptions(defines={"spp": "4"}), OutputOptions(output_dir=Path("o")))
    assert names(jobs) == ["o/x_a.exr", "o/y_a.exr"] and jobs[0].defines is None


def test_sweep_files_combine_with_ranges(tmp_path):
    f = tmp_path / "s.txt"
    f.write_text('# extinction and colour\nsigma_t=0.1 albedo="0.5, 0.5, 0.5"\n\nsigma_t=1e-2  # thin\n')
    sets = sweep.combine({"frame": "1..2"}, f)
    assert sets[1] == {"frame": "1", "sigma_t": "1e-2"} and sets[0]["albedo"] == "0.5, 0.5, 0.5"
    jobs = make_jobs(["fog.xml"], SceneOptions(defines={"frame": "1..2"}, sweep=f), OutputOptions())
    assert names(jobs) == ["fog_frame_1_sigma_t_0.1_albedo_0.5-0.5-0.5.exr", "fog_frame_1_sigma_t_1e-2.exr",
                           "fog_frame_2_sigma_t_0.1_albedo_0.5-0.5-0.5.exr", "fog_frame_2_sigma_t_1e-2.exr"]


@pytest.mark.parametrize("text, message", [
    ("sigma_t=0.1\nsigma_t\n", r"s.txt:2: 'sigma_t': expected name=value"),
    ("g='0.3\n", r"s.txt:1: No closing quotation"),
    ("# nothing\n", r"no values in it"),
    ("sigma_t=0.1\nsigma_t=0.1\n", r"would both write .*fog_sigma_t|each set of values once"),
])
def test_bad_sweep_files_are_named_with_their_line(tmp_path, text, message):
    f = tmp_path / "s.txt"
    f.write_text(text)
    with pytest.raises(VolclError, match=message):
        make_jobs(["fog.xml"], SceneOptions(sweep=f), OutputOptions())


def test_bad_ranges_and_outputs_are_refused():
    with pytest.raises(VolclError, match="runs upwards"):
        sweep.expand({"frame": "5..1"})
    with pytest.raises(VolclError, match="-o names one output"):
        make_jobs(["a.xml", "b.xml"], SceneOptions(), OutputOptions(output=Path("x.exr")))
    with pytest.raises(VolclError, match="cannot read"):
        make_jobs(["a.xml"], SceneOptions(sweep=Path("/nonexistent/sweep.txt")), OutputOptions())
