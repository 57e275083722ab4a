"""Fuzzing the loader: whatever XML comes in, `load` returns a Scene/TTest or raises VolclError.

Documents are grown from the dialects' own plugin tables (real tags, types, parameter names and
kinds), sprinkled with junk names and values, and sometimes mangled as text afterwards.
"""
import shutil
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from volcl.errors import VolclError
from volcl.scene import load, parse_mitsuba, parse_nori
from volcl.scene.model import Scene, TTest
from volcl.scene.parse_common import ACCEPTS
from volcl.pack import pack
from volcl.scene.volfile import write_vol

DATA = Path(__file__).parent / "data" / "scene"

JUNK_NAMES = ["foo", "", "Type", "value ", "to-world", "scene", "ref", "default", "test"]
JUNK_TAGS = ["foo", "Shape", "texture", "scene", "test", "default", "ref", "float"]
VALUES_BY_KIND = {
    "float": ["0", "1", "-1", "0.5", "1e-3", "180", "2.5e10", "1e999",
              # the numerical hard cases: HG g near +-1 and 0, thick and thin media, float32 range
              "0.999", "-0.999", "1e-6", "-1e-6", "1e6", "1e-8", "3e38", "1e39", "1e-45"],
    "integer": ["0", "1", "-1", "4", "16", "3"],
    "boolean": ["true", "false", "True"],
    "string": ["tetra.obj", "density.vol", "missing.obj", "x", "y", "diagonal", "none", "bk7",
               "water", "trilinear", "nearest", "1, 2", "sub/../tetra.obj"],
    "rgb": ["0.5", "1, 0.5, 0.25", "0 0 0", "-1", "2, 2, 2", "0, 1, 2", "1e6, 0, 1e-8", "1e39"],
    "color": ["0.5", "1, 0.5, 0.25", "0 0 0", "-1"],
    "spectrum": ["0.5", "400:0.5, 500:1", "1 2"],
    "point": ["0, 0, 0", "1, 2, 3", "0,0,1"],
    "vector": ["0, 0, 1", "0, -1, 0", "0, 0, 0"],
}
NAMED_VALUES = {
    "filename": ["tetra.obj", "density.vol", "missing.obj", "open.obj", "flat.obj"],
    "fov_axis": ["x", "y", "diagonal", "smaller", "larger", "z"],
    "material": ["none", "Au"],
    "filter_type": ["trilinear", "nearest", "cubic"],
    "int_ior": ["bk7", "water", "fused silica", "glass"],
    "ext_ior": ["air", "vacuum"],
    "references": ["1", "1, 2", "2 5"],
}
JUNK_VALUES = ["", "abc", "2147483648", "nan", "inf", "$x", "$undefined", "1,,2", "  ", "&amp;", "<", "1;2",
               "0x10", "٣"]
OPS = {
    "translate": ["value", "x", "y", "z"],
    "scale": ["value", "x", "y", "z"],
    "rotate": ["value", "x", "y", "z", "angle"],
    "matrix": ["value"],
    "lookat": ["origin", "target", "up"],
}
OP_VALUES = ["1", "0", "1, 2, 3", "0, 0, 0", "0, 1, 0", "90", "-1,1,1",
             "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", "1 0 0 0 0 1 0 0 0 0 1"]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    shutil.copy(DATA / "tetra.obj", root / "tetra.obj")
    (root / "open.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")      # no inside for a medium
    (root / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")      # no area for an emitter
    write_vol(root / "density.vol", np.linspace(0, 1, 8).reshape(2, 2, 2))
    return root


def render(tag: str, attrs: list, children: list) -> str:
    text = " ".join(f"{k}={quoteattr(v)}" for k, v in attrs)
    inner = "".join(children)
    return f"<{tag} {text}>{inner}</{tag}>" if inner else f"<{tag} {text}/>"


def chance(data, percent: int) -> bool:
    """True about `percent` times in a hundred (listed so that shrinking heads for False)."""
    return data.draw(st.sampled_from([False] * (100 - percent) + [True] * percent))


def pick(data, options, junk, percent=8):
    if chance(data, percent):
        return data.draw(st.sampled_from(junk))
    return data.draw(st.sampled_from(options))


def gen_property(data, name: str, kind: str, tags) -> str:
    tag = pick(data, sorted(ACCEPTS[kind] & tags), sorted(tags))
    if tag == "transform":
        ops = [gen_op(data) for _ in range(data.draw(st.integers(0, 3)))]
        return render("transform", [("name", name)], ops)
    if tag in ("point", "vector") and data.draw(st.booleans()):
        attrs = [(k, pick(data, ["0", "1", "-2"], JUNK_VALUES)) for k in "xyz"
                 if data.draw(st.booleans())]
        return render(tag, [("name", name)] + attrs, [])
    options = NAMED_VALUES.get(name, VALUES_BY_KIND[tag]) if tag == "string" else VALUES_BY_KIND[tag]
    value = pick(data, options, JUNK_VALUES)
    return render(tag, [("name", name), ("value", value)], [])


def gen_op(data) -> str:
    op = pick(data, sorted(OPS), JUNK_NAMES)
    names = OPS.get(op, ["value"])
    attrs = [(n, pick(data, OP_VALUES, JUNK_VALUES)) for n in names if data.draw(st.booleans())]
    return render(op if op.strip() == op and op else "x", attrs, [])


def gen_object(data, dialect, tag: str, depth: int) -> str:
    types = dialect.specs.get(tag, {})
    kind = None if tag == "scene" else \
        pick(data, sorted(t for t in types if t is not None) or [None], JUNK_NAMES, 3)
    spec = types.get(kind)
    attrs = [] if kind is None else [("type", kind)]
    nested = depth > 0 and tag != "scene"
    if nested and chance(data, 30):
        attrs.append(("id", pick(data, ["a", "b"], JUNK_NAMES)))
    if nested and chance(data, 30):
        attrs.append(("name", pick(data, ["interior", "exterior", "sigma_t", "albedo"],
                                   JUNK_NAMES)))
    children = []
    if spec is not None:
        children += [gen_property(data, name, param_kind, dialect.property_tags)
                     for name, param_kind in _draw_params(data, spec)]
        children += [gen_child(data, dialect, spec, depth) for _ in range(_child_count(data, depth))
                     if depth < 3 and spec.children]
    if depth == 0 and chance(data, 20):
        children.insert(0, render("default", [("name", "x"), ("value", "1")], []))
    if tag == "scene" and dialect is parse_nori.DIALECT and not chance(data, 20):
        # Nori insists on an integrator and a camera; give most scenes both.
        children[:0] = ['<integrator type="path_mis"/>', '<camera type="perspective"/>']
    return render(tag, attrs, children)


def _draw_params(data, spec) -> list:
    params = sorted(spec.params.items())
    chosen = data.draw(st.lists(st.sampled_from(params), max_size=min(4, len(params)),
                                unique=not chance(data, 5))) if params else []
    # Now and then a parameter the plugin does not know.
    if chance(data, 5):
        chosen.append((data.draw(st.sampled_from(JUNK_NAMES)), "float"))
    return chosen


def _child_count(data, depth: int) -> int:
    return data.draw(st.integers(1, 6) if depth == 0 else st.integers(0, 2))


def gen_child(data, dialect, spec, depth: int) -> str:
    if chance(data, 10):
        return render("ref", [("id", pick(data, ["a", "b"], JUNK_NAMES))], [])
    child = pick(data, sorted(spec.children), JUNK_TAGS, 4)
    return gen_object(data, dialect, child, depth + 1)


def gen_document(data) -> str:
    root = data.draw(st.sampled_from(["mitsuba", "nori", "test"]))
    if root == "test":
        scenes = [gen_object(data, parse_nori.DIALECT, "scene", 1)
                  for _ in range(data.draw(st.integers(0, 2)))]
        refs = pick(data, ["1", "1, 2", "2 5"], JUNK_VALUES)
        prop = render("string", [("name", "references"), ("value", refs)], [])
        return render("test", [("type", "ttest")], [prop] + scenes)
    dialect = parse_mitsuba.DIALECT if root == "mitsuba" else parse_nori.DIALECT
    text = gen_object(data, dialect, "scene", 0)
    if root == "mitsuba":
        text = text.replace("<scene ", '<scene version="3.0.0" ', 1)
    return text


MUTATION_INSERTS = ["<", ">", "/>", "&", '"', "$", "<!DOCTYPE x>", "<?pi x?>", "<!-- c -->",
                    "]]>", "\x00", "é", "\n"]


def mutate(data, text: str) -> str:
    for _ in range(data.draw(st.integers(1, 3))):
        at = data.draw(st.integers(0, len(text)))
        action = data.draw(st.sampled_from(["delete", "insert", "duplicate"]))
        span = data.draw(st.integers(1, 12))
        if action == "delete":
            text = text[:at] + text[at + span:]
        elif action == "insert":
            text = text[:at] + data.draw(st.sampled_from(MUTATION_INSERTS)) + text[at:]
        else:
            text = text[:at] + text[at:at + span] + text[at:]
    return text


@settings(max_examples=200, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_load_returns_a_scene_or_raises_volclerror(workdir, data):
    text = gen_document(data)
    if chance(data, 25):
        text = mutate(data, text)
    # a -D for a parameter the scene never reads is an error of its own: mostly only when it does
    uses_x = "$x" in text or 'name="x"' in text
    defines = data.draw(st.sampled_from([None, {"x": "1"}, {"x": "abc"}] if uses_x else
                                        [None] * 9 + [{"x": "1"}]))
    path = workdir / "fuzz.xml"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        result = load(path, defines)
    except VolclError:
        return
    assert isinstance(result, (Scene, TTest))
    # a valid scene is one the kernels can take: it packs into finite float32 buffers
    for scene in result.scenes if isinstance(result, TTest) else [result]:
        assert_packs_finite(scene)


def assert_packs_finite(scene):
    if any(m.kind == "heterogeneous" for m in scene.media):
        return      # packing grid media for the kernels is the heterogeneous-media work (volcl/pack.py)
    scene.camera.width, scene.camera.height = 4, 3
    packed = pack(scene)
    for name, arr in packed.arrays.items():
        if name == "nodes":
            # unused child slots of a wide node carry an inverted infinite box by design
            b = arr["bounds"]
            used = b[:, 0] <= b[:, 3]
            assert np.all(used == np.isfinite(b).all(axis=1)), "a used child box is not finite"
            assert np.all(b[:, :3][~np.broadcast_to(used[:, None], b[:, :3].shape)] == np.inf)
            continue
        for field in arr.dtype.names or [None]:
            values = arr if field is None else arr[field]
            if values.dtype.kind == "f":
                assert np.isfinite(values).all(), f"{name}.{field} holds non-finite values"
    lights = packed.arrays["lights"]
    area = lights["area"][lights["type"] == 0][: sum(s.emitter_radiance is not None for s in scene.shapes)]
    assert (area > 0).all(), "an area light without area"


def test_generator_reaches_valid_scenes(workdir):
    """Guard against a fuzzer that only ever produces errors: the generator can build a scene."""
    text = ('<scene version="3.0.0"><shape type="obj">'
            '<string name="filename" value="tetra.obj"/></shape></scene>')
    (workdir / "ok.xml").write_text(text)
    assert isinstance(load(workdir / "ok.xml"), Scene)


# -- media, volumes and phase functions, in scenes that mostly make sense --------------------------

# Per parameter: values in range, the numerical hard cases among them, and a few out of range.
MEDIUM_VALUES = {
    "sigma_t": (["0", "1", "2", "1e6", "1e-8", "1e-45", "3e38", "0, 1, 2", "1e6, 0, 1e-8"], ["-1", "1e39", "nan"]),
    "albedo": (["0", "1", "0.5", "0.999", "1, 0, 0.5"], ["2", "-0.5", "inf"]),
    "scale": (["1", "1e-4", "1e4", "1e6"], ["0", "-1"]),
    "volcl_radiance": (["1", "0.5, 1, 2", "0"], ["-1", "1e39"]),
    "g": (["0.999", "-0.999", "1e-6", "-1e-6", "0", "0.5"], ["1", "-1", "1e6"]),
    "value": (["0.5", "1", "0, 1, 2", "1e6"], ["-1", "1e39"]),
}


def medium_value(data, name: str) -> tuple[str, str]:
    """(tag, value) for a medium parameter: <float> or <rgb> by the value's shape."""
    good, bad = MEDIUM_VALUES[name]
    value = pick(data, good, bad, 10)
    return ("rgb" if "," in value else data.draw(st.sampled_from(["float", "rgb"]))), value


def gen_medium(data, ident: str) -> str:
    kind = pick(data, ["homogeneous", "homogeneous", "heterogeneous"], JUNK_NAMES, 3)
    children = []
    for name in ("sigma_t", "albedo", "scale", "volcl_radiance"):
        what = data.draw(st.sampled_from(["absent", "value", "value", "volume"] if kind == "heterogeneous"
                                         and name in ("sigma_t", "albedo") else ["absent", "value"]))
        if what == "value":
            tag, value = medium_value(data, name)
            children.append(render("float" if name == "scale" else tag, [("name", name), ("value", value)], []))
        elif what == "volume":
            if data.draw(st.booleans()):
                tag, value = medium_value(data, "value")
                vol = render("volume", [("type", "constvolume"), ("name", name)],
                             [render(tag, [("name", "value"), ("value", value)], [])])
            else:
                props = [render("string", [("name", "filename"),
                                           ("value", pick(data, ["density.vol"], ["missing.vol", "tetra.obj"]))], [])]
                if chance(data, 30):
                    props.append(render("string", [("name", "filter_type"),
                                                   ("value", pick(data, ["nearest", "trilinear"], ["cubic"]))], []))
                vol = render("volume", [("type", "gridvolume"), ("name", name)], props)
            children.append(vol)
    phase = data.draw(st.sampled_from([None, "isotropic", "hg", "hg"]))
    if phase == "hg":
        g = [render("float", [("name", "g"), ("value", medium_value(data, "g")[1])], [])] \
            if not chance(data, 20) else []
        children.append(render("phase", [("type", "hg")], g))
    elif phase:
        children.append(render("phase", [("type", phase)], []))
    return render("medium", [("type", kind), ("id", ident)], children)


def gen_media_scene(data) -> str:
    media = [gen_medium(data, f"m{i}") for i in range(data.draw(st.integers(1, 3)))]
    ids = [f"m{i}" for i in range(len(media))] + ["nope"]
    sensor_medium = ([render("ref", [("id", pick(data, ids[:-1], ids[-1:], 5))], [])]
                     if data.draw(st.booleans()) else [])
    body = media + [render("sensor", [("type", "perspective")], sensor_medium + [
        render("film", [("type", "hdrfilm")], [render("integer", [("name", "width"), ("value", "4")], []),
                                               render("integer", [("name", "height"), ("value", "3")], [])])])]
    for _ in range(data.draw(st.integers(0, 3))):
        kind = data.draw(st.sampled_from(["cube", "sphere", "rectangle", "obj", "disk"]))
        children = []
        if kind == "obj":
            children.append(render("string", [("name", "filename"),
                                              ("value", data.draw(st.sampled_from(["tetra.obj", "open.obj", "flat.obj"])))], []))
        if chance(data, 40):
            children.append(render("bsdf", [("type", data.draw(st.sampled_from(["null", "dielectric", "diffuse"])))], []))
        if chance(data, 25):
            radiance = pick(data, ["1", "0.5, 1, 2"], ["-1", "1e39"], 10)
            children.append(render("emitter", [("type", "area")],
                                   [render("rgb", [("name", "radiance"), ("value", radiance)], [])]))
        for side in ("interior", "exterior"):
            if chance(data, 50):
                children.append(render("ref", [("id", pick(data, ids[:-1], ids[-1:], 5)), ("name", side)], []))
        if chance(data, 20):
            children.append(render("transform", [("name", "to_world")],
                                   [render("scale", [("value", data.draw(st.sampled_from(["1e-4", "1e4", "1e-30", "1e30"])))], [])]))
        body.append(render("shape", [("type", kind)], children))
    if data.draw(st.booleans()):
        body.append(render("emitter", [("type", "constant")], []))
    return render("scene", [("version", "3.0.0")], body)


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_media_scenes_load_and_pack_or_raise_volclerror(workdir, data):
    """The vocabulary of media: homogeneous and heterogeneous media with the numerical hard cases
    as values (g near +-1 and 0, sigma_t 1e6 and 1e-8, beyond float32), constant and grid volumes,
    phase functions, media on open and closed shapes, emitters on zero-area meshes."""
    path = workdir / "media.xml"
    path.write_text(gen_media_scene(data))
    try:
        scene = load(path)
    except VolclError:
        return
    assert isinstance(scene, Scene)
    assert_packs_finite(scene)


def test_media_generator_reaches_valid_scenes_with_media(workdir):
    """The media fuzzer is no use if every scene it builds is an error: some must load, with media."""
    valid = []

    @settings(max_examples=60, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(st.data())
    def collect(data):
        path = workdir / "media_valid.xml"
        path.write_text(gen_media_scene(data))
        try:
            valid.append(load(path))
        except VolclError:
            pass
    collect()
    with_media = [s for s in valid if s.media]
    assert len(with_media) >= 5, f"only {len(with_media)} of 60 generated scenes loaded with media"
    assert any(s.shapes and any(sh.interior is not None for sh in s.shapes) for s in with_media)
