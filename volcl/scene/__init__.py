"""Scene loading: `load(path)` reads a Mitsuba 3 or Nori XML file into volcl.scene.model objects.

The dialect is decided per file by its root element: <scene version="3..."> is Mitsuba 3,
<scene> without a version or a <test> root is Nori. Everything a user can get wrong in a file
surfaces as a VolclError naming the file, line and element.
"""
from __future__ import annotations

import os
from typing import Mapping, Optional, Union

from . import parse_mitsuba, parse_nori
from .model import Scene, TTest
from .parse_common import Context, Dialect, read_object, substitute_parameters
from .xml import Element, parse_bytes, parse_file

__all__ = ["load", "load_string"]

_DEFAULT_PARENTS = {"scene", "test"}


def load(path: Union[str, os.PathLike], defines: Optional[Mapping[str, str]] = None
         ) -> Union[Scene, TTest]:
    """Load a scene (or a Nori t-test file). `defines` are the CLI's -D name=value overrides."""
    path = os.fspath(path)
    root = parse_file(path)
    substitute_parameters(root, {str(k): str(v) for k, v in (defines or {}).items()},
                          _DEFAULT_PARENTS)
    ctx = Context(path, _dialect(root))
    return read_object(ctx, root).obj


def load_string(text: Union[str, bytes], base_dir: Union[str, os.PathLike, None] = None,
                defines: Optional[Mapping[str, str]] = None, name: str = "<string>") -> Union[Scene, TTest]:
    """Load a scene from XML text. Messages name the text `name`; files it refers to (meshes,
    volumes) are found relative to `base_dir` (default: the working folder)."""
    data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
    root = parse_bytes(data, name)
    substitute_parameters(root, {str(k): str(v) for k, v in (defines or {}).items()},
                          _DEFAULT_PARENTS)
    # relative file names resolve against the folder of the context's path (objects.resolve_path)
    folder = os.path.abspath(os.fspath(base_dir) if base_dir is not None else os.getcwd())
    ctx = Context(os.path.join(folder, name), _dialect(root))
    return read_object(ctx, root).obj


def _dialect(root: Element) -> Dialect:
    if root.tag == "scene" and "version" in root.attrs:
        version = root.attrs["version"]
        if not version.strip().startswith("3"):
            raise root.error(f"Mitsuba scene version {version!r} is not supported; volcl reads "
                             f"version 3 files (<scene version=\"3.0.0\">) and Nori files "
                             f"(<scene> without a version)")
        return parse_mitsuba.DIALECT
    if root.tag in ("scene", "test"):
        return parse_nori.DIALECT
    raise root.error(f"the root element must be <scene> (Mitsuba 3 with version=\"3...\", Nori "
                     f"without) or Nori's <test>, not <{root.tag}>")

