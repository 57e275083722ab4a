"""<phase> elements of the Mitsuba dialect: what each one loads as (Mitsuba 3.9's meaning for
rayleigh, blendphase and tabphase; volcl's extensions), the feature flag each one compiles, and
every bad input as an error naming the file, the line and the valid range."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from volcl import phase as ph
from volcl.errors import VolclError
from volcl.features import detect
from volcl.pack import pack
from volcl.scene import load
from volcl.scene.model import Phase

SCENE = '''<scene version="3.0.0">
<medium type="homogeneous" id="m">
{}
</medium>
<sensor type="perspective"><ref id="m"/>
<film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="3"/></film></sensor>
</scene>
'''     # the phase element starts on line 3


def load_phase(tmp_path, body):
    path = tmp_path / "phase.xml"
    path.write_text(SCENE.format(body))
    sc = load(path)
    return sc.camera.medium.phase, sc


def expect_error(tmp_path, body, line, *fragments):
    path = tmp_path / "phase.xml"
    path.write_text(SCENE.format(body))
    with pytest.raises(VolclError) as info:
        load(path)
    message = str(info.value)
    assert f"phase.xml:{line}:" in message, message
    for f in fragments:
        assert f in message, message
    return message


def test_rayleigh(tmp_path):
    p, sc = load_phase(tmp_path, '<phase type="rayleigh"/>')
    assert p.kind == "rayleigh"
    assert detect(sc)["PHASE_FAMILIES"] and not detect(sc)["HG"]


def test_blendphase_nested_in_document_order(tmp_path):
    """Mitsuba 3.9.1 takes the two nested phases in the order they are written (checked with it: a
    blend with weight 0 of <phase name="zz" type="hg"> then <phase name="aa" type="isotropic"> is
    the hg), whatever their names; weight 0 selects the first, 1 the second, default 0.5."""
    p, _ = load_phase(tmp_path, '''<phase type="blendphase">
        <float name="weight" value="0.25"/>
        <phase name="zz" type="hg"><float name="g" value="0.3"/></phase>
        <phase name="aa" type="blendphase">
            <phase type="rayleigh"/>
            <phase type="isotropic"/>
        </phase>
    </phase>''')
    assert p.kind == "blend" and p.weight == 0.25
    assert p.phases[0].kind == "hg" and p.phases[0].g == 0.3
    inner = p.phases[1]
    assert inner.kind == "blend" and inner.weight == 0.5 and [q.kind for q in inner.phases] == ["rayleigh", "isotropic"]
    assert [(round(w, 6), leaf.kind) for w, leaf in ph.lobes(p)] == [(0.75, "hg"), (0.125, "rayleigh"),
                                                                     (0.125, "isotropic")]


def test_blend_that_selects_one_hg_is_the_hg_fast_path(tmp_path):
    p, sc = load_phase(tmp_path, '''<phase type="blendphase"><float name="weight" value="0"/>
        <phase type="hg"><float name="g" value="0.4"/></phase><phase type="rayleigh"/></phase>''')
    f = detect(sc)
    assert f["HG"] and not f["PHASE_FAMILIES"]
    assert pack(sc).arrays["media"][0]["phase"] == 1


def test_blended_hg_pair_is_double_hg(tmp_path):
    """Two HG lobes blended: what a double-HG phase function is (volcl has no separate plugin)."""
    p, _ = load_phase(tmp_path, '''<phase type="blendphase"><float name="weight" value="0.2"/>
        <phase type="hg"><float name="g" value="0.9"/></phase>
        <phase type="hg"><float name="g" value="-0.4"/></phase></phase>''')
    c = np.linspace(-1, 1, 11)
    hg = lambda g: (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)     # noqa: E731
    assert np.allclose(ph.pdf(p, c), 0.8 * hg(0.9) + 0.2 * hg(-0.4), rtol=1e-12)


def test_tabphase_values(tmp_path):
    """Mitsuba's tokenizer splits on commas and spaces."""
    p, _ = load_phase(tmp_path, '<phase type="tabphase"><string name="values" value="1, 2 3,,0.5"/></phase>')
    assert p.kind == "tabulated" and p.values.tolist() == [1.0, 2.0, 3.0, 0.5]


def test_draine_cornette_shanks_mie_defaults(tmp_path):
    """Defaults as Blender Cycles' Volume Scatter node: g 0, alpha 0.5, diameter 20."""
    p, _ = load_phase(tmp_path, '<phase type="volcl_draine"/>')
    assert (p.kind, p.g, p.alpha) == ("draine", 0.0, 0.5)
    p, _ = load_phase(tmp_path, '<phase type="volcl_cornetteshanks"><float name="g" value="0.6"/></phase>')
    assert (p.kind, p.g) == ("cornette_shanks", 0.6)
    assert ph.lobes(p)[0][1].kind == "draine" and ph.lobes(p)[0][1].alpha == 1.0
    p, _ = load_phase(tmp_path, '<phase type="volcl_mie"/>')
    assert (p.kind, p.diameter) == ("mie", 20.0)
    assert [leaf.kind for _, leaf in ph.lobes(p)] == ["hg", "draine"]


def test_fournier_forand_parametrizations(tmp_path):
    p, _ = load_phase(tmp_path, '<phase type="volcl_fournierforand"><float name="backscatter" value="0.0183"/></phase>')
    assert p.n == pytest.approx(1.10, abs=1e-3) and p.mu == pytest.approx(3.5835, abs=1e-3)
    p, _ = load_phase(tmp_path, '''<phase type="volcl_fournierforand"><float name="backscatter" value="0.05"/>
        <float name="n" value="1.2"/></phase>''')
    assert p.n == 1.2 and ph.FournierForand(p.n, p.mu).backscatter() == pytest.approx(0.05, rel=1e-9)
    p, _ = load_phase(tmp_path, '''<phase type="volcl_fournierforand"><float name="n" value="1.05"/>
        <float name="mu" value="3.7"/></phase>''')
    assert (p.n, p.mu) == (1.05, 3.7)
    p, _ = load_phase(tmp_path, '<phase type="volcl_fournierforand"/>')
    assert ph.FournierForand(p.n, p.mu).backscatter() == pytest.approx(0.1, rel=1e-9)


CASES = {
    "draine alpha below zero": ('<phase type="volcl_draine">\n<float name="alpha" value="-0.1"/></phase>', 4,
                                "'alpha' = -0.1", "0 <= alpha <= 1e+06"),
    "draine g of one": ('<phase type="volcl_draine">\n<float name="g" value="1"/></phase>', 4, "-1 < g < 1"),
    "cornette-shanks g": ('<phase type="volcl_cornetteshanks">\n<float name="g" value="-1.2"/></phase>', 4,
                          "-1 < g < 1"),
    "tabphase one entry": ('<phase type="tabphase">\n<string name="values" value="1"/></phase>', 4,
                           "at least 2 entries", "found 1"),
    "tabphase negative": ('<phase type="tabphase">\n<string name="values" value="1, -2, 3"/></phase>', 4,
                          ">= 0", "-2"),
    "tabphase nan": ('<phase type="tabphase">\n<string name="values" value="1, nan"/></phase>', 4, "finite"),
    "tabphase not a number": ('<phase type="tabphase">\n<string name="values" value="1, x2"/></phase>', 4,
                              "'x2' is not a number"),
    "tabphase all zero": ('<phase type="tabphase">\n<string name="values" value="0 0 0"/></phase>', 4,
                          "all zero"),
    "tabphase without values": ('<phase type="tabphase"/>', 3, "missing required parameter 'values'"),
    "tabphase values as float": ('<phase type="tabphase">\n<float name="values" value="1"/></phase>', 4,
                                 "<string>"),
    "blend weight above one": ('<phase type="blendphase">\n<float name="weight" value="1.5"/>'
                               '<phase type="isotropic"/><phase type="rayleigh"/></phase>', 4, "[0, 1]", "1.5"),
    "blend of one": ('<phase type="blendphase"><phase type="isotropic"/></phase>', 3, "exactly two", "found 1"),
    "blend of three": ('<phase type="blendphase"><phase type="isotropic"/><phase type="isotropic"/>'
                       '<phase type="isotropic"/></phase>', 3, "exactly two", "found 3"),
    "blend weight volume": ('<phase type="blendphase">\n<volume type="constvolume" name="weight"/>'
                            '<phase type="isotropic"/><phase type="rayleigh"/></phase>', 4, "spatially varying"),
    "mie diameter zero": ('<phase type="volcl_mie">\n<float name="diameter" value="0"/></phase>', 4,
                          "0 < diameter <= 50"),
    "mie diameter too large": ('<phase type="volcl_mie">\n<float name="diameter" value="80"/></phase>', 4,
                               "80", "0 < diameter <= 50"),
    "ff mu alone": ('<phase type="volcl_fournierforand"><float name="mu" value="3.5"/></phase>', 3,
                    "'backscatter'", "'n' and 'mu'"),
    "ff all three": ('<phase type="volcl_fournierforand"><float name="mu" value="3.5"/><float name="n" value="1.1"/>'
                     '<float name="backscatter" value="0.1"/></phase>', 3, "got backscatter, mu, n"),
    "ff mu out of range": ('<phase type="volcl_fournierforand"><float name="n" value="1.1"/>\n'
                           '<float name="mu" value="5.5"/></phase>', 4, "3.001 <= mu <= 5"),
    "ff n out of range": ('<phase type="volcl_fournierforand">\n<float name="n" value="0.9"/>'
                          '<float name="mu" value="4"/></phase>', 4, "1 < n <= 3"),
    "ff backscatter too large": ('<phase type="volcl_fournierforand">\n<float name="backscatter" value="0.7"/>'
                                 '</phase>', 4, "backscatter <= 0.5", "Mobley"),
    "ff backscatter zero with n": ('<phase type="volcl_fournierforand">\n<float name="backscatter" value="0"/>'
                                   '<float name="n" value="1.2"/></phase>', 4, "n = 1.2", "<= backscatter"),
    "unknown phase": ('<phase type="sggx"/>', 3, "'sggx'", "blendphase", "rayleigh", "tabphase", "volcl_mie"),
    "doublehg is blendphase": ('<phase type="volcl_doublehg"/>', 3, "'volcl_doublehg'", "blendphase"),
}


@pytest.mark.parametrize("body, line, fragments", [(b, line, f) for b, line, *f in CASES.values()],
                         ids=list(CASES))
def test_phase_errors(tmp_path, body, line, fragments):
    expect_error(tmp_path, body, line, *fragments)


# -- fuzzing: any tree of phase elements loads and packs into finite records, or raises VolclError

LEAVES = {
    "isotropic": [],
    "rayleigh": [],
    "hg": [("float", "g", ["0.999", "-0.999", "0", "1e-6", "1", "0.5"])],
    "volcl_draine": [("float", "g", ["0.9", "-0.99", "0"]), ("float", "alpha", ["0", "1", "250", "1e6", "-1", "1e7"])],
    "volcl_cornetteshanks": [("float", "g", ["0.5", "-0.9999", "1.5"])],
    "tabphase": [("string", "values", ["1 2", "0, 1, 0", "1", "-1 2", "1e38 1e38", "0 0", "1,,2, 3e-30"])],
    "volcl_fournierforand": [("float", "backscatter", ["0.0183", "1e-7", "0.5", "0.6", "1e-3"]),
                             ("float", "n", ["1.1", "1.0001", "3", "1"]), ("float", "mu", ["3.001", "5", "3.5", "2"])],
    "volcl_mie": [("float", "diameter", ["1e-6", "0.1", "1.5", "5", "50", "0", "51"])],
}


@st.composite
def phase_xml(draw, depth=0):
    kind = draw(st.sampled_from(list(LEAVES) + (["blendphase"] * 3 if depth < 3 else [])))
    if kind == "blendphase":
        parts = []
        if draw(st.booleans()):
            parts.append(f'<float name="weight" value="{draw(st.sampled_from(["0", "1", "0.3", "1e-9", "2"]))}"/>')
        count = draw(st.sampled_from([2, 2, 2, 1, 3]))
        parts += [draw(phase_xml(depth + 1)) for _ in range(count)]
        return f'<phase type="blendphase">{"".join(parts)}</phase>'
    props = [f'<{tag} name="{name}" value="{draw(st.sampled_from(values))}"/>'
             for tag, name, values in LEAVES[kind] if draw(st.booleans())]
    return f'<phase type="{kind}">{"".join(props)}</phase>'


@settings(max_examples=120, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(phase_xml())
def test_phase_trees_load_and_pack_or_raise_volclerror(tmp_path_factory, body):
    path = tmp_path_factory.mktemp("phase") / "phase.xml"
    path.write_text(SCENE.format(body))
    try:
        sc = load(path)
    except VolclError:
        return
    p = pack(sc)
    lobes, tables = p.arrays["phase_lobes"], p.arrays["phase_tables"]
    assert np.isfinite(lobes["p"]).all() and np.isfinite(lobes["weight"]).all() and np.isfinite(tables).all()
    m = p.arrays["media"][0]
    if m["phase"] == 2:
        w = lobes["weight"][m["phase_lobe"]:m["phase_lobe"] + m["phase_lobe_count"]]
        assert (w > 0).all() and abs(w.sum() - 1) < 1e-6


@pytest.mark.parametrize("phase", [Phase("draine", 0.2, alpha=-1.0), Phase("mie", diameter=0.0),
                                   Phase("fournier_forand", n=1.1, mu=2.5), Phase("tabulated", values=np.array([1.0])),
                                   Phase("blend", weight=0.5, phases=(Phase("hg", 1.5), Phase()))],
                         ids=["draine alpha", "mie diameter", "ff mu", "tabulated one value", "blend of a bad hg"])
def test_phases_built_in_python_are_checked_when_packed(phase):
    with pytest.raises(ValueError, match="outside|at least 2"):
        ph.PhasePacker().add(phase)
