"""The estimator choices a user can make, and what each one turns into: kernel feature flags (whether
code exists) and RenderParams fields (which code runs). README, "Estimators", gives the measurements
behind the defaults.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import VolclError
from .features import POINT_LIKE, detect
from .scene.model import Scene

EQUIANGULAR_CHOICES = ("auto", "on", "off")
EQUIANGULAR_MIS_CHOICES = ("two", "one")
# RenderParams.equiangular (kernels/types.h: EQUIANGULAR_*)
EQUIANGULAR_MODES = {"off": 0, "two": 1, "one": 2}


@dataclass(frozen=True)
class Estimator:
    nee: bool = True            # next-event estimation (light sampling)
    mis: bool = True            # combine NEE with BSDF / phase sampling (and equiangular with distance) by MIS
    equiangular: str = "auto"   # towards point and spot lights in media: 'on', 'off', or 'auto' (on for such lights inside media)
    equiangular_mis: str = "two"    # samples per segment in the equiangular / distance combination: 'two' or 'one'

    def __post_init__(self):
        if self.equiangular not in EQUIANGULAR_CHOICES:
            raise VolclError(f"equiangular {self.equiangular!r}: expected one of {', '.join(EQUIANGULAR_CHOICES)}")
        if self.equiangular_mis not in EQUIANGULAR_MIS_CHOICES:
            raise VolclError(f"equiangular MIS {self.equiangular_mis!r}: expected one of "
                             f"{', '.join(EQUIANGULAR_MIS_CHOICES)}")

    def uses_equiangular(self, scene: Scene, detected: dict | None = None) -> bool:
        """Whether this choice samples equiangularly in `scene`: 'auto' where a point light sits
        inside a medium (detected by features.detect), 'on' wherever the scene has point lights and
        media at all, never without next-event estimation (equiangular sampling is a way to sample
        light)."""
        if not self.nee or self.equiangular == "off":
            return False
        if self.equiangular == "on":
            return any(e.kind in POINT_LIKE for e in scene.emitters) and bool(scene.media)
        return bool((detected or detect(scene))["EQUIANGULAR"])

    def resolve(self, scene: Scene, features: dict | None = None, detected: dict | None = None) -> tuple[dict, dict]:
        """(feature flags to compile, RenderParams values) for `scene`. `features` overrides the
        detected flags (e.g. 'all'); the EQUIANGULAR flag then still follows this choice when it is
        on, and code that exists but is not chosen is switched off by the parameter. `detected`:
        features.detect(scene), when the caller has it already."""
        detected = detected if detected is not None else detect(scene)
        eq = self.uses_equiangular(scene, detected)
        feats = dict(detected if features is None else features)
        if features is None:
            feats["EQUIANGULAR"] = eq
        else:
            feats["EQUIANGULAR"] = bool(feats.get("EQUIANGULAR", False)) or eq
        params = {"nee": int(self.nee), "mis": int(self.mis),
                  "equiangular": EQUIANGULAR_MODES[self.equiangular_mis] if eq else 0}
        return feats, params

    def describe(self) -> str:
        eq = self.equiangular
        if self.equiangular == "on":
            eq = f"on ({self.equiangular_mis}-sample MIS)" if self.mis else "on (alone: MIS off)"
        return f"nee {'on' if self.nee else 'off'}, mis {'on' if self.mis else 'off'}, equiangular {eq}"


# The choices `volcl converge` compares, by name. Each sets every switch so that it means the same in
# every scene (`mis` is distance sampling alone even where 'auto' would add equiangular sampling).
CHOICES = {
    "mis": Estimator(nee=True, mis=True, equiangular="off"),
    "nee-only": Estimator(nee=True, mis=False, equiangular="off"),
    "bsdf-only": Estimator(nee=False, mis=False, equiangular="off"),
    "equiangular+mis": Estimator(nee=True, mis=True, equiangular="on", equiangular_mis="two"),
    "equiangular+mis-1s": Estimator(nee=True, mis=True, equiangular="on", equiangular_mis="one"),
    "equiangular-only": Estimator(nee=True, mis=False, equiangular="on"),
}


def applicable_choices(scene: Scene) -> list[str]:
    """Names of the CHOICES that estimate something different in `scene` (and converge to the
    right image): without lights a path can hit (area, environment) sampling BSDFs alone never sees
    the delta lights; without them MIS changes nothing against NEE alone; equiangular sampling needs
    point lights and media."""
    kinds = {e.kind for e in scene.emitters}
    hittable = any(s.emitter_radiance is not None for s in scene.shapes) or bool(kinds & {"constant", "envmap"})
    delta = bool(kinds & {"point", "spot", "directional"})
    out = ["mis"]
    if hittable:
        out.append("nee-only")
        if not delta:
            out.append("bsdf-only")
    if kinds & set(POINT_LIKE) and scene.media:
        out += ["equiangular+mis", "equiangular+mis-1s", "equiangular-only"]
    return out
