"""Help text for the command line: plain text from reST docstrings, defaults shown.

Each command writes its help in the docstring style of the library (``literal``,
:func:`name`); :class:`PlainHelpFormatter` turns that into plain text for the terminal and
adds ``(default: X)`` to every option whose help does not already name its default.
``build_parser`` applies it to every command.
"""

from __future__ import annotations

import argparse
import re

__all__ = ["PlainHelpFormatter", "plain"]

_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`~?([^`<]*?)\s*(?:<[^`>]*>)?`")
_LITERAL = re.compile(r"``(.+?)``", re.S)
_EMPH = re.compile(r"(?<![\w*])\*\*?([^*\s][^*]*?)\*\*?(?![\w*])")


def plain(text: str | None) -> str:
    """reST markup to plain text: ````x```` -> ``x``, ``:func:`~a.b``` -> ``b``,
    ``**x**`` -> ``x``.

    >>> plain("``fit`` calls :func:`triaxcal.fit.select.fit_robust`; see :class:`~tc.Calibration`")
    'fit calls triaxcal.fit.select.fit_robust; see Calibration'
    """
    if not text:
        return text or ""

    def role(m: re.Match[str]) -> str:
        target = m.group(1)
        whole = m.group(0)
        return target.rsplit(".", 1)[-1] if "`~" in whole else target

    text = _ROLE.sub(role, text)
    text = _LITERAL.sub(r"\1", text)
    return _EMPH.sub(r"\1", text)


class PlainHelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Raw description (line breaks kept), reST markup removed, defaults shown."""

    def _format_text(self, text: str) -> str:
        return super()._format_text(plain(text))

    def _expand_help(self, action: argparse.Action) -> str:
        return plain(super()._expand_help(action))

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (
            action.option_strings
            and "%(default)" not in text
            and "default" not in text.lower()
            and not any(default is x for x in (None, False, True, argparse.SUPPRESS))
            and default != []
            and action.nargs != 0
        ):
            text += " (default: %(default)s)"
        return text
