"""Strings from input files shown safely: control characters escaped, never sent raw.

A topic, frame_id, file name or metadata value comes from someone else's recording.  Printed
as it is, a newline in it could forge a line of imupipe's own (``imupipe: error: ...``) and an
escape sequence could rewrite the terminal.  :func:`printable` shows every character that is not
printable (Unicode categories Cc, Cf, Zl, Zp, Co, Cn and separators other than the space:
:meth:`str.isprintable`) as its Python escape (``\\n``, ``\\x1b``, ``\\u202e``), so one message is
always one line of visible characters.
"""

from __future__ import annotations


def _escaped(char: str) -> str:
    return char if char.isprintable() else char.encode("unicode_escape").decode("ascii")


def printable(text: str) -> str:
    """``text`` with every non-printable character written as its escape (one line, no
    terminal control sequences); printable text, ``°`` and ``√`` included, is unchanged."""
    if text.isprintable():
        return text
    return "".join(_escaped(c) for c in text)
