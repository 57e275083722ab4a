"""Scene loading: `load(path)` reads a Mitsuba or Nori XML file into volcl.scene.model objects,
`load_string(text)` the same from text.

The dialect is decided per file by its root element: <scene version="..."> is Mitsuba (versions 2.x
and 3.x as they are, older ones upgraded as Mitsuba 3 upgrades them), <scene> without a version or
a <test> root is Nori. Everything a user can get wrong in a file surfaces as a VolclError naming the
file, line and element.
"""
from __future__ import annotations

import os
from typing import Mapping, Optional, Union

from . import mitsuba_files, parse_mitsuba, parse_nori
from .mitsuba_files import Resolver
from .model import Scene, TTest
from .parse_common import Context, read_object, substitute_parameters
from .xml import Element, parse_bytes, parse_file

__all__ = ["load", "load_string"]

_DEFAULT_PARENTS = {"scene", "test"}


def load(path: Union[str, os.PathLike], defines: Optional[Mapping[str, str]] = None
         ) -> Union[Scene, TTest]:
    """Load a scene (or a Nori t-test file). `defines` are the CLI's -D name=value overrides."""
    path = os.fspath(path)
    return _read(parse_file(path), path, os.path.dirname(os.path.abspath(path)), defines)


def load_string(text: Union[str, bytes], base_dir: Union[str, os.PathLike, None] = None,
                defines: Optional[Mapping[str, str]] = None, name: str = "<string>") -> Union[Scene, TTest]:
    """Load a scene from XML text. Messages name the text `name`; files it refers to (meshes,
    volumes, includes) are found relative to `base_dir` (default: the working folder)."""
    data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
    folder = os.path.abspath(os.fspath(base_dir) if base_dir is not None else os.getcwd())
    return _read(parse_bytes(data, name), os.path.join(folder, name), folder, defines)


def _read(root: Element, path: str, folder: str, defines) -> Union[Scene, TTest]:
    defines = {str(k): str(v) for k, v in (defines or {}).items()}
    _check_root(root)
    if "version" in root.attrs:
        expanded = mitsuba_files.expand(root, defines, folder)
        ctx = Context(path, parse_mitsuba.DIALECT, elements=expanded.ids, resolver=expanded.resolver)
        scene = read_object(ctx, root).obj
        scene.warnings = expanded.warnings + scene.warnings
        return scene
    substitute_parameters(root, defines, _DEFAULT_PARENTS)
    ctx = Context(path, parse_nori.DIALECT, resolver=Resolver([folder]))
    return read_object(ctx, root).obj


def _check_root(root: Element) -> None:
    if root.tag == "scene" or (root.tag == "test" and "version" not in root.attrs):
        return
    raise root.error(f"the root element must be <scene> (Mitsuba with a version attribute, Nori "
                     f"without) or Nori's <test>, not <{root.tag}>")
