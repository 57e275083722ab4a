"""volcl's kernels compile without a warning under clang's OpenCL front end: -Weverything, and
clang's static analyzer, for the program with every feature compiled in; and every specialization
(no feature, each feature alone, all features but one) under the same warnings less the
unused-parameter and unused-variable family (code a specialization compiles out leaves its
arguments unused, by design). The wavefront renderer's entry points (wavefront.cl, wavefront_lanes.cl,
wavefront_surface.cl) are checked with every feature compiled in, with and without the lanes stage's
whole-scene tests, the medium stage also with its paths in a loop of each work-item (PoCL's build),
and the packet renderer's (packets.cl) at both packet widths with every feature it takes, with and
without its vector step for diffuse lanes (packet_lanes.h), and with its rough plastic step and
bitmaps (lanes_rough.h, lanes_bitmap.h). Skipped, with the reason, where clang is
absent (`./quickstart test` installs it)."""
import shutil
import subprocess

import pytest

from volcl import packets
from volcl.features import FLAGS, all_features
from volcl.program import build_options, kernels_dir

CLANG = next((c for c in ["clang"] + [f"clang-{v}" for v in range(22, 13, -1)] if shutil.which(c)), None)
pytestmark = pytest.mark.skipif(CLANG is None, reason="clang is not installed (./quickstart test installs it)")

FRONT_END = ["-x", "cl", "-cl-std=CL1.2", "-target", "spir64-unknown-unknown", "-Xclang", "-finclude-default-header"]
# Everything clang can warn about, less what is policy here: explicit pad fields in structs shared with
# the host (types.h), C99 declarations after statements, and exact float comparisons (zero
# determinants and extinctions are tested exactly on purpose).
WARNINGS = ["-Weverything", "-Werror", "-Wno-padded", "-Wno-declaration-after-statement", "-Wno-float-equal"]
COMPILED_OUT = ["-Wno-unused-parameter", "-Wno-unused-variable", "-Wno-unused-but-set-variable"]


def _specializations():
    none = dict.fromkeys(FLAGS, False)
    out = [("no-features", none)]
    for f in FLAGS:
        out.append((f"only-{f.lower()}", {**none, f: True}))
        out.append((f"all-but-{f.lower()}", {**all_features(), f: False}))
    return out


# (file, extra options): the wavefront stages also as built for a scene tested whole (volcl.wavefront:
# 6 triangles in packets of 4 and 2, 2 spheres, 3 light triangles)
TINY = ["-DVOLCL_WF_TINY=6", "-DVOLCL_WF_TINY_ENDS=40", "-DVOLCL_WF_SPHERES=2", "-DVOLCL_WF_LIGHT_TRIS=3"]
ENTRY_POINTS = ["render.cl", "wavefront.cl", "wavefront_lanes.cl", "wavefront.cl tiny", "wavefront_lanes.cl tiny",
                "wavefront_lanes.cl loop", "wavefront_lanes.cl tiny loop", "wavefront_surface.cl tiny",
                "packets.cl 16", "packets.cl 8", "packets.cl 16 lanes", "packets.cl 8 lanes", "packets.cl 16 rough"]
# the medium stage with its paths in a loop of each work-item, as PoCL builds it (wavefront.lanes_loop)
LOOP = ["-DVOLCL_WF_LOOP=16"]
# the packet renderer's vector step, as built for a scene of 6 tested triangles and 3 light triangles
PACKET_LANES = ["-DVOLCL_PACKET_LANES=1", "-DVOLCL_WF_TINY=6", "-DVOLCL_WF_LIGHT_TRIS=3"]
# and its rough plastic step, reading bitmaps
PACKET_ROUGH = PACKET_LANES + ["-DVOLCL_PACKET_ROUGH=1", "-DVOLCL_PACKET_BITMAPS=1"]


def _compile(args, features, entry="render.cl"):
    name, _, variant = entry.partition(" ")
    extra = (TINY if variant.startswith("tiny") else []) + (LOOP if variant.endswith("loop") else [])
    if name == packets.SOURCE_FILE:     # the features it takes (the others are an #error there)
        features = {k: v and k not in packets.EXCLUDED for k, v in features.items()}
        width, _, lanes = variant.partition(" ")
        extra = [f"-DVOLCL_PACKET_WIDTH={width}"] + {"": [], "lanes": PACKET_LANES, "rough": PACKET_ROUGH}[lanes]
    cmd = [CLANG] + FRONT_END + args + build_options(features, tuple(extra)) + [str(kernels_dir() / name)]
    return subprocess.run(cmd, capture_output=True, text=True)


@pytest.mark.parametrize("entry", ENTRY_POINTS)
def test_every_feature_compiles_without_warnings(entry):
    # (the packet renderer's program is a specialization: without media, say, arguments go unused)
    compiled_out = COMPILED_OUT if entry.startswith(packets.SOURCE_FILE) else []
    r = _compile(WARNINGS + compiled_out + ["-fsyntax-only"], all_features(), entry)
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr


@pytest.mark.parametrize("entry", ENTRY_POINTS)
def test_static_analyzer_finds_nothing(tmp_path, entry):
    """clang --analyze follows paths through the kernel (uninitialized reads, dead stores, null
    dereferences) and reports through the same diagnostics."""
    r = _compile(["--analyze", "-Xanalyzer", "-analyzer-output=text", "-o", str(tmp_path / "report")],
                 all_features(), entry)
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr


@pytest.mark.parametrize("name,features", _specializations(), ids=[n for n, _ in _specializations()])
def test_specializations_compile_without_warnings(name, features):
    r = _compile(WARNINGS + COMPILED_OUT + ["-fsyntax-only"], features)
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr


def test_the_check_sees_a_warning():
    """The flags do report: an uninitialized read added through -D is an error."""
    r = _compile(WARNINGS + ["-fsyntax-only", "-DVOLCL_KERNEL=int probe(void) { int x; return x; } __kernel"],
                 all_features())
    assert r.returncode != 0 and "-Wuninitialized" in r.stderr, r.stderr
