"""What both XML dialects share: parameter substitution, plugin tables, ids and refs, typed access.

A dialect describes itself as a `Dialect`: for every object tag and plugin type a `Spec` (the
parameters it accepts and their kinds, the object tags it accepts as children) and a builder that
turns a checked `Node` into model objects. `read_object` walks an element against that table, so
"unknown element / type / parameter" errors come from one place and always list what is supported.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Callable, Mapping, Optional

import numpy as np

from ..errors import VolclError
from . import checks, spectra
from .model import Source, rgb
from .spectra import Spectrum
from .properties import Prop, check_attrs, check_leaf, parse_property
from .xml import Element

# Which property tags can supply a parameter of each kind.
ACCEPTS = {
    "float": frozenset({"float", "integer"}),
    "int": frozenset({"integer"}),
    "bool": frozenset({"boolean"}),
    "string": frozenset({"string"}),
    "color": frozenset({"rgb", "color", "spectrum", "float", "integer"}),
    "point": frozenset({"point", "vector"}),
    "transform": frozenset({"transform"}),
    "ior": frozenset({"float", "integer", "string"}),
}

_KIND_NAMES = {
    "float": "a <float>", "int": "an <integer>", "bool": "a <boolean>", "string": "a <string>",
    "color": "a colour (<rgb>/<color>, <spectrum> or <float>)", "point": "a <point> or <vector>",
    "transform": "a <transform>", "ior": "a <float> or a <string> material name",
}


@dataclass(frozen=True)
class Spec:
    """What one plugin accepts. `ignored` maps parameters that volcl reads past to what it does
    instead (each a warning); `other_params='warn'` turns every unknown parameter into a warning."""
    params: Mapping[str, str] = field(default_factory=dict)
    children: frozenset = frozenset()
    attrs: tuple = ("type", "id", "name")
    other_params: str = "error"
    ignored: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Dialect:
    name: str
    property_tags: frozenset
    specs: Mapping[str, Mapping[Optional[str], Spec]]     # tag -> type (None: untyped) -> Spec
    builders: Mapping[str, Callable]                       # tag -> fn(Node) -> object
    rotate_axis_as_given: bool = False                     # Mitsuba: rotate does not normalize its axis


@dataclass
class Child:
    """An object inside another: built object, its tag, the name it was given, where it came from."""
    tag: str
    name: str
    obj: object
    element: Element


class Context:
    """Per-file parsing state: the dialect, the ids a <ref> can name, the objects built so far, the
    folders filenames are looked up in, and the warnings collected.

    `elements` maps every id in the file (and its includes) to its element, so a <ref> may name an
    object defined further down: the object is then built on first use, once, and reused when its
    own turn in the file comes (`built`, keyed by element)."""

    def __init__(self, path: str, dialect: Dialect, elements: Optional[dict] = None, resolver=None):
        self.path = path
        self.dialect = dialect
        self.elements: dict = dict(elements or {})
        self.built: dict[int, Child] = {}
        self.building: list = []        # elements being built, innermost last (reference cycles)
        self.resolver = resolver
        self.warnings: list[str] = []

    def warn(self, el: Element, message: str) -> None:
        self.warnings.append(f"{el.file}:{el.line}: <{el.label()}>: {message}")


# ---------------------------------------------------------------------------------------------
# Parameter substitution: <default name= value=/> and $name, overridden by the CLI's -D.

_PARAM_REF = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


def substitute_parameters(root: Element, defines: Mapping[str, str], default_parents: set) -> None:
    """Resolve <default> elements and $name references in place, in document order.

    Mitsuba applies substitution while it walks the file, so a $name is known only after its
    <default> (or when given on the command line). <default> elements are removed from the tree.
    """
    params = dict(defines)
    fixed = set(defines)
    used = set()

    def walk(el: Element) -> None:
        kept = []
        for child in el.children:
            substitute_attrs(child, params, used)
            if child.tag == "default":
                if el.tag not in default_parents:
                    raise child.error("<default> is only allowed directly inside "
                                      + " or ".join(f"<{t}>" for t in sorted(default_parents)))
                check_attrs(child, ("name", "value"))
                check_leaf(child)
                if child.attrs["name"] not in fixed:
                    params[child.attrs["name"]] = child.attrs["value"]
                used.add(child.attrs["name"])
                continue
            kept.append(child)
            walk(child)
        el.children = kept

    substitute_attrs(root, params, used)
    walk(root)
    unused = sorted(fixed - used)
    if unused:
        # as in Mitsuba: a -D the scene never reads is a typo, not something to skip silently
        declared = sorted(used - fixed) or ["none"]
        raise VolclError(f"-D {unused[0]}=...: the scene has no <default name=\"{unused[0]}\"> and uses no "
                         f"${unused[0]}; its parameters: {', '.join(declared)}", file=root.file)


def substitute_attrs(el: Element, params: Mapping[str, str], used: set) -> None:
    for key, value in el.attrs.items():
        if "$" in value:
            el.attrs[key] = _substitute(el, key, value, params)
            used.update(m.group(1) for m in _PARAM_REF.finditer(value))


# Defaults may refer to earlier defaults, so without a cap a few lines could build a value of
# gigabytes (the "billion laughs" attack, replayed through $name).
MAX_SUBSTITUTED_LENGTH = 100_000


def _substitute(el: Element, key: str, value: str, params: Mapping[str, str]) -> str:
    pieces, length, pos = [], 0, 0
    for match in _PARAM_REF.finditer(value):
        name = match.group(1)
        if name not in params:
            known = ", ".join(sorted(params)) or "none"
            raise el.error(f"attribute {key}={value!r} uses undefined parameter ${name}; define "
                           f"it with <default name=\"{name}\" value=\"...\"/> or -D {name}=... "
                           f"(defined: {known})")
        for piece in (value[pos:match.start()], params[name]):
            length += len(piece)
            pieces.append(piece)
        if length > MAX_SUBSTITUTED_LENGTH:
            raise el.error(f"attribute {key}: substituting parameters makes it longer than "
                           f"{MAX_SUBSTITUTED_LENGTH} characters")
        pos = match.end()
    pieces.append(value[pos:])
    return "".join(pieces)


# ---------------------------------------------------------------------------------------------
# Reading objects against the dialect's table.

def plugin_spec(ctx: Context, el: Element) -> Spec:
    types = ctx.dialect.specs[el.tag]
    kind = el.attrs.get("type")
    if None in types:
        if kind is not None:
            raise el.error(f"<{el.tag}> takes no type attribute")
        return types[None]
    if kind is None:
        raise el.error(f"missing attribute 'type'; supported {el.tag} types: "
                       + ", ".join(sorted(types)))
    if kind not in types:
        raise el.error(f"unknown {el.tag} type '{kind}'; supported: " + ", ".join(sorted(types)))
    return types[kind]


def read_object(ctx: Context, el: Element) -> Child:
    """Check `el` against its Spec, read its parameters and children, and build it (once: an object
    a forward <ref> needed is built then and reused here)."""
    done = ctx.built.get(id(el))
    if done is not None:
        return done
    spec = plugin_spec(ctx, el)
    check_attrs(el, (), spec.attrs)
    ctx.building.append(el)
    try:
        node = Node(ctx, el, spec)
        for child in el.children:
            if child.tag in ctx.dialect.property_tags:
                node.add_prop(parse_property(child, ctx.dialect.rotate_axis_as_given))
            elif child.tag == "ref":
                node.add_child(resolve_ref(ctx, child))
            elif child.tag in ctx.dialect.specs and child.tag in spec.children:
                node.add_child(read_object(ctx, child))
            else:
                raise child.error(f"<{child.tag}> is not allowed inside <{el.label()}>; supported "
                                  f"here: {_supported_here(ctx, spec)}", element=child.tag)
        obj = ctx.dialect.builders[el.tag](node)
    finally:
        ctx.building.pop()
    result = Child(el.tag, el.attrs.get("name", ""), obj, el)
    ctx.built[id(el)] = result
    return result


def _supported_here(ctx: Context, spec: Spec) -> str:
    props = sorted({tag for kind in spec.params.values() for tag in ACCEPTS[kind]}
                   & ctx.dialect.property_tags)
    objects = sorted(spec.children)
    items = [f"<{t}>" for t in props + objects] + (["<ref>"] if objects else [])
    return ", ".join(items) or "nothing (no child elements)"


def resolve_ref(ctx: Context, el: Element) -> Child:
    check_attrs(el, ("id",), ("name",))
    check_leaf(el)
    ident = el.attrs["id"]
    target = ctx.elements.get(ident)
    if target is None:
        known = ", ".join(sorted(ctx.elements)) or "none"
        raise el.error(f"reference to unknown id '{ident}' (ids in the scene: {known})")
    if any(target is open_el for open_el in ctx.building):
        chain = [b.attrs.get("id", f"<{b.label()}>") for b in ctx.building]
        start = next(i for i, b in enumerate(ctx.building) if b is target)
        raise el.error("circular reference: " + " -> ".join(chain[start:] + [ident]))
    built = read_object(ctx, target)
    return Child(built.tag, el.attrs.get("name", built.name), built.obj, el)


class Node:
    """A plugin element being built: its checked parameters and its already-built children."""

    def __init__(self, ctx: Context, element: Element, spec: Spec):
        self.ctx, self.element, self.spec = ctx, element, spec
        self.props: dict[str, Prop] = {}
        self.children: list[Child] = []
        # Warnings raised while this element's children are read belong to it (a ttest's scenes).
        self.first_warning = len(ctx.warnings)

    @property
    def type(self) -> str:
        return self.element.attrs.get("type", "")

    @property
    def label(self) -> str:
        return self.element.label()

    def source(self) -> Source:
        return Source(self.element.file, self.element.line, self.label)

    # -- collecting ---------------------------------------------------------------------------

    def add_prop(self, prop: Prop) -> None:
        note = self.spec.ignored.get(prop.name)
        if note is not None:
            self.ctx.warn(prop.element, f"'{prop.name}' is ignored: {note}")
            return
        kind = self.spec.params.get(prop.name)
        if kind is None:
            if self.spec.other_params == "warn":
                self.ctx.warn(prop.element, f"parameter '{prop.name}' of <{self.label}> is "
                                            f"ignored by volcl")
                return
            supported = ", ".join(sorted(self.spec.params)) or "none"
            raise prop.element.error(f"unknown parameter '{prop.name}' for <{self.label}>; "
                                     f"supported: {supported}")
        if prop.tag not in ACCEPTS[kind]:
            raise prop.element.error(f"parameter '{prop.name}' of <{self.label}> must be "
                                     f"{_KIND_NAMES[kind]}, not <{prop.tag}>")
        if prop.name in self.props:
            first = self.props[prop.name].element.line
            raise prop.element.error(f"parameter '{prop.name}' given twice (first on line {first})")
        self.props[prop.name] = prop

    def add_child(self, child: Child) -> None:
        if child.tag not in self.spec.children:
            allowed = ", ".join(f"<{t}>" for t in sorted(self.spec.children)) or "none"
            raise child.element.error(f"a {child.tag} is not allowed inside <{self.label}>; "
                                      f"allowed objects: {allowed}")
        self.children.append(child)

    # -- reading ------------------------------------------------------------------------------

    def has(self, name: str) -> bool:
        return name in self.props

    def at(self, name: Optional[str] = None) -> Element:
        """The element to blame for a parameter: its property element if given, else the plugin."""
        prop = self.props.get(name) if name else None
        return prop.element if prop is not None else self.element

    def fail(self, name: Optional[str], message: str) -> VolclError:
        return self.at(name).error(message)

    def checked(self, name: Optional[str], rule, *args):
        """rule(*args) from volcl.scene.checks, its CheckError blamed on parameter `name`."""
        try:
            return rule(*args)
        except checks.CheckError as exc:
            raise self.fail(name, str(exc)) from None

    def value(self, name: str, default=None):
        prop = self.props.get(name)
        if prop is None:
            if default is None:
                raise self.element.error(f"missing required parameter '{name}'")
            return default
        return prop.value

    def float(self, name: str, default: Optional[float] = None) -> float:
        return float(self.value(name, default))

    def int(self, name: str, default: Optional[int] = None) -> int:
        return int(self.value(name, default))

    def bool(self, name: str, default: Optional[bool] = None) -> bool:
        return bool(self.value(name, default))

    def string(self, name: str, default: Optional[str] = None) -> str:
        return str(self.value(name, default))

    def color(self, name: str, default=None, kind: str = "reflectance") -> np.ndarray:
        """A colour parameter as linear sRGB; a <spectrum> is converted as Mitsuba's RGB variants
        convert it for a parameter of `kind` (volcl.scene.spectra: 'reflectance', 'unbounded' or
        'emission')."""
        value = self.value(name, default)
        if isinstance(value, Spectrum):
            where = self.at(name)
            return spectra.to_rgb(value, kind, warn=lambda msg: self.ctx.warn(where, msg),
                                  fail=lambda msg: where.error(f"'{name}': {msg}"))
        return rgb(value)

    def point(self, name: str, default=None) -> np.ndarray:
        return np.asarray(self.value(name, default), dtype=np.float64).copy()

    def transform(self, name: str) -> np.ndarray:
        return np.array(self.value(name, np.eye(4)), dtype=np.float64)

    def normal_matrix(self, name: str) -> Optional[np.ndarray]:
        """The 3x3 matrix Mitsuba takes normals to the world with, where it is not the inverse
        transpose of the transform (volcl.scene.properties.parse_transform); None elsewhere."""
        prop = self.props.get(name)
        return None if prop is None else prop.normal_matrix

    # -- validated reading --------------------------------------------------------------------

    def positive(self, name: str, default: Optional[float] = None) -> float:
        return self.checked(name, checks.positive, name, self.float(name, default))

    def choice(self, name: str, options, default: Optional[str] = None) -> str:
        value = self.string(name, default)
        if value not in options:
            raise self.fail(name, f"'{name}' is {value!r}; supported: " + ", ".join(options))
        return value

    def nonneg_color(self, name: str, default=None, kind: str = "reflectance") -> np.ndarray:
        return self.checked(name, checks.nonneg_color, name, self.color(name, default, kind))

    def unit_color(self, name: str, default=None, kind: str = "reflectance") -> np.ndarray:
        return self.checked(name, checks.unit_color, name, self.color(name, default, kind))

    # -- children -----------------------------------------------------------------------------

    def objects(self, tag: str) -> list[Child]:
        return [c for c in self.children if c.tag == tag]

    def single(self, tag: str) -> Optional[Child]:
        found = self.objects(tag)
        if len(found) > 1:
            raise found[1].element.error(f"<{self.label}> takes at most one {tag}, found "
                                         f"{len(found)}")
        return found[0] if found else None


def medium_list(camera_medium, shapes) -> list:
    """Every distinct medium referenced by the camera or a shape, first reference first."""
    seen: dict[int, object] = {}
    for medium in [camera_medium] + [m for s in shapes for m in (s.interior, s.exterior)]:
        if medium is not None and id(medium) not in seen:
            seen[id(medium)] = medium
    return list(seen.values())
