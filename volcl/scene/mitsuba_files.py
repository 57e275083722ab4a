"""What a Mitsuba scene file does before any plugin is built: versions, <include>, <path>, <alias>,
parameter substitution, and the table of ids that lets a <ref> point forwards.

Mitsuba 3.9 (src/core/parser.cpp) walks each file once in document order, substituting $name as it
goes, so a <default> counts from where it stands on, also inside the files it includes, which share
the parameters. Its file resolver is a list of folders searched in order:
- loading a scene puts the scene's own folder first;
- <path value=...> (a child of a file's root) puts a folder in front of the list: later <path>s are
  searched first. The folder is taken relative to the file it is written in. A <path> in an included
  file only lasts while that file is read (Mitsuba restores the resolver after an <include>), so it
  reaches that file's own <include>s and spectrum files, but not its meshes or volumes;
- <include filename=...> is looked up with the including file's folder in front of the list;
- every other filename (meshes, volumes) is resolved when the objects are built, after the whole
  file has been read, with the scene's list: its <path> folders, then its folder. Mitsuba also
  tries the working folder last; volcl does not, so a scene never depends on where it is rendered.
An included file whose root is <scene> contributes its children in place of the <include>; any
other root is included as that one object.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import Mapping, Optional

from ..errors import VolclError
from .parse_common import substitute_attrs
from .properties import check_attrs, check_leaf
from .xml import Element, parse_file

# Mitsuba's own limit on nested includes (ParserConfig::max_include_depth).
MAX_INCLUDE_DEPTH = 15

OBJECT_TAGS = frozenset({"scene", "integrator", "sensor", "film", "rfilter", "sampler", "shape",
                         "bsdf", "emitter", "medium", "volume", "phase", "texture", "spectrum"})

_VERSION = re.compile(r"\s*(\d+)(?:\.(\d+))?(?:\.(\d+))?\s*\Z")


@dataclass
class Resolver:
    """Folders searched, in order, for a relative filename."""
    folders: list

    def resolve(self, filename: str) -> Optional[str]:
        if os.path.isabs(filename):
            return filename if os.path.exists(filename) else None
        for folder in self.folders:
            candidate = os.path.join(folder, filename)
            if os.path.exists(candidate):
                return candidate
        return None

    def describe(self) -> str:
        return ", ".join(self.folders)

    def copy(self) -> "Resolver":
        return Resolver(list(self.folders))


@dataclass
class MitsubaFile:
    """A Mitsuba scene with its includes spliced in and its parameters substituted."""
    root: Element
    version: tuple
    resolver: Resolver                       # for meshes, volumes and other files read later
    ids: dict = field(default_factory=dict)  # id (or alias) -> Element, across every file
    warnings: list = field(default_factory=list)


def parse_version(el: Element) -> tuple:
    text = el.attrs.get("version", "")
    match = _VERSION.match(text)
    if match is None:
        raise el.error(f"invalid version {text!r}; expected numbers like \"3.0.0\"")
    return tuple(int(g or 0) for g in match.groups())


def check_version(el: Element, version: tuple) -> None:
    if version[0] > 3:
        raise el.error(f"Mitsuba scene version {el.attrs['version']!r} is newer than Mitsuba 3, which "
                       f"volcl reads (versions 0.x to 3.x; Nori files have no version)")


def expand(root: Element, defines: Mapping[str, str], folder: Optional[str] = None) -> MitsubaFile:
    """Resolve <default>, $name, <include>, <path> and <alias> in place, in document order, and collect
    every id. `defines` (the CLI's -D) override the files' defaults; one that no file reads is an
    error, as in Mitsuba. `folder`: the scene's own folder (default: that of root.file)."""
    version = parse_version(root)
    check_version(root, version)
    walk = _Walk(defines, root.file, folder or os.path.dirname(os.path.abspath(root.file)))
    walk.file(root, version, walk.scene_resolver, depth=0)
    unused = sorted(walk.fixed - walk.used)
    if unused:
        declared = sorted(walk.used - walk.fixed) or ["none"]
        raise VolclError(f"-D {unused[0]}=...: the scene has no <default name=\"{unused[0]}\"> and uses no "
                         f"${unused[0]}; its parameters: {', '.join(declared)}", file=root.file)
    return MitsubaFile(root, version, walk.scene_resolver, walk.ids, walk.warnings)


class _Walk:
    def __init__(self, defines: Mapping[str, str], main: str, folder: str):
        self.params = dict(defines)
        self.fixed = set(defines)
        self.used: set = set()
        self.ids: dict = {}
        self.warnings: list = []
        self.main, self.folder = main, folder
        self.stack = [os.path.join(folder, os.path.basename(main))]     # files being read (cycles)
        self.scene_resolver = Resolver([folder])

    def folder_of(self, el: Element) -> str:
        """The folder an element's file lies in (the scene's folder for the scene, also when it was
        loaded from text)."""
        return self.folder if el.file == self.main else os.path.dirname(os.path.abspath(el.file))

    def warn(self, el: Element, message: str) -> None:
        self.warnings.append(f"{el.file}:{el.line}: <{el.label()}>: {message}")

    def file(self, root: Element, version: tuple, resolver: Resolver, depth: int) -> None:
        substitute_attrs(root, self.params, self.used)
        if version < (2, 0, 0):
            _upgrade_from_v1(root)
            self.warn(root, f"version {root.attrs['version']} file: parameter names are upgraded as "
                            f"Mitsuba 3 does (camelCase to snake_case, diffuse_reflectance to "
                            f"reflectance); plugins that Mitsuba 3 no longer has stay errors")
        self.children(root, root, resolver, depth)

    def children(self, el: Element, root: Element, resolver: Resolver, depth: int) -> None:
        kept = []
        for child in el.children:
            substitute_attrs(child, self.params, self.used)
            if child.tag == "default":
                self.default(child, el)
            elif child.tag == "include":
                kept.extend(self.include(child, resolver, depth))
            elif child.tag == "path":
                self.path(child, el is root, resolver)
            elif child.tag == "alias":
                self.alias(child)
            else:
                if child.tag in OBJECT_TAGS and "id" in child.attrs:
                    self.register(child.attrs["id"], child)
                if child.tag == "spectrum" and "filename" in child.attrs and "value" not in child.attrs:
                    self.spectrum_file(child, resolver)
                self.children(child, root, resolver, depth)
                kept.append(child)
        el.children = kept

    def default(self, el: Element, parent: Element) -> None:
        if parent.tag != "scene":
            raise el.error("<default> is only allowed directly inside <scene>")
        check_attrs(el, ("name", "value"))
        check_leaf(el)
        name = el.attrs["name"]
        if not name:
            raise el.error("<default>: name must be non-empty")
        if name not in self.fixed and name not in self.params:
            # the first definition holds, as in Mitsuba (an included file cannot change it)
            self.params[name] = el.attrs["value"]
        self.used.add(name)

    def register(self, ident: str, el: Element) -> None:
        first = self.ids.get(ident)
        if first is not None:
            where = f"line {first.line}" if first.file == el.file else f"{first.file}:{first.line}"
            raise el.error(f"duplicate id '{ident}' (first used on {where})")
        self.ids[ident] = el

    def alias(self, el: Element) -> None:
        check_attrs(el, ("id", "as"))
        check_leaf(el)
        source, dest = el.attrs["id"], el.attrs["as"]
        if dest in self.ids:
            raise el.error(f"alias destination id '{dest}' already exists")
        if source not in self.ids:
            known = ", ".join(sorted(self.ids)) or "none"
            raise el.error(f"alias source id '{source}' is not defined before the alias (defined so far: "
                           f"{known})")
        self.ids[dest] = self.ids[source]

    def path(self, el: Element, at_root: bool, resolver: Resolver) -> None:
        check_attrs(el, ("value",))
        check_leaf(el)
        if not at_root:
            raise el.error("<path> is only allowed directly inside the file's root element")
        value = el.attrs["value"]
        folder = os.path.join(self.folder_of(el), value)
        if not os.path.isdir(folder):
            folder = resolver.resolve(value) or folder
        if not os.path.isdir(folder):
            raise el.error(f"<path>: folder {value!r} not found (looked relative to "
                           f"{self.folder_of(el)} and in {resolver.describe()})")
        resolver.folders.insert(0, os.path.normpath(folder))

    def include(self, el: Element, resolver: Resolver, depth: int) -> list:
        check_attrs(el, ("filename",), ("name",))
        check_leaf(el)
        filename = el.attrs["filename"]
        inner = resolver.copy()
        inner.folders.insert(0, self.folder_of(el))
        path = inner.resolve(filename)
        if path is None or not os.path.isfile(path):
            raise el.error(f"included file {filename!r} not found (looked in {inner.describe()})")
        path = os.path.abspath(path)
        if path in self.stack:
            chain = " -> ".join(os.path.basename(p) for p in self.stack + [path])
            raise el.error(f"<include> cycle: {chain}")
        if depth + 1 >= MAX_INCLUDE_DEPTH:
            raise el.error(f"includes nested more than {MAX_INCLUDE_DEPTH} deep")
        root = parse_file(path)
        if "version" not in root.attrs:
            raise root.error(f"an included file needs a version attribute on its root element "
                             f"(it is read as a Mitsuba file; included from {el.file}:{el.line})")
        version = parse_version(root)
        check_version(root, version)
        self.stack.append(path)
        try:
            self.file(root, version, inner, depth + 1)
        finally:
            self.stack.pop()
        if root.tag == "scene":
            return root.children
        if root.tag not in OBJECT_TAGS:
            raise root.error(f"an included file's root must be <scene> or an object such as <bsdf>, "
                             f"not <{root.tag}>")
        root.attrs.pop("version", None)     # an included object's own root carries the file's version
        if "name" in el.attrs:
            root.attrs.setdefault("name", el.attrs["name"])
        if "id" in root.attrs:
            self.register(root.attrs["id"], root)
        return [root]

    def spectrum_file(self, el: Element, resolver: Resolver) -> None:
        # resolved while the file is read, with the resolver of that moment (as in Mitsuba)
        filename = el.attrs["filename"]
        found = resolver.resolve(filename)
        if found is None or not os.path.isfile(found):
            raise el.error(f"spectrum file {filename!r} not found (looked in {resolver.describe()})")
        el.extra["path"] = os.path.abspath(found)


_CAMEL = re.compile(r"(?<=[a-z])([A-Z]+)")
_PROPERTY_TAGS = frozenset({"float", "integer", "boolean", "string", "rgb", "color", "spectrum", "point",
                            "vector", "transform", "ref"})


def _camel_to_snake(name: str) -> str:
    """Mitsuba's camel_to_underscore_case: an underscore before each run of capitals that follows a
    lower-case letter, the run lower-cased (toWorld -> to_world, intIOR -> int_ior)."""
    return _CAMEL.sub(lambda m: "_" + m.group(1).lower(), name)


def _upgrade_from_v1(root: Element) -> None:
    """What Mitsuba 3 changes in files older than version 2: parameter names."""
    def walk(el: Element) -> None:
        for child in el.children:
            if child.tag in _PROPERTY_TAGS and "name" in child.attrs:
                child.attrs["name"] = _camel_to_snake(child.attrs["name"])
                if el.attrs.get("type") == "diffuse" and child.attrs["name"] == "diffuse_reflectance":
                    child.attrs["name"] = "reflectance"
            walk(child)
    walk(root)
