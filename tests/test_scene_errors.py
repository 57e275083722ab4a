"""Every kind of user error: a VolclError whose message names the file, the line and the culprit."""
import time

import numpy as np
import pytest

from volcl.errors import VolclError
from volcl.scene import load
from volcl.scene.volfile import write_vol

M = '<scene version="3.0.0">\n{}\n</scene>\n'      # body starts on line 2
N = '<scene>\n{}\n</scene>\n'
NORI_OK = '<integrator type="path_mis"/><camera type="perspective"/>'


def expect_error(tmp_path, text: str, line, *fragments, defines=None, name="scene.xml", scene=None):
    """`name`: the file the message must name (the scene, unless `scene` names the scene file)."""
    path = tmp_path / (scene or name)
    path.write_text(text)
    with pytest.raises(VolclError) as info:
        load(path, defines)
    message = str(info.value)
    assert name in message, message
    if line is not None:
        assert f"{name}:{line}:" in message, message
    for fragment in fragments:
        assert fragment in message, message
    return message


MITSUBA_CASES = {
    "unknown element": ('<foo/>', 2, "<foo>", "supported here", "<shape>"),
    "unknown element in shape": ('<shape type="cube">\n<texture type="bitmap"/>\n</shape>', 3,
                                 "<texture>", "<bsdf>", "<emitter>", "<medium>"),
    "unknown plugin type": ('<shape type="cube">\n<bsdf type="principled"/>\n</shape>', 3,
                            "'principled'", "conductor, dielectric, diffuse, mask, normalmap, null, plastic, "
                            "roughconductor, roughdielectric, roughplastic, thindielectric, twosided"),
    "unknown shape type": ('<shape type="bsplinecurve"/>', 2, "'bsplinecurve'", "obj", "serialized", "sphere"),
    "unknown parameter": ('<bsdf type="diffuse">\n<float name="roughness" value="0.1"/>\n</bsdf>',
                          3, "'roughness'", "supported: reflectance"),
    "string where float": ('<sensor type="perspective">\n<string name="fov" value="wide"/>\n'
                           '</sensor>', 3, "'fov'", "<float>", "<string>"),
    "abc as float": ('<sensor type="perspective"><float name="fov" value="abc"/></sensor>', 2,
                     "'abc'", "not a finite number"),
    "non-finite float": ('<shape type="cube"><emitter type="area"><rgb name="radiance" '
                         'value="inf"/></emitter></shape>', 2, "'inf'"),
    "rgb with two values": ('<bsdf type="diffuse"><rgb name="reflectance" value="0.1, 0.2"/>'
                            '</bsdf>', 2, "'0.1, 0.2'", "1 or 3"),
    "spectrum two values": ('<bsdf type="diffuse"><spectrum name="reflectance" value="0.1 0.2"/>'
                            '</bsdf>', 2, "'0.1'", "wavelength:value pair"),
    "spectrum one pair": ('<bsdf type="diffuse"><spectrum name="reflectance" value="400:0.1"/>'
                          '</bsdf>', 2, "at least two"),
    "spectrum decreasing": ('<bsdf type="diffuse"><spectrum name="reflectance" value="500:0.1, 400:0.2"/>'
                            '</bsdf>', 2, "must increase"),
    "spectrum bad number": ('<bsdf type="diffuse"><spectrum name="reflectance" value="400:x, 500:1"/>'
                            '</bsdf>', 2, "'x'"),
    "spectrum value and file": ('<bsdf type="diffuse"><spectrum name="reflectance" value="1" '
                                'filename="a.spd"/></bsdf>', 2, "not both"),
    "spectrum file missing": ('<bsdf type="diffuse">\n<spectrum name="reflectance" filename="a.spd"/>'
                              '</bsdf>', 3, "'a.spd'", "not found"),
    "unknown spectrum type": ('<bsdf type="diffuse"><spectrum type="d75" name="reflectance"/></bsdf>',
                              2, "'d75'", "blackbody"),
    "blackbody reflectance": ('<bsdf type="diffuse">\n<spectrum type="blackbody" name="reflectance">'
                              '<float name="temperature" value="3000"/></spectrum></bsdf>', 3,
                              "only meaningful as emission"),
    "blackbody without temperature": ('<shape type="cube"><emitter type="area">\n<spectrum type="blackbody" '
                                      'name="radiance"/></emitter></shape>', 3, "'temperature'"),
    "bad point": ('<shape type="sphere"><point name="center" value="1, 2"/></shape>', 2,
                  "'1, 2'"),
    "bad boolean": ('<shape type="cube"><boolean name="flip_normals" value="yes"/></shape>', 2,
                    "'yes'", "true or false"),
    "bad integer": ('<integrator type="path"><integer name="max_depth" value="1.5"/>'
                    '</integrator>', 2, "'1.5'", "not an integer"),
    "huge integer": ('<integrator type="path"><integer name="max_depth" value="99999999999"/>'
                     '</integrator>', 2, "99999999999", "32-bit"),
    "very long integer": ('<integrator type="path"><integer name="max_depth" value="%s"/>'
                          '</integrator>' % ("9" * 5000), 2, "32-bit"),
    "non-ascii digit": ('<integrator type="path"><integer name="max_depth" value="\u0663"/>'
                        '</integrator>', 2, "not an integer"),
    "undefined parameter": ('<integrator type="path">\n<integer name="max_depth" value="$depth"/>'
                            '\n</integrator>', 3, "$depth"),
    "ref to unknown id": ('<shape type="cube">\n<ref id="nope"/>\n</shape>', 3, "'nope'"),
    "reference cycle": ('<bsdf type="twosided" id="a">\n<ref id="b"/></bsdf>'
                        '<bsdf type="twosided" id="b"><ref id="a"/></bsdf>', 3, "circular reference",
                        "a -> b -> a"),
    "alias to unknown id": ('<alias id="nope" as="x"/>', 2, "alias source id 'nope'"),
    "alias onto existing id": ('<bsdf type="diffuse" id="a"/><bsdf type="diffuse" id="b"/>\n'
                               '<alias id="a" as="b"/>', 3, "'b' already exists"),
    "path outside the root": ('<shape type="cube">\n<path value="."/></shape>', 3, "<path>",
                              "directly inside"),
    "missing path folder": ('<path value="nowhere"/>', 2, "'nowhere'", "not found"),
    "missing include": ('<include filename="nowhere.xml"/>', 2, "'nowhere.xml'", "not found"),
    "instance of an unknown group": ('<shape type="instance"><ref id="g"/></shape>', 2, "unknown id 'g'"),
    "nested shapegroup": ('<shape type="shapegroup" id="g">\n<shape type="shapegroup" id="h"><shape type="cube"/>'
                          '</shape></shape>', 3, "Nested ShapeGroup", "outer group"),
    "instance inside a shapegroup": ('<shape type="shapegroup" id="g"><shape type="cube"/></shape><shape type="shapegroup" id="h">\n<shape type="instance">'
                                     '<ref id="g"/></shape></shape>', 3, "Nested instancing"),
    "emitter inside a shapegroup": ('<shape type="shapegroup" id="g">\n<shape type="cube"><emitter type="area"/>'
                                    '</shape></shape>', 3, "Instancing of emitters", "directly in the scene"),
    "bsdf directly in a shapegroup": ('<shape type="shapegroup" id="g"><shape type="cube"/>\n<bsdf type="diffuse"/>'
                                      '</shape>', 3, "holds shapes only"),
    "instance without a group": ('<shape type="instance">\n</shape>', 2, "must be specified", "<ref id="),
    "instance of a plain shape": ('<shape type="instance">\n<shape type="cube"/></shape>', 3,
                                  "Only a shapegroup can be specified"),
    "instance of two groups": ('<shape type="shapegroup" id="g"><shape type="cube"/></shape><shape type="shapegroup" id="h"><shape type="cube"/></shape>'
                               '<shape type="instance"><ref id="g"/>\n<ref id="h"/></shape>', 3,
                               "Only a single shapegroup"),
    "singular instance": ('<shape type="shapegroup" id="g"><shape type="cube"/></shape><shape type="instance"><ref id="g"/>\n<transform name="to_world">'
                          '<scale x="0"/></transform></shape>', 3, "singular"),
    "direct with media": ('<integrator type="direct"/>\n<shape type="cube"><bsdf type="null"/>'
                          '<medium type="homogeneous" name="interior"/></shape>', 1, "direct",
                          "ignores media", "volpath"),
    "direct without samples": ('<integrator type="direct"><integer name="emitter_samples" value="0"/>'
                               '<integer name="bsdf_samples" value="0"/></integrator>', 2,
                               "at least one"),
    "direct shading_samples twice": ('<integrator type="direct"><integer name="emitter_samples" value="1"/>'
                                     '<integer name="shading_samples" value="2"/></integrator>', 2,
                                     "not both"),
    "empty moment": ('<integrator type="moment"/>', 2, "wraps an integrator"),
    "fov and focal_length": ('<sensor type="perspective"><float name="fov" value="30"/>'
                             '<string name="focal_length" value="35mm"/></sensor>', 2, "not both"),
    "bad focal_length": ('<sensor type="perspective"><string name="focal_length" value="wide"/></sensor>',
                         2, "'wide'", "millimetres"),
    "thinlens without aperture": ('<sensor type="thinlens"/>', 2, "'aperture_radius'"),
    "cylinder of zero length": ('<shape type="cylinder"><point name="p1" value="0, 0, 0"/></shape>', 2,
                                "coincide"),
    "serialized index out of range": ('<shape type="serialized"><string name="filename" value="m.serialized"/>'
                                      '\n<integer name="shape_index" value="-1"/></shape>', 3, ">= 0"),
    "wrap mode": ('<medium type="heterogeneous"><volume type="gridvolume" name="sigma_t">\n'
                  '<string name="wrap_mode" value="repeat"/></volume></medium>', 3, "'repeat'", "clamp"),
    "duplicate id": ('<bsdf type="diffuse" id="a"/>\n<bsdf type="null" id="a"/>', 3,
                     "duplicate id 'a'", "line 2"),
    "ref of the wrong kind": ('<bsdf type="diffuse" id="b"/>\n<sensor type="perspective">'
                              '<ref id="b"/></sensor>', 3, "bsdf is not allowed inside",
                              "perspective"),
    "ref at scene level": ('<bsdf type="diffuse" id="b"/>\n<ref id="b"/>', 3, "<ref>"),
    "missing mesh file": ('<shape type="obj">\n<string name="filename" value="missing.obj"/>\n'
                          '</shape>', 3, "missing.obj", "not found"),
    "sphere non-uniform scale": ('<shape type="sphere">\n<transform name="to_world">'
                                 '<scale value="1, 2, 1"/></transform>\n</shape>', 3,
                                 "similarity", "non-uniform"),
    "negative radiance": ('<shape type="cube"><emitter type="area">\n<rgb name="radiance" '
                          'value="-1"/></emitter></shape>', 3, "'radiance' must be >= 0"),
    "negative intensity": ('<emitter type="point"><rgb name="intensity" value="1 -1 1"/>'
                           '</emitter>', 2, "'intensity'", ">= 0"),
    "albedo above one": ('<medium type="homogeneous">\n<float name="albedo" value="1.5"/>'
                         '</medium>', 3, "'albedo'", "[0, 1]"),
    "negative sigma_t": ('<medium type="homogeneous"><rgb name="sigma_t" value="1, -2, 1"/>'
                         '</medium>', 2, "'sigma_t'", ">= 0"),
    "g out of range": ('<medium type="homogeneous"><phase type="hg">\n<float name="g" '
                       'value="1"/></phase></medium>', 3, "-1 < g < 1"),
    "scale not positive": ('<medium type="homogeneous"><float name="scale" value="0"/>'
                           '</medium>', 2, "'scale' must be > 0"),
    "twosided with two bsdfs": ('<bsdf type="twosided">\n<bsdf type="diffuse"/>'
                                '<bsdf type="diffuse"/></bsdf>', 2, "exactly one"),
    "twosided dielectric": ('<bsdf type="twosided">\n<bsdf type="dielectric"/></bsdf>', 3,
                            "dielectric", "transmission"),
    "unknown conductor material": ('<bsdf type="conductor"><string name="material" value="Unobtainium"/></bsdf>', 2,
                                   "'Unobtainium'", "Au, Be", '"none"'),
    "unknown ior name": ('<bsdf type="dielectric"><string name="int_ior" value="glass"/></bsdf>',
                         2, "'glass'", "bk7", "acrylic glass", "polypropylene"),
    "point emitter in shape": ('<shape type="cube">\n<emitter type="point"/></shape>', 3,
                               "only an area emitter"),
    "medium without interior name": ('<shape type="cube">\n<medium type="homogeneous"/></shape>',
                                     3, "interior", "exterior"),
    "two interiors": ('<shape type="cube"><medium type="homogeneous" name="interior"/>\n'
                      '<medium type="homogeneous" name="interior"/></shape>', 3, "already"),
    "two integrators": ('<integrator type="path"/>\n<integrator type="path"/>', 3,
                        "at most one integrator"),
    "unknown transform op": ('<shape type="cube"><transform name="to_world">\n<shear/>'
                             '</transform></shape>', 3, "<shear>", "lookat"),
    "singular transform": ('<shape type="cube">\n<transform name="to_world"><scale value="0"/>'
                           '</transform></shape>', 3, "singular"),
    "lookat origin is target": ('<sensor type="perspective"><transform name="to_world">\n'
                                '<lookat origin="1,1,1" target="1,1,1"/></transform></sensor>',
                                3, "coincide"),
    "lookat up parallel": ('<sensor type="perspective"><transform name="to_world">\n'
                           '<lookat origin="0,0,0" target="0,1,0" up="0,2,0"/></transform>'
                           '</sensor>', 3, "parallel"),
    "rotate zero axis": ('<shape type="cube"><transform name="to_world">\n'
                         '<rotate angle="30"/></transform></shape>', 3, "axis is zero"),
    "rotate without angle": ('<shape type="cube"><transform name="to_world">\n'
                             '<rotate x="1"/></transform></shape>', 3, "'angle'"),
    "matrix wrong count": ('<shape type="cube"><transform name="to_world">\n'
                           '<matrix value="1 2 3"/></transform></shape>', 3, "16 or 9"),
    "matrix not affine": ('<shape type="cube"><transform name="to_world">\n'
                          '<matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1"/></transform></shape>',
                          3, "affine"),
    "text content": ('<shape type="cube">\n\n  hello\n</shape>', 4, "unexpected text", "hello"),
    "missing type": ('<shape/>', 2, "missing attribute 'type'", "cube"),
    "unknown attribute": ('<sensor type="perspective"><float name="fov" value="1" units="deg"/>'
                          '</sensor>', 2, "'units'"),
    "unknown object attribute": ('<shape type="cube" size="2"/>', 2, "'size'"),
    "default not at top level": ('<shape type="cube">\n<default name="a" value="1"/></shape>', 3,
                                 "<default>"),
    "fov out of range": ('<sensor type="perspective"><float name="fov" value="180"/></sensor>', 2,
                         "between 0 and 180"),
    "film width zero": ('<sensor type="perspective"><film type="hdrfilm">\n'
                        '<integer name="width" value="0"/></film></sensor>', 3, "width"),
    "unknown film": ('<sensor type="perspective">\n<film type="specfilm"/></sensor>', 3,
                     "'specfilm'", "hdrfilm"),
    "unknown sampler": ('<sensor type="perspective">\n<sampler type="sobol"/></sensor>', 3,
                        "'sobol'", "independent"),
    "unknown fov_axis": ('<sensor type="perspective"><float name="fov" value="30"/>\n'
                         '<string name="fov_axis" value="z"/></sensor>', 3, "'z'", "diagonal"),
    "near clip beyond far": ('<sensor type="perspective"><float name="near_clip" value="10"/>\n'
                             '<float name="far_clip" value="1"/></sensor>', 3, "far clip"),
    "sample count zero": ('<sensor type="perspective"><sampler type="independent">\n'
                          '<integer name="sample_count" value="0"/></sampler></sensor>', 3,
                          "'sample_count' must be >= 1"),
    "max_depth below -1": ('<integrator type="path"><integer name="max_depth" value="-2"/>'
                           '</integrator>', 2, "'max_depth'"),
    "parameter given twice": ('<bsdf type="diffuse"><float name="reflectance" value="0.1"/>\n'
                              '<float name="reflectance" value="0.2"/></bsdf>', 3, "twice"),
    "position and to_world": ('<emitter type="point"><point name="position" value="0,0,0"/>'
                              '\n<transform name="to_world"/></emitter>', 3, "not both"),
    "zero direction": ('<emitter type="directional">\n<vector name="direction" value="0,0,0"/>'
                       '</emitter>', 3, "zero vector"),
    "volume with a wrong name": ('<medium type="heterogeneous">\n<volume type="constvolume" '
                                 'name="density"/></medium>', 3, "sigma_t", "albedo"),
    "volume in homogeneous": ('<medium type="homogeneous">\n<volume type="constvolume" '
                              'name="sigma_t"/></medium>', 3, "not allowed"),
    "color in mitsuba": ('<bsdf type="diffuse">\n<color name="reflectance" value="1"/></bsdf>', 3,
                         "<color>", "<rgb>"),
    "fov_axis without fov": ('<sensor type="perspective">\n<string name="fov_axis" value="y"/>'
                             '</sensor>', 3, "'fov'"),
    "sphere beyond float range": ('<shape type="sphere"><float name="radius" value="1e38"/>\n'
                                  '<transform name="to_world"><scale value="10"/></transform>'
                                  '</shape>', 3, "floating-point range"),
    "float beyond float32": ('<bsdf type="diffuse">\n<float name="reflectance" value="1e39"/></bsdf>',
                             3, "'1e39'", "single-precision"),
    "nan coefficient": ('<medium type="homogeneous">\n<rgb name="sigma_t" value="1, nan, 1"/></medium>',
                        3, "'nan'", "not a finite number"),
    "infinite albedo": ('<medium type="homogeneous">\n<float name="albedo" value="-inf"/></medium>',
                        3, "'-inf'", "not a finite number"),
    "negative scalar sigma_t": ('<medium type="homogeneous">\n<float name="sigma_t" value="-0.5"/>'
                                '</medium>', 3, "'sigma_t' must be >= 0", "-0.5"),
    "sigma_t times scale overflows": ('<medium type="homogeneous">\n<float name="sigma_t" value="1e38"/>'
                                      '<float name="scale" value="10"/></medium>', 2, "sigma_t (times scale)",
                                      "1e+39", "single-precision"),
    "emission overflows": ('<medium type="homogeneous">\n<float name="sigma_t" value="1e30"/>'
                           '<rgb name="volcl_radiance" value="1e10"/></medium>', 2, "emission", "1e+40"),
    "g of minus one": ('<medium type="homogeneous"><phase type="hg">\n<float name="g" '
                       'value="-1"/></phase></medium>', 3, "'g' = -1.0", "-1 < g < 1"),
    "g above one": ('<medium type="homogeneous"><phase type="hg">\n<float name="g" '
                    'value="1.5"/></phase></medium>', 3, "1.5", "-1 < g < 1"),

    "scaled camera": ('<sensor type="perspective">\n<transform name="to_world">'
                      '<scale value="2"/></transform></sensor>', 3, "not scale"),
    "nested scene": ('<scene version="3.0.0"/>', 2, "<scene>"),
}


@pytest.mark.parametrize("body, line, fragments",
                         [(b, line, f) for b, line, *f in MITSUBA_CASES.values()],
                         ids=list(MITSUBA_CASES))
def test_mitsuba_errors(tmp_path, body, line, fragments):
    expect_error(tmp_path, M.format(body), line, *fragments)


NORI_CASES = {
    "missing camera": ('<integrator type="path_mis"/>', 1, "needs a <camera>"),
    "missing integrator": ('<camera type="perspective"/>', 1, "needs an <integrator>",
                           "path_mis"),
    "unknown integrator": ('<integrator type="photon"/>', 2, "'photon'", "path_mis", "whitted"),
    "medium with sigma_t and sigma_a": (NORI_OK + '\n<medium type="homogeneous">'
                                        '<float name="sigma_s" value="1"/>'
                                        '<float name="sigma_t" value="1"/>'
                                        '<float name="sigma_a" value="1"/></medium>', 3,
                                        "exactly one"),
    "sigma_s above sigma_t": (NORI_OK + '<medium type="homogeneous">'
                              '<float name="sigma_s" value="2"/>\n'
                              '<float name="sigma_t" value="1"/></medium>', 3, "exceeds"),
    "medium g out of range": (NORI_OK + '<medium type="homogeneous">'
                              '<float name="sigma_s" value="1"/><float name="sigma_a" value="1"/>'
                              '\n<float name="g" value="-1.5"/></medium>', 3, "-1 < g < 1"),
    "point without power": (NORI_OK + '\n<emitter type="point"/>', 3,
                            "missing required parameter 'power'"),
    "area without radiance": (NORI_OK + '<mesh type="obj"><string name="filename" '
                              'value="t.obj"/>\n<emitter type="area"/></mesh>', 3,
                              "'radiance'"),
    "rgb in nori": (NORI_OK + '<mesh type="obj"><bsdf type="diffuse">\n<rgb name="albedo" '
                    'value="1"/></bsdf></mesh>', 3, "<rgb>", "<color>"),
    "mesh type ply": (NORI_OK + '\n<mesh type="ply"/>', 3, "'ply'", "obj"),
    "two media": (NORI_OK + '<medium type="homogeneous"><float name="sigma_s" value="1"/>'
                  '<float name="sigma_a" value="1"/></medium>\n'
                  '<medium type="homogeneous"><float name="sigma_s" value="1"/>'
                  '<float name="sigma_a" value="1"/></medium>', 3, "at most one medium"),
    "nori sampler": (NORI_OK + '\n<sampler type="stratified"/>', 3, "'stratified'"),
    "scaled nori camera": ('<integrator type="path_mis"/><camera type="perspective">\n'
                           '<transform name="toWorld"><scale value="1, 1, 3"/></transform>'
                           '</camera>', 3, "not scale"),
    "camera width zero": ('<integrator type="path_mis"/><camera type="perspective">\n'
                          '<integer name="width" value="0"/></camera>', 3, "width"),
}


@pytest.mark.parametrize("body, line, fragments",
                         [(b, line, f) for b, line, *f in NORI_CASES.values()],
                         ids=list(NORI_CASES))
def test_nori_errors(tmp_path, body, line, fragments):
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    expect_error(tmp_path, N.format(body), line, *fragments)


def test_nori_scene_attribute(tmp_path):
    expect_error(tmp_path, '<scene id="x"/>', 1, "'id'")


def test_ttest_count_mismatch(tmp_path):
    scene = f'<scene>{NORI_OK}</scene>'
    text = (f'<test type="ttest">\n<string name="references" value="1, 2"/>\n{scene}\n</test>')
    expect_error(tmp_path, text, 2, "2 references for 1 scenes")


def test_ttest_bad_reference(tmp_path):
    text = f'<test type="ttest">\n<string name="references" value="1, x"/><scene>{NORI_OK}</scene></test>'
    expect_error(tmp_path, text, 2, "'x'")


# -- XML-level problems ------------------------------------------------------------------------

def test_malformed_xml(tmp_path):
    expect_error(tmp_path, '<scene version="3.0.0">\n<shape type="cube">\n</scene>\n', 3,
                 "malformed XML", "mismatched tag")


def test_empty_file(tmp_path):
    expect_error(tmp_path, "", 1, "malformed XML")


def test_doctype_is_rejected(tmp_path):
    text = '<?xml version="1.0"?>\n<!DOCTYPE scene>\n<scene version="3.0.0"/>\n'
    expect_error(tmp_path, text, 2, "DOCTYPE")


def test_external_entity_is_rejected(tmp_path):
    text = ('<?xml version="1.0"?>\n<!DOCTYPE scene [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n'
            '<scene version="3.0.0"><string name="a" value="&x;"/></scene>\n')
    expect_error(tmp_path, text, 2, "DOCTYPE")


def test_billion_laughs_is_rejected_quickly(tmp_path):
    lines = ['<?xml version="1.0"?>', '<!DOCTYPE lolz [', ' <!ENTITY lol "lol">']
    lines += [f' <!ENTITY lol{i} "{("&lol" + str(i - 1) + ";") * 10 if i > 1 else "&lol;" * 10}">'
              for i in range(1, 10)]
    lines += [']>', '<scene version="3.0.0"><default name="a" value="&lol9;"/></scene>']
    start = time.perf_counter()
    expect_error(tmp_path, "\n".join(lines), 2, "DOCTYPE")
    assert time.perf_counter() - start < 1.0


def test_undeclared_entity_reference(tmp_path):
    expect_error(tmp_path, '<scene version="3.0.0">\n<foo a="&x;"/></scene>', 2, "undefined entity")


def test_parameter_expansion_bomb_is_rejected(tmp_path):
    defaults = ['<default name="a0" value="xxxxxxxxxx"/>']
    defaults += [f'<default name="a{i}" value="{("$a" + str(i - 1)) * 10}"/>' for i in range(1, 9)]
    text = M.format("\n".join(defaults))
    start = time.perf_counter()
    expect_error(tmp_path, text, None, "longer than")
    assert time.perf_counter() - start < 1.0


def test_deep_nesting(tmp_path):
    body = '<bsdf type="twosided">' * 100 + '<bsdf type="diffuse"/>' + '</bsdf>' * 100
    expect_error(tmp_path, M.format(body), 2, "nested more than")


def test_wrong_root(tmp_path):
    expect_error(tmp_path, '<html/>', 1, "root element", "<html>")


def test_newer_mitsuba_version(tmp_path):
    expect_error(tmp_path, '<scene version="4.0.0"/>', 1, "'4.0.0'", "newer than Mitsuba 3")


def test_bad_version(tmp_path):
    expect_error(tmp_path, '<scene version="three"/>', 1, "'three'", "invalid version")


def test_errors_in_included_files_name_that_file(tmp_path):
    (tmp_path / "part.xml").write_text('<scene version="2.0.0">\n\n<bsdf type="principled"/>\n</scene>\n')
    expect_error(tmp_path, M.format('<include filename="part.xml"/>'), 3, "'principled'", name="part.xml",
                 scene="scene.xml")


def test_include_cycle(tmp_path):
    (tmp_path / "part.xml").write_text('<scene version="3.0.0">\n<include filename="scene.xml"/>\n</scene>\n')
    message = expect_error(tmp_path, M.format('<include filename="part.xml"/>'), None, "cycle",
                           "scene.xml -> part.xml -> scene.xml")
    assert "part.xml:2:" in message, message


def test_included_file_needs_a_version(tmp_path):
    (tmp_path / "part.xml").write_text('<scene>\n</scene>\n')
    message = expect_error(tmp_path, M.format('<include filename="part.xml"/>'), None, "version",
                           "included from")
    assert "part.xml:1:" in message, message


def test_duplicate_id_across_files(tmp_path):
    (tmp_path / "part.xml").write_text('<scene version="3.0.0">\n<bsdf type="diffuse" id="a"/>\n</scene>\n')
    message = expect_error(tmp_path, M.format('<bsdf type="diffuse" id="a"/>\n<include filename="part.xml"/>'),
                           None, "duplicate id 'a'", "scene.xml:2")
    assert "part.xml:2:" in message, message


def test_missing_scene_file(tmp_path):
    with pytest.raises(VolclError, match="absent.xml"):
        load(tmp_path / "absent.xml")


# -- problems in referenced files --------------------------------------------------------------

def _mesh_scene(tmp_path, mesh_name: str, mesh_text: str, kind: str = "obj") -> str:
    (tmp_path / mesh_name).write_text(mesh_text)
    return M.format(f'<shape type="{kind}">\n<string name="filename" value="{mesh_name}"/>'
                    '</shape>')


@pytest.mark.parametrize("mesh_name, text, kind, fragment", [
    ("empty.obj", "# nothing\n", "obj", "empty"),
    ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "obj", "non-finite"),
    ("bad.ply", "not a ply file\n", "ply", "cannot parse PLY"),
    ("index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "obj", "index missing vertices"),
])
def test_bad_mesh_files(tmp_path, mesh_name, text, kind, fragment):
    message = expect_error(tmp_path, _mesh_scene(tmp_path, mesh_name, text, kind), 3, fragment)
    assert mesh_name in message


def test_bad_vol_file_names_scene_and_volume(tmp_path):
    (tmp_path / "bad.vol").write_bytes(b"XYZ" + bytes(100))
    body = ('<medium type="heterogeneous">\n<volume type="gridvolume" name="sigma_t">\n'
            '<string name="filename" value="bad.vol"/></volume></medium>')
    message = expect_error(tmp_path, M.format(body), 4, "bad.vol", "b'XYZ'")
    assert "not a valid Mitsuba .vol file" in message


def test_albedo_grid_above_one(tmp_path):
    write_vol(tmp_path / "albedo.vol", np.full((2, 2, 2), 1.5))
    body = ('<medium type="heterogeneous">\n<volume type="gridvolume" name="albedo">'
            '<string name="filename" value="albedo.vol"/></volume></medium>')
    expect_error(tmp_path, M.format(body), 3, "'albedo' values must be in [0, 1]", "albedo.vol")


# -- shapes that cannot do what their emitter or medium needs ------------------------------------

CLOSED_TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


@pytest.mark.parametrize("mesh_text, fragments", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ["not closed", "3 edges border only one triangle"]),
    (CLOSED_TETRA.replace("f 2 3 4\n", ""), ["not closed", "3 edges border only one triangle"]),
    (CLOSED_TETRA + "f 2 3 4\n", ["not closed", "shared by more than two triangles"]),
    (CLOSED_TETRA.replace("f 2 3 4", "f 2 4 3"), ["not wound consistently"]),
    ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", ["all of its triangles have zero area"]),
], ids=["one triangle", "hole", "non-manifold", "inconsistent winding", "flat"])
def test_interior_medium_on_an_open_mesh_warns(tmp_path, mesh_text, fragments):
    """As in Mitsuba, a medium may sit inside a mesh that does not enclose it; inside and outside are
    then decided per crossing, and the warning says so."""
    (tmp_path / "part.obj").write_text(mesh_text)
    body = ('<shape type="obj" id="vessel">\n<string name="filename" value="part.obj"/>'
            '<medium type="homogeneous" name="interior"/></shape>')
    (tmp_path / "scene.xml").write_text(M.format(body))
    scene = load(tmp_path / "scene.xml")
    (warning,) = [w for w in scene.warnings if "interior medium" in w]
    for fragment in ["scene.xml:2:", "id 'vessel'", "mesh 'part.obj'", "at each crossing", *fragments]:
        assert fragment in warning, warning


@pytest.mark.parametrize("shape, fragment", [("rectangle", "4 edges border only one triangle"),
                                             ("disk", "512 edges")])
def test_interior_medium_on_a_primitive_surface_warns(tmp_path, shape, fragment):
    body = f'<shape type="{shape}">\n<medium type="homogeneous" name="interior"/></shape>'
    (tmp_path / "scene.xml").write_text(M.format(body))
    (warning,) = [w for w in load(tmp_path / "scene.xml").warnings if "interior medium" in w]
    assert "scene.xml:2:" in warning and fragment in warning and "not closed" in warning, warning


def test_closed_meshes_and_exterior_media_are_accepted(tmp_path):
    """A closed mesh (also with degenerate triangles and split corners, as OBJ groups give) may hold
    a medium; an open surface may have one outside it."""
    # a degenerate extra triangle, and a normal per face: the loader splits every corner
    faces = [line.split()[1:] for line in CLOSED_TETRA.splitlines() if line.startswith("f")]
    with_normals = "".join(line + "\n" for line in CLOSED_TETRA.splitlines() if line.startswith("v"))
    with_normals += "vn 0 0 -1\nvn 0 -1 0\nvn -1 0 0\nvn 1 1 1\nv 0.5 0 0\n"
    with_normals += "".join(f"f {a}//{i + 1} {b}//{i + 1} {c}//{i + 1}\n" for i, (a, b, c) in enumerate(faces))
    with_normals += "f 1//1 2//1 5//1\n"
    (tmp_path / "tetra.obj").write_text(with_normals)
    body = ('<medium type="homogeneous" id="fog"/>'
            '<shape type="obj"><string name="filename" value="tetra.obj"/><ref id="fog" name="interior"/></shape>'
            '<shape type="cube"><ref id="fog" name="interior"/></shape>'
            '<shape type="sphere"><ref id="fog" name="interior"/></shape>'
            '<shape type="rectangle"><ref id="fog" name="exterior"/></shape>')
    path = tmp_path / "ok.xml"
    path.write_text(M.format(body))
    scene = load(path)
    assert sum(s.interior is not None for s in scene.shapes) == 3
    assert len(scene.shapes[0].vertices) > 5        # the corners were split


def test_zero_area_emitter(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 4 4 1\n")
    body = ('<shape type="obj" id="lamp">\n<string name="filename" value="flat.obj"/>'
            '<emitter type="area"/></shape>')
    expect_error(tmp_path, M.format(body), 2, "id 'lamp'", "mesh 'flat.obj'", "area emitter",
                 "zero total area", "all 2 triangles")


def test_emitter_collapsing_in_single_precision_is_zero_area(tmp_path):
    (tmp_path / "sliver.obj").write_text("v 1 1 1\nv 1.00000000001 1 1\nv 1 1.00000000001 1\nf 1 2 3\n")
    body = ('<shape type="obj">\n<string name="filename" value="sliver.obj"/>'
            '<emitter type="area"/></shape>')
    expect_error(tmp_path, M.format(body), 2, "mesh 'sliver.obj'", "zero total area", "single precision")


def test_nori_emitter_on_zero_area_mesh(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    body = (NORI_OK + '<mesh type="obj">\n<string name="filename" value="flat.obj"/>'
            '<emitter type="area"><color name="radiance" value="1"/></emitter></mesh>')
    expect_error(tmp_path, N.format(body), 2, "mesh 'flat.obj'", "zero total area")


def test_unreadable_scene_path_is_a_clear_error(tmp_path):
    (tmp_path / "dir.xml").mkdir()
    with pytest.raises(VolclError, match="not a regular file"):
        load(tmp_path / "dir.xml")


def test_mesh_path_that_is_a_directory(tmp_path):
    (tmp_path / "dir.obj").mkdir()
    body = '<shape type="obj">\n<string name="filename" value="dir.obj"/></shape>'
    expect_error(tmp_path, M.format(body), 3, "dir.obj", "not a regular file")


# -- untrusted XML reaches nothing but the files it names ----------------------------------------

def test_xinclude_is_not_processed(tmp_path):
    expect_error(tmp_path, M.format('<xi:include href="/etc/passwd" parse="text"/>'), 2, "<xi:include>",
                 "not allowed")
    text = ('<scene version="3.0.0" xmlns:xi="http://www.w3.org/2001/XInclude">\n'
            '<xi:include href="/etc/passwd" parse="text"/></scene>')
    expect_error(tmp_path, text, 1, "unknown attribute 'xmlns:xi'")


def test_external_dtd_is_rejected(tmp_path):
    text = '<?xml version="1.0"?>\n<!DOCTYPE scene SYSTEM "http://example.com/evil.dtd">\n<scene version="3.0.0"/>'
    expect_error(tmp_path, text, 2, "DOCTYPE")


def test_parameter_entity_is_rejected(tmp_path):
    text = ('<?xml version="1.0"?>\n<!DOCTYPE s [<!ENTITY % p SYSTEM "file:///etc/passwd"> %p;]>\n'
            '<scene version="3.0.0"/>')
    expect_error(tmp_path, text, 2, "DOCTYPE")


def test_loader_opens_only_the_files_the_scene_names(tmp_path, monkeypatch):
    import builtins
    (tmp_path / "tetra.obj").write_text(CLOSED_TETRA)
    path = tmp_path / "scene.xml"
    path.write_text(M.format('<shape type="obj"><string name="filename" value="tetra.obj"/></shape>'))
    opened = []
    real_open = builtins.open

    def spy(file, *args, **kwargs):
        opened.append(str(file))
        return real_open(file, *args, **kwargs)
    monkeypatch.setattr(builtins, "open", spy)
    load(path)
    monkeypatch.undo()
    assert set(opened) == {str(path), str(tmp_path / "tetra.obj")}, opened
