"""The shipped scenes of environment lighting, textures and rough materials against Mitsuba 3 itself,
as files, unchanged but for a small film and few samples (-D width, height, spp): a cloud under an
envmap sky (cloud_sky.xml), rough glass holding a medium on a checkerboard (rough_glass_medium.xml)
and the textured Cornell box (textured_cbox.xml). volcl's image must match the mean of Mitsuba's
seeds within the standard error both renders' variances predict, per channel over the image and over
4 x 4 blocks (the harness of tests/test_mitsuba_agreement.py). benchmarks/compare_mitsuba.py makes
the same comparison at larger sizes.

Optional: skipped without Mitsuba 3 ($VOLCL_MITSUBA_PYTHON or /work/mitsuba-venv/bin/python).
"""
from pathlib import Path

import pytest

from imagestats import assert_mean_matches
from test_mitsuba_agreement import SEEDS, VARIANT, mitsuba_references, reference_image
from volcl.renderer import Renderer
from volcl.scene import load

HERE = Path(__file__).resolve().parent
SCENES = HERE.parent / "scenes"
# scene -> film (the scene's aspect ratio) and samples per pixel for each renderer
CASES = {
    "cloud_sky": ({"width": "32", "height": "18"}, 64),
    "rough_glass_medium": ({"width": "32", "height": "24"}, 64),
    "textured_cbox": ({"width": "24", "height": "24"}, 64),
}


def _defines(name):
    film, spp = CASES[name]
    return {**film, "spp": str(spp)}


@pytest.fixture(scope="module")
def mitsuba_images(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mitsuba_scenes")
    jobs = [{"scene": str(SCENES / f"{name}.xml"), "out": str(folder / name), "spp": CASES[name][1],
             "seeds": SEEDS, "variant": VARIANT, "defines": _defines(name)} for name in CASES]
    return folder, mitsuba_references(folder, jobs)


@pytest.mark.parametrize("name", list(CASES))
def test_shipped_scene_matches_mitsuba(mitsuba_images, device, name):
    folder, references = mitsuba_images
    mean, var = reference_image(references, str(folder / name))
    scene = load(SCENES / f"{name}.xml", _defines(name))
    result = Renderer(scene, device=device, seed=5).render(CASES[name][1])
    assert_mean_matches(result, mean, blocks=4, what=name, expected_variance=var)
