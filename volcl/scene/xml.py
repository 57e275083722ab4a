"""Safe XML reading into a small element tree that remembers line numbers.

Scene files are untrusted input, so the reader refuses every DOCTYPE and entity declaration instead of
trying to expand them safely: entity expansion ("billion laughs"), external DTDs and external entities
are how XML parsers are made to hang or reach the network. Expat from the standard library does the
tokenising; raising from its DOCTYPE handler stops the parse before any declaration inside is read.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from xml.parsers import expat

from ..errors import VolclError

# Real scenes nest a handful of levels; the limit keeps the recursive readers far from Python's
# recursion limit on hostile input.
MAX_DEPTH = 64


@dataclass
class Element:
    """One XML element: tag, attributes in document order, child elements, and where it was."""
    tag: str
    attrs: dict
    file: str
    line: int
    children: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)     # what reading the file added (a resolved filename)

    def error(self, message: str, element: str | None = None) -> VolclError:
        return VolclError(message, file=self.file, line=self.line, element=element or self.label())

    def label(self) -> str:
        """How the element is named in messages: its tag and, for plugins, its type."""
        kind = self.attrs.get("type")
        return f'{self.tag} type="{kind}"' if kind is not None else self.tag


def parse_file(path: str) -> Element:
    """Read and parse an XML file; every problem is a VolclError naming the file (and line)."""
    if not os.path.isfile(path):
        raise VolclError("scene file not found (or not a regular file)", file=path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise VolclError(f"cannot read scene file: {exc.strerror or exc}", file=path) from None
    return parse_bytes(data, path)


def parse_bytes(data: bytes, path: str) -> Element:
    builder = _TreeBuilder(path)
    parser = expat.ParserCreate()
    builder.attach(parser)
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise VolclError(f"malformed XML: {expat.ErrorString(exc.code)} (column {exc.offset + 1})",
                         file=path, line=exc.lineno) from None
    if builder.root is None:
        raise VolclError("the file holds no XML element", file=path)
    return builder.root


class _TreeBuilder:
    def __init__(self, path: str):
        self.path = path
        self.parser = None
        self.root: Element | None = None
        self.stack: list[Element] = []

    def attach(self, parser) -> None:
        self.parser = parser
        parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
        parser.StartElementHandler = self.start
        parser.EndElementHandler = self.end
        parser.CharacterDataHandler = self.text
        parser.StartDoctypeDeclHandler = self.reject_doctype
        parser.EntityDeclHandler = self.reject_entity
        parser.UnparsedEntityDeclHandler = self.reject_entity
        parser.ExternalEntityRefHandler = self.reject_entity
        # Unbuffered, so that the parser's position is still at the text when it is rejected.
        parser.buffer_text = False

    def _line(self) -> int:
        return self.parser.CurrentLineNumber

    def start(self, tag, attrs) -> None:
        if len(self.stack) >= MAX_DEPTH:
            raise VolclError(f"elements nested more than {MAX_DEPTH} deep", file=self.path,
                             line=self._line(), element=tag)
        el = Element(tag, dict(attrs), self.path, self._line())
        if self.stack:
            self.stack[-1].children.append(el)
        else:
            self.root = el
        self.stack.append(el)

    def end(self, tag) -> None:
        self.stack.pop()

    def text(self, data: str) -> None:
        if data.strip() and self.stack:
            snippet = data.strip()[:40]
            raise VolclError(f"unexpected text {snippet!r}; values go in value=\"...\" attributes",
                             file=self.path, line=self._line(), element=self.stack[-1].tag)

    def reject_doctype(self, *args) -> None:
        raise VolclError("DOCTYPE declarations are not allowed in scene files (no DTDs or entities)",
                         file=self.path, line=self._line())

    def reject_entity(self, *args) -> None:
        raise VolclError("entity declarations and references are not allowed in scene files",
                         file=self.path, line=self._line())
