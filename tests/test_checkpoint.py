"""Checkpoint files: a round trip continues bit for bit; a checkpoint of another render is refused."""
import shutil
from pathlib import Path

import numpy as np
import pytest

from volcl import checkpoint
from volcl.errors import VolclError
from volcl.renderer import Renderer
from volcl.scene import load

ROOT = Path(__file__).resolve().parent.parent


def renderer(path, device, seed=3, **defines):
    defines = {"width": "20", "height": "12", **{k: str(v) for k, v in defines.items()}}
    r = Renderer(load(path, defines), device=device, seed=seed)
    return r, checkpoint.identity(r, path, defines)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "cbox.xml"
    shutil.copy(ROOT / "scenes" / "cbox.xml", path)
    shutil.copytree(ROOT / "scenes" / "meshes", tmp_path / "meshes")
    return path


def test_round_trip_continues_bit_for_bit(tmp_path, scene_file, device):
    ref = renderer(scene_file, device)[0].render(90)
    r, ident = renderer(scene_file, device)
    r.render(50)
    ckpt = checkpoint.path_for(tmp_path / "out.exr")
    assert ckpt.name == "out.exr.checkpoint.npz"
    checkpoint.save(ckpt, r, ident, {"spp_requested": 90})
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []   # no temporary left
    state, meta = checkpoint.load(ckpt)
    assert meta["samples_done"] == 50 and meta["spp_requested"] == 90 and meta["seed"] == 3
    fresh, ident2 = renderer(scene_file, device)
    checkpoint.check(ckpt, meta, ident2, fresh.seed)
    fresh.restore(state)
    res = fresh.render(40)
    assert res.spp == 90 and np.array_equal(res.image, ref.image) and np.array_equal(res.variance, ref.variance)


def test_another_render_is_refused(tmp_path, scene_file, device):
    r, ident = renderer(scene_file, device)
    r.render(8)
    ckpt = checkpoint.save(tmp_path / "x.checkpoint.npz", r, ident)
    _, meta = checkpoint.load(ckpt)
    other, other_ident = renderer(scene_file, device, max_depth=2)
    with pytest.raises(VolclError, match="different render.*-D overrides.*scene data"):
        checkpoint.check(ckpt, meta, other_ident, other.seed)
    with pytest.raises(VolclError, match="seed: 3 in the checkpoint, 4 now"):
        checkpoint.check(ckpt, meta, ident, 4)
    with pytest.raises(VolclError, match="image width"):
        checkpoint.check(ckpt, meta, renderer(scene_file, device, width=21)[1], 3)
    scene_file.write_text(scene_file.read_text() + "<!-- edited -->\n")
    with pytest.raises(VolclError, match="scene file contents"):
        checkpoint.check(ckpt, meta, renderer(scene_file, device)[1], 3)
    # the target spp is no part of the identity: a resume may ask for more samples
    assert renderer(ROOT / "scenes" / "cbox.xml", device, spp=999)[1]["defines"] == ident["defines"]


def test_unreadable_checkpoint_is_a_clear_error(tmp_path):
    bad = tmp_path / "out.exr.checkpoint.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(VolclError, match="unreadable.*delete it"):
        checkpoint.load(bad)
