"""Small pieces the benchmark scripts share. Standard library only: mitsuba_ref.py imports this
from inside the Python that has Mitsuba, which need not have volcl."""
import platform
from pathlib import Path


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def parse_defines(items) -> dict:
    """-D name=value arguments as a dict."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"-D {item!r}: expected name=value")
        k, v = item.split("=", 1)
        out[k.strip()] = v
    return out
