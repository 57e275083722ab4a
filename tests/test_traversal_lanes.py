"""benchmarks/traversal_lanes.py: its lanes-style walks of the wide tree find the shipped walk's hits
bit for bit (the agreement its speed figures stand on)."""
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import traversal_lanes  # noqa: E402


@pytest.mark.parametrize("variant", ["loop", "regs"])
def test_lanes_walk_finds_the_shipped_hits(variant, device, capsys):
    if device.kind != "cpu":
        pytest.skip("a study of the CPU runtimes' vectorizers")
    selector = f"{device.platform_index}:{device.device_index}"
    traversal_lanes.main(["--device", selector, "--scenes", "tcbox", "--rays", "2048", "--repeat", "1",
                          "--variants", variant])
    rows = [line.split("|") for line in capsys.readouterr().out.splitlines() if f"| lanes {variant} |" in line]
    assert len(rows) == 2     # camera and bounce rays
    for cells in rows:
        agree, bits = cells[-3].strip(), cells[-2].strip()
        assert agree == bits == "100.0000%", cells
