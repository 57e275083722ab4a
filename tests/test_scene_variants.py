"""benchmarks/scene_variants.py: each variant of textured_cbox takes away what its label says, and
volcl reads every one."""
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import volcl

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import scene_variants  # noqa: E402

SCENE = ROOT / "scenes" / "textured_cbox.xml"


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """label: (file, its root element as read back)"""
    files = scene_variants.write_variants(SCENE, tmp_path_factory.mktemp("variants"))
    return {label: (path, ET.parse(path).getroot()) for label, path in files}


def bsdf_types(root):
    return [b.get("type") for b in root.iter("bsdf")]


def test_labels(written):
    shapes_with_textures = [k for k in written if k.startswith("plain textures on ")]
    # floor, back wall, red wall, sphere, cube: every textured shape gets a variant of its own
    assert len(shapes_with_textures) == 5
    assert {"as shipped", "plain textures", "plain textures, GGX", "every bsdf diffuse"} <= set(written)


def test_plain_textures(written):
    root = written["plain textures"][1]
    assert not list(root.iter("texture"))
    assert not set(bsdf_types(root)) & set(scene_variants.WRAPPERS)
    # a float parameter became a float, a colour one a colour
    sphere = [s for s in root.iter("shape") if s.get("type") == "sphere"][0]
    assert sphere.find("bsdf/float[@name='alpha']") is not None
    assert root.find(".//bsdf[@type='roughplastic']/rgb[@name='diffuse_reflectance']") is not None


def test_one_shape_only(written):
    root = written["plain textures on floor"][1]
    floor = [s for s in root.iter("shape") if s.get("id") == "floor"][0]
    assert not list(floor.iter("texture"))
    assert len(list(root.iter("texture"))) == len(list(written["as shipped"][1].iter("texture"))) - 1


def test_distributions(written):
    root = written["plain textures, GGX"][1]
    rough = [b for b in root.iter("bsdf") if b.get("type") in scene_variants.ROUGH]
    assert rough and all(b.find("string[@name='distribution']").get("value") == "ggx" for b in rough)
    root = written["plain textures, Beckmann with sample_visible false"][1]
    flags = root.findall(".//boolean[@name='sample_visible']")
    # the cube's roughplastic is the only Beckmann bsdf (Mitsuba's default distribution)
    assert len(flags) == 1 and flags[0].get("value") == "false"


def test_every_bsdf_diffuse(written):
    root = written["every bsdf diffuse"][1]
    assert set(bsdf_types(root)) == {"diffuse"}
    assert len(root.findall(".//emitter")) == 1


def test_volcl_reads_every_variant(written):
    """volcl reads each, and compiles what is left: no texture code once every texture is plain,
    no rough bsdf once every bsdf is diffuse."""
    features = {label: volcl.load_file(str(path), width=8, height=8).features
                for label, (path, _) in written.items()}
    assert features["as shipped"]["TEXTURES"] and features["as shipped"]["BUMP_MAPS"]
    assert not features["plain textures"]["TEXTURES"] and not features["plain textures"]["BUMP_MAPS"]
    assert features["plain textures"]["ROUGHPLASTIC"] and features["plain textures"]["ROUGHCONDUCTOR"]
    assert not features["every bsdf diffuse"]["ROUGHPLASTIC"]
    assert not features["every bsdf diffuse"]["ROUGHCONDUCTOR"]


def test_albedo_variants(tmp_path):
    """--albedo: each non-diffuse shape made diffuse of its own albedo (the floor's bitmap's mean
    linear colour, the normal-mapped wall's inner reflectance, grey for the gold sphere), one at a
    time and then together; volcl reads every one."""
    import numpy as np
    from volcl.scene.images import read_image
    files = dict(scene_variants.write_variants(SCENE, tmp_path, by_albedo=True))
    assert list(files)[0] == "as shipped"
    singles = [k for k in files if k.startswith("diffuse on ") and "," not in k]
    assert len(singles) == 4, singles      # floor, back wall, sphere, cube
    root = ET.parse(files["diffuse on floor"]).getroot()
    floor = [s for s in root.iter("shape") if s.get("id") == "floor"][0]
    value = [float(v) for v in floor.find("bsdf[@type='diffuse']/rgb").get("value").split(",")]
    tiles = read_image(str(ROOT / "scenes" / "textures" / "tiles.png"))[..., :3].reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(value, tiles, atol=1e-4)
    back = [s for s in ET.parse(files["diffuse on back"]).getroot().iter("shape") if s.get("id") == "back"][0]
    assert back.find("bsdf[@type='diffuse']/rgb").get("value") == "0.725, 0.71, 0.68"
    last = ET.parse(list(files.values())[-1]).getroot()
    assert {b.get("type") for s in last.iter("shape") for b in s.findall("bsdf")} == {"diffuse"}
    for path in files.values():
        volcl.load_file(path)
