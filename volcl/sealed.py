"""Sealed media: media that a path can only be in while it is inside a closed surface that stops
shadow rays, with no light inside. Every shadow ray from a scattering event in such a medium ends on
that surface, so next-event estimation there always adds zero (a medium inside frosted glass lit
from outside: Mitsuba samples the light and traces the shadow ray anyway). The kernels skip it
(Medium.sealed), and the phase-sampled direction loses no MIS partner: it cannot reach a light
either before it meets the same surface.

The test is conservative. A medium is sealed only when:
- no camera starts in it and no shape names it as its exterior;
- every shape that names it as interior is a closed surface whose inside is its interior: a sphere,
  or a mesh that is closed, consistently wound and wound outwards (volcl.mesh.encloses_outward);
  not instanced, not flipped;
- every one of those shapes stops shadow rays (not null, no mask, no thin dielectric:
  volcl.pack_materials.transmits) and emits nothing;
- no point or spot light and no emitting shape has bounds that touch the bounds of those shapes
  (lights at infinity, directional and environment lights, are outside every closed surface).
Emission NEE towards emissive media is a separate estimator and is left as it is."""
from __future__ import annotations

import numpy as np

from .mesh import encloses_outward
from .pack_materials import transmits


def sealed_media(scene, media: list, bounds_of) -> list[bool]:
    """For each medium of `media` (the packer's list), whether it is sealed; `bounds_of(shape)` gives
    a shape's world bounds (lo, hi)."""
    boundaries = {id(m): [] for m in media}
    open_to = {id(scene.camera.medium)}
    for s in scene.shapes:
        if s.interior is not None:
            boundaries[id(s.interior)].append(s)
        if s.exterior is not None:
            open_to.add(id(s.exterior))
    lights = _light_bounds(scene, bounds_of)
    out = []
    for m in media:
        shapes = boundaries[id(m)]
        ok = bool(shapes) and id(m) not in open_to and all(_closed_opaque(s) for s in shapes)
        if ok:
            boxes = [bounds_of(s) for s in shapes]
            ok = not any(boxes_touch(a, b) for a in boxes for b in lights)
        out.append(ok)
    return out


def _closed_opaque(s) -> bool:
    """A closed surface around its interior that stops shadow rays and emits nothing."""
    if s.group is not None or s.flip_normals or s.emitter_radiance is not None or transmits(s.bsdf):
        return False
    if s.kind == "sphere":
        return s.radius > 0
    return s.kind == "mesh" and encloses_outward(s.vertices, s.faces)     # cylinders are open tubes


def _light_bounds(scene, bounds_of) -> list:
    """Bounds of every light that has a place in the scene: emitting shapes, point and spot lights."""
    boxes = [bounds_of(s) for s in scene.shapes if s.emitter_radiance is not None]
    for e in scene.emitters:
        if e.kind in ("point", "spot"):
            p = np.asarray(e.position, np.float64)
            boxes.append((p, p))
    return boxes


def boxes_touch(a, b) -> bool:
    """Whether boxes a and b, each (lo, hi), share a point."""
    return bool(np.all(a[0] <= b[1]) and np.all(b[0] <= a[1]))
