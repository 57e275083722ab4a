"""The Renderer's bookkeeping: images bit-identical whatever the batching of samples into passes
and launches, state saved and restored mid-render, launches sized to a time budget."""
from pathlib import Path

import numpy as np
import pytest

from volcl.renderer import Renderer
from volcl.scene import load

pytestmark = pytest.mark.every_implementation

ROOT = Path(__file__).resolve().parent.parent


def cbox(width, height, **defines):
    scene = load(ROOT / "scenes" / "cbox.xml", {k: str(v) for k, v in defines.items()})
    scene.camera.width, scene.camera.height = width, height
    return scene


def same(a, b):
    return (a.spp == b.spp and a.invalid == b.invalid and np.array_equal(a.image, b.image)
            and np.array_equal(a.variance, b.variance))


@pytest.fixture(scope="module")
def small():
    return cbox(24, 16)


@pytest.fixture(scope="module")
def reference(small, device):
    """100 spp in one call; 24x16 pixels keep 42 accumulator slots, so 100 spp is not a whole
    number of slot rounds."""
    r = Renderer(small, device=device, seed=7)
    assert r.slots == 42
    return r.render(100)


def test_repeated_renders_are_bit_identical(small, device, reference):
    again = Renderer(small, device=device, seed=7).render(100)
    assert same(again, reference)
    assert reference.image.mean() > 0


def test_seed_changes_the_image(small, device, reference):
    other = Renderer(small, device=device, seed=8).render(100)
    assert not np.array_equal(other.image, reference.image)


@pytest.mark.parametrize("calls", [[7, 30, 63], [42, 58], [1] * 5 + [95], [41, 1, 1, 57]])
def test_spp_split_into_calls_is_bit_identical(small, device, reference, calls):
    """Calls that start inside a round of slots (7, 37, ...) go through the scratch path."""
    r = Renderer(small, device=device, seed=7)
    for spp in calls:
        res = r.render(spp)
    assert same(res, reference)


@pytest.mark.parametrize("pixels", [1, 37, 100])
def test_launch_size_does_not_change_the_image(small, device, reference, pixels):
    r = Renderer(small, device=device, seed=7, launch_pixels=pixels)
    res = r.render(100)
    assert r.launches == 3 * -(-24 * 16 // pixels)     # 3 passes (42 + 42 + 16 spp), each in launches
    assert same(res, reference)


def test_render_in_launches_of_several_rounds_is_bit_identical(small, device, reference, monkeypatch):
    """render() on a device without a launch budget, once it has timed a round of the slots, runs
    several to a launch (up to MULTI_PASS_SECONDS): the same bits."""
    from volcl import renderer
    monkeypatch.setattr(renderer, "MULTI_PASS_SECONDS", 0.0)       # one round per launch
    single = Renderer(small, device=device, seed=7)
    one_each = single.render(200)
    monkeypatch.setattr(renderer, "MULTI_PASS_SECONDS", 1e9)
    r = Renderer(small, device=device, seed=7)
    res = r.render(200)
    if device.kind != "gpu":
        assert single.launches == 5     # 4 x 42 + 32
        assert r.launches == 3          # 42 spp (timed), 3 x 42 in one launch, the last 32
    assert same(res, one_each)


@pytest.mark.parametrize("calls", [[100], [7, 93], [42, 58], [90, 10]])
def test_advance_in_launches_of_several_rounds_is_bit_identical(small, device, reference, calls):
    """advance() (the tiles of volcl.rounds) runs whole rounds of the slots several to a launch on a
    device without a launch time budget, the partial rounds each in their own: the bits of render()."""
    r = Renderer(small, device=device, seed=7)
    for spp in calls:
        r.advance(spp)
    if device.kind != "gpu":
        launches = {(100,): 2, (7, 93): 4, (42, 58): 3, (90, 10): 3}[tuple(calls)]    # (100,): 84 spp in one
        assert r.launches == launches, r.launches
    assert same(r.result(), reference)


def test_state_restored_in_a_new_renderer_continues_bit_for_bit(small, device, reference):
    first = Renderer(small, device=device, seed=7)
    first.render(61)
    state = first.state()
    second = Renderer(small, device=device, seed=7)
    second.restore(state)
    assert second.samples_done == 61
    assert same(second.render(39), reference)


def test_restore_refuses_another_seed_or_size(small, device):
    state = Renderer(small, device=device, seed=7).state()
    with pytest.raises(ValueError, match="seed"):
        Renderer(small, device=device, seed=8).restore(state)
    with pytest.raises(ValueError, match="slots"):
        Renderer(cbox(16, 16), device=device, seed=7).restore(state)


def test_time_budget_splits_passes_into_short_launches_without_changing_the_image(device, monkeypatch):
    """What GPUs get (GPU_LAUNCH_SECONDS), forced here on whatever device runs the tests with a
    budget of half a pass: passes split into several launches, and the image is the same."""
    from volcl import renderer
    monkeypatch.setattr(renderer, "MULTI_PASS_SECONDS", 1e9)     # no timing in the launch count
    scene = cbox(128, 128)
    plain = Renderer(scene, device=device, seed=1, launch_seconds=None)
    plain.render(1)                                     # PoCL compiles at the first launch
    plain.reset()
    ref = plain.render(4)
    # without a budget: the first pass alone (its time unknown), then the other 3 in one launch
    assert plain.launches == 3
    budget = Renderer(scene, device=device, seed=1, launch_seconds=ref.seconds / 4 / 2)
    res = budget.render(4)
    assert budget.launches >= 8
    assert same(res, ref)
