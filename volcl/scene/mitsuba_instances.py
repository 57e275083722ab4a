"""Mitsuba's shapegroup and instance (src/shapes/shapegroup.cpp, src/shapes/instance.cpp).

A <shape type="shapegroup"> holds shapes that are never rendered on their own; each
<shape type="instance"> names one group (a <ref> or a nested group) and places it with its own
to_world. Mitsuba 3 refuses, and so does volcl, with its words quoted: groups inside groups, instances
inside groups, emitting shapes inside groups, and anything but one group inside an instance. A
group's own to_world is ignored by Mitsuba (only the instance's counts); volcl warns and does the
same. Shapes in a group keep their bsdfs and media: a hit on an instance is a hit on the group's
shape, as in Mitsuba.
"""
from __future__ import annotations

import numpy as np

from ..errors import VolclError
from .model import Instance, Shape, ShapeGroup
from .parse_common import Node, Spec

SPECS = {
    # bsdf, emitter and medium are accepted by the table so that the error can say what to do instead
    "shapegroup": Spec({"to_world": "transform"}, children=frozenset({"shape", "bsdf", "emitter", "medium"})),
    "instance": Spec({"to_world": "transform"}, children=frozenset({"shape", "bsdf", "emitter", "medium"})),
}


def build_shapegroup(node: Node) -> ShapeGroup:
    if node.has("to_world"):
        node.ctx.warn(node.at("to_world"), "a shapegroup's to_world is ignored (as in Mitsuba 3): only the "
                                           "to_world of each instance places the group")
    group = ShapeGroup(id=node.element.attrs.get("id", ""), source=node.source())
    for child in node.children:
        if child.tag != "shape":
            raise child.element.error(f"a shapegroup holds shapes only; a <{child.tag}> directly inside it "
                                      f"has nothing to apply to (Mitsuba 3 refuses it too): put it inside a "
                                      f"shape of the group")
        obj = child.obj
        if isinstance(obj, ShapeGroup):
            raise child.element.error("a shapegroup inside a shapegroup (Mitsuba 3: \"Nested ShapeGroup is not "
                                      "permitted\"); put the inner group's shapes in the outer group")
        if isinstance(obj, Instance):
            raise child.element.error("an instance inside a shapegroup (Mitsuba 3: \"Nested instancing is not "
                                      "permitted\"); instance the shapes' group directly from the scene")
        if obj.emitter_radiance is not None:
            raise child.element.error("an emitting shape inside a shapegroup (Mitsuba 3: \"Instancing of "
                                      "emitters is not supported\"); place emitting shapes directly in the "
                                      "scene")
        if obj.group is not None and obj.group is not group:
            raise child.element.error(f"this shape is already in the shapegroup of {obj.group.source}; a shape "
                                      f"belongs to one group (give each group its own copy)")
        obj.group = group
        group.shapes.append(obj)
    return group


def build_instance(node: Node) -> Instance:
    groups = []
    for child in node.children:
        if child.tag != "shape" or not isinstance(child.obj, ShapeGroup):
            what = f"a <{child.tag}>" if child.tag != "shape" else "a shape that is not a shapegroup"
            raise child.element.error(f"{what} inside an instance (Mitsuba 3: \"Only a shapegroup can be "
                                      f"specified in an instance.\"); an instance takes one <ref> to a "
                                      f"shapegroup, whose shapes bring their own bsdfs and media")
        groups.append(child)
    if not groups:
        raise node.fail(None, "an instance needs its shapegroup (Mitsuba 3: \"A reference to a 'shapegroup' "
                              "must be specified!\"): add <ref id=\"...\"/> naming a "
                              "<shape type=\"shapegroup\" id=\"...\">")
    if len(groups) > 1:
        raise groups[1].element.error("an instance names one shapegroup (Mitsuba 3: \"Only a single shapegroup "
                                      "can be specified per instance.\"); use one instance per group")
    to_world = node.transform("to_world")
    if not np.isfinite(to_world).all() or abs(np.linalg.det(to_world[:3, :3])) < 1e-30:
        raise node.fail("to_world", "the instance's to_world is singular (it flattens the group); rays cannot "
                                    "be taken into the group's space: give it a scale that is not zero")
    if np.linalg.det(to_world[:3, :3]) < 0:
        node.ctx.warn(node.at("to_world"), "the instance's to_world mirrors: as in Mitsuba 3, the group's shapes "
                                           "keep their outward normals (the inverse transpose), unlike a shape "
                                           "mirrored by its own to_world, which turns inside out")
    return Instance(groups[0].obj, to_world, id=node.element.attrs.get("id", ""), source=node.source())


def scene_shapes(objects: list) -> tuple[list, list]:
    """The scene's shapes and instances from the objects of its <shape> elements: the scene's own
    shapes, then the shapes of every group an instance uses (first use first), each once; groups no
    instance uses render nothing and are left out, as in Mitsuba."""
    own = [o for o in objects if isinstance(o, Shape)]
    instances = [o for o in objects if isinstance(o, Instance)]
    groups = {}
    for inst in instances:
        groups.setdefault(id(inst.group), inst.group)
    grouped = [s for g in groups.values() for s in g.shapes]
    for s in own:
        if s.group is not None:
            src = s.source
            raise VolclError(f"this shape is in the shapegroup of {s.group.source} and also placed in the scene "
                             f"directly; place it through an instance, or give the scene its own copy",
                             file=src.file if src else None, line=src.line if src else None,
                             element=src.element if src else None)
    return own + grouped, instances


def instance_bounds(instances: list, box_of) -> list:
    """World boxes (lo, hi) of the instances whose group has a box (box_of(shapes) -> (lo, hi) or None)."""
    out = []
    for inst in instances:
        box = box_of(inst.group.shapes)
        if box is None:
            continue
        corners = np.array([[x, y, z] for x in (box[0][0], box[1][0]) for y in (box[0][1], box[1][1])
                            for z in (box[0][2], box[1][2])])
        world = corners @ inst.to_world[:3, :3].T + inst.to_world[:3, 3]
        out.append((world.min(0), world.max(0)))
    return out
