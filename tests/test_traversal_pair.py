"""benchmarks/traversal_pair.py: the closest-hit walk cut into steps, one ray per work-item and two
taking turns, finds the shipped walk's hits bit for bit on every implementation (the agreement its
speed figures stand on)."""
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import traversal_pair  # noqa: E402

pytestmark = pytest.mark.every_implementation


def test_step_and_pair_walks_find_the_shipped_hits(device, capsys):
    selector = f"{device.platform_index}:{device.device_index}"
    # an odd count: the last work-item of the pair kernel holds one ray twice
    traversal_pair.main(["--device", selector, "--scenes", "tcbox", "--rays", "2001", "--repeat", "1"])
    rows = [line.split("|") for line in capsys.readouterr().out.splitlines()
            if "| step |" in line or "| pair |" in line]
    assert len(rows) == 4     # camera and bounce rays, two walks each
    for cells in rows:
        assert cells[-2].strip() == "100.0000%", cells


def test_same_bits_tells_a_changed_hit():
    t = np.array([1.0, 2.0, np.inf], np.float32)
    prim = np.array([3, 4, 0x7fffffff], np.int32)
    assert traversal_pair.same_bits((t, prim), (t.copy(), prim.copy())) == 1.0
    nudged = t.copy()
    nudged[0] = np.nextafter(nudged[0], np.float32(0))
    assert traversal_pair.same_bits((t, prim), (nudged, prim)) == pytest.approx(2 / 3)
    assert traversal_pair.same_bits((t, prim), (t, prim + 1)) == 0.0
