"""OpenUSD's own diagnostics, turned into simbake's lines.

OpenUSD reports problems through its diagnostic manager: errors (raised in Python as
``Tf.ErrorException``), warnings printed on stderr as ``Warning: in _ReportErrors at line
3326 of .../stage.cpp -- ...``, and composition errors (a missing or cyclic sublayer, a
reference or payload that does not resolve) that only warn. :func:`trapped` catches all of
them for the length of a block (``Tf.DiagnosticTrap``) so that none reaches stderr raw, and
:func:`one_line` makes one of them a short line: the user's own location (``FILE:LINE:COL``
of a syntax error, in whichever layer it is), the message without C++ namespaces, call sites
and stage addresses.
"""

from __future__ import annotations

import os
import re
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

_LOCATION = re.compile(r"(?P<file>[^\s@'\";]+?):(?P<line>\d+):(?P<column>\d+): ")
_NAMESPACE = re.compile(r"\b[A-Za-z_][A-Za-z0-9_]*::")
_ADDRESS = re.compile(r"\s*\((instantiating|opening) stage on stage @[^@]*@ <0x[0-9a-f]+>\)")
_TF_ERROR = re.compile(r"Error in '[^']*' at line \d+ in file \S+ : '(?P<message>.*?)'?$", re.S)
LIMIT = 300  # characters of one message (the location is always kept)


class Diagnostics:
    """What OpenUSD reported inside a :func:`trapped` block: message texts."""

    def __init__(self):
        self.errors: list[str] = []
        self.warnings: list[str] = []


@contextmanager
def trapped() -> Iterator[Diagnostics]:
    """Catch OpenUSD's errors and warnings in the block (none printed); the texts are in the
    yielded Diagnostics once the block ends, whether it raised or not."""
    from pxr import Tf

    found = Diagnostics()
    with Tf.DiagnosticTrap() as trap:
        try:
            yield found
        finally:
            found.errors += [d.commentary for d in trap.GetErrors()]
            found.warnings += [d.commentary for d in trap.GetWarnings()]
            trap.Clear()


def error_texts(error: BaseException) -> list[str]:
    """The messages inside a Tf.ErrorException (one per reported error)."""
    texts = []
    for part in re.split(r"\n\s*(?=Error in ')", str(error).strip()):
        match = _TF_ERROR.search(part.strip())
        texts.append(match["message"] if match else part.strip())
    return [t for t in texts if t]


def location(texts: list[str]) -> tuple[str, str] | None:
    """(file, "line L, column C") of the first syntax error among the texts, or None."""
    for text in texts:
        match = _LOCATION.search(text)
        if match:
            return match["file"], f"line {match['line']}, column {match['column']}"
    return None


def clean(text: str) -> str:
    """One short line: no C++ namespaces, stage addresses, newlines or runs of spaces."""
    text = _ADDRESS.sub("", text)
    text = _NAMESPACE.sub("", text)
    text = " ".join(text.replace(";", " ;").split()).replace(" ;", ";")
    return text if len(text) <= LIMIT else text[: LIMIT - 3] + "..."


def shown_path(path: str, given: str, given_path: Path) -> str:
    """A layer's path as the user would name it: as given for the root, else relative to here."""
    try:
        if os.path.realpath(path) == os.path.realpath(given_path):
            return given
        relative = os.path.relpath(path)
        return relative if not relative.startswith("../..") else path
    except ValueError:
        return path


def syntax_message(texts: list[str]) -> str:
    """The parser's own words for a syntax error, without the location (given apart)."""
    for text in texts:
        for piece in re.split(r"\s*(?:--|;)\s*", text):
            piece = _LOCATION.sub("", piece).strip()
            if piece and not piece.startswith(("Could not load", "Failed to open", "skipping")):
                return clean(piece)
    return "not valid USD"
