"""Sweeps: one scene rendered with several sets of <default> values, from `-D` ranges
(`-D frame=1..100`, `-D seed_offset=0..40:10`) or from a sweep file (`--sweep FILE`, one set of
values a line: `sigma_t=0.1 g=0.3`; `#` starts a comment). Each set is a job of the batch, its
output named after the scene and the values that vary (fog.xml, -D frame=1..100 ->
fog_frame_001.exr ... fog_frame_100.exr; the scene reads the values as given, unpadded).
"""
from __future__ import annotations

import itertools
import re
import shlex
from pathlib import Path

from .errors import VolclError

RANGE = re.compile(r"^\s*(-?\d+)\.\.(-?\d+)(?::(\d+))?\s*$")
SAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def _range_values(name: str, text: str) -> list[str] | None:
    m = RANGE.match(text)
    if m is None:
        return None
    first, last, step = int(m.group(1)), int(m.group(2)), int(m.group(3) or 1)
    if step < 1 or last < first:
        raise VolclError(f"-D {name}={text}: a range runs upwards, A..B or A..B:STEP with A <= B and STEP >= 1")
    return [str(v) for v in range(first, last + 1, step)]


def expand(defines: dict) -> list[dict]:
    """Every combination of the -D values, ranges expanded (in the order the names were given)."""
    axes = []
    for name, value in defines.items():
        values = _range_values(name, str(value))
        axes.append([(name, v) for v in (values if values is not None else [value])])
    return [dict(combo) for combo in itertools.product(*axes)]


def read_file(path) -> list[dict]:
    """The value sets of a sweep file, one a line: name=value pairs separated by spaces (quote a
    value with spaces: name="0.5, 0.5, 0.5")."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise VolclError(f"--sweep {path}: cannot read it ({exc.strerror})") from None
    sets = []
    for number, line in enumerate(lines, 1):
        try:
            words = shlex.split(line, comments=True)
        except ValueError as exc:
            raise VolclError(f"{path}:{number}: {exc}") from None
        if not words:
            continue
        values = {}
        for word in words:
            if "=" not in word or not word.split("=", 1)[0]:
                raise VolclError(f"{path}:{number}: {word!r}: expected name=value")
            name, value = word.split("=", 1)
            values[name] = value
        sets.append(values)
    if not sets:
        raise VolclError(f"--sweep {path}: no values in it (one set a line: name=value name=value)")
    return sets


def combine(defines: dict, sweep_file=None) -> list[dict]:
    """The -D values of each job: the -D ranges expanded, times each line of the sweep file (whose
    values win over -D's)."""
    sets = expand(defines)
    if sweep_file is None:
        return sets
    return [{**base, **line} for base in sets for line in read_file(sweep_file)]


def varying(sets: list[dict]) -> list[str]:
    """The names whose value differs between the sets (what outputs are named by)."""
    names = list(dict.fromkeys(k for s in sets for k in s))
    return [n for n in names if len({s.get(n) for s in sets}) > 1]


def suffix(values: dict, names: list[str], sets: list[dict]) -> str:
    """'_frame_007_g_0.3': the varying values, safe in a file name; integers are zero-padded to the
    width of the largest among `sets`, so that outputs sort in order."""
    parts = []
    for n in names:
        if n not in values:         # a sweep file's line that leaves this one to the scene
            continue
        value = str(values[n])
        column = [str(s[n]) for s in sets if n in s]
        if all(re.fullmatch(r"\d+", v) for v in column):
            value = value.zfill(max(len(v) for v in column))
        parts.append(f"_{SAFE.sub('-', n)}_{SAFE.sub('-', value)}")
    return "".join(parts)
