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
from .xml import Element, parse_file

__all__ = ["load"]

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

