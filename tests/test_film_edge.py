"""The reconstruction filter at the image's edge, against its analytic answer.

Mitsuba's hdrfilm without `sample_border` (its default, and Nori always) draws no samples outside
the film, so a pixel within the filter's radius of the edge averages only the part of its filter
that lies inside, renormalized; with `sample_border` every pixel averages its whole filter. An
orthographic camera looks at black space with an emitter of radiance 1 that ends a quarter pixel
inside one edge of the image: a pixel's value is the chance that its sample lands on the emitter,
a ratio of filter masses either way, and the render's mean over a row (or column) is a binomial
estimate of it."""
import math

import numpy as np
import pytest

import stats
import volcl
from test_sampling import filter_profile
from volcl.scene.model import Filter

pytestmark = pytest.mark.every_implementation

W, H, SPP = 24, 16, 1024
PIXEL = 2.0 / W                  # the orthographic frame spans x in [-1, 1], y in [-H/W, H/W]
INSIDE = 0.25                    # pixels of the emitter inside the image's edge


def expected(kind, radius, k, sample_border):
    """Chance that pixel k's sample (k pixels from the emitter's edge of the image) lands on the
    emitter, which covers offsets below -(k + 0.5) + INSIDE from the pixel's centre."""
    w = filter_profile(Filter(kind, radius, 0.5))
    lo = -radius if sample_border else max(-radius, -(k + 0.5))
    lit = -(k + 0.5) + INSIDE
    if lit <= lo:
        return 0.0
    return stats.integral_1d(w, lo, lit) / stats.integral_1d(w, lo, radius)


def scene_xml(axis, rfilter, sample_border):
    # image row 0 is the frame's top (+y); image column 0 is world -x (the frame's +x, seen from behind)
    if axis == "y":
        edge = H / W - INSIDE * PIXEL
        place = f'<scale x="3" y="1"/><translate y="{edge + 1.0!r}"/>'
    else:
        edge = -1.0 + INSIDE * PIXEL
        place = f'<scale x="1" y="3"/><translate x="{edge - 1.0!r}"/>'
    return f'''<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="1"/></integrator>
    <sensor type="orthographic">
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{H}"/>
            <boolean name="sample_border" value="{str(sample_border).lower()}"/>{rfilter}</film>
        <sampler type="independent"><integer name="sample_count" value="{SPP}"/></sampler>
    </sensor>
    <shape type="rectangle"><transform name="to_world">{place}</transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>'''


FILTERS = {"gaussian": ('<rfilter type="gaussian"/>', "gaussian", 2.0),
           "tent-1.5": ('<rfilter type="tent"><float name="radius" value="1.5"/></rfilter>', "tent", 1.5)}


@pytest.mark.parametrize("sample_border", [False, True], ids=["cut", "sample_border"])
@pytest.mark.parametrize("axis", ["y", "x"])
@pytest.mark.parametrize("name", list(FILTERS))
def test_pixels_at_the_edge_average_the_filter_part_mitsuba_samples(device, name, axis, sample_border):
    xml, kind, radius = FILTERS[name]
    scene = volcl.load_string(scene_xml(axis, xml, sample_border))
    assert scene.model.camera.sample_border is sample_border
    image = volcl.render(scene, seed=3, device=device).image[..., 0].astype(np.float64)
    lines = image if axis == "y" else image.T          # lines[k]: the pixels k from the lit edge
    for k in range(int(math.ceil(radius)) + 1):
        p = expected(kind, radius, k, sample_border)
        other = expected(kind, radius, k, not sample_border)
        n = lines.shape[1] * SPP
        sd = math.sqrt(max(p * (1 - p), 1.0 / n) / n)
        got = lines[k].mean()
        assert abs(got - p) < 4.5 * sd, (f"{name} {axis} line {k}: mean {got:.5f}, expected {p:.5f} "
                                         f"(sd {sd:.5f}; the other mode gives {other:.5f})")
    # the lines beyond the filter's reach see no emitter in either mode
    assert not lines[int(math.ceil(radius)) + 1:].any()
