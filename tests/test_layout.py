"""Every struct shared with the host: size and field offsets as the device compiler lays them out
must equal the numpy dtypes in volcl/layout.py."""
import numpy as np
import pytest

from conftest import run_kernel
from volcl.device import cl
from volcl.features import all_features
from volcl.layout import SHARED_STRUCTS
from volcl.program import build_options

pytestmark = pytest.mark.every_implementation


def probe_source():
    """A probe kernel writing sizeof and __builtin_offsetof of every field, in dtype order."""
    lines = ['#include "types.h"', "__kernel void probe(__global int *out) {"]
    i = 0
    for struct, dtype in SHARED_STRUCTS.items():
        lines.append(f"    out[{i}] = (int)sizeof({struct});")
        i += 1
        for name in dtype.names:
            lines.append(f"    out[{i}] = (int)__builtin_offsetof({struct}, {name});")
            i += 1
    lines.append("}")
    return "\n".join(lines), i


def test_shared_structs_match_device(cl_env):
    ctx, queue = cl_env
    src, n = probe_source()
    prog = cl.Program(ctx, src).build(options=build_options(all_features()))
    (out,) = run_kernel(cl_env, prog, "probe", 1, [(np.int32, (n,))])
    out = out[0]
    i = 0
    problems = []
    for struct, dtype in SHARED_STRUCTS.items():
        if out[i] != dtype.itemsize:
            problems.append(f"sizeof({struct}) = {out[i]} on the device, {dtype.itemsize} in numpy")
        i += 1
        for name in dtype.names:
            if out[i] != dtype.fields[name][1]:
                problems.append(f"{struct}.{name} at {out[i]} on the device, {dtype.fields[name][1]} in numpy")
            i += 1
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("struct", list(SHARED_STRUCTS))
def test_struct_sizes_are_16_byte_multiples(struct):
    """Arrays of structs stay aligned for float4 loads on every device."""
    assert SHARED_STRUCTS[struct].itemsize % 16 == 0
