"""Help text for the command line: plain text from reST docstrings, defaults shown.

Each command writes its help in the docstring style of the library (``literal``,
:func:`name`); :class:`PlainHelpFormatter` turns that into plain text for the terminal and
adds ``(default: X)`` to every option whose help does not already name its default.
``build_parser`` applies it to every command.
"""

from __future__ import annotations

import argparse
import re
from typing import Any

__all__ = ["PlainHelpFormatter", "plain", "renamed"]

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


class _Renamed(argparse.Action):
    """An old spelling of an option, kept for one release: it does what the new one does and
    says on standard error that it was renamed."""

    def __init__(self, option_strings: list[str], dest: str, new: str = "",
                 target: argparse.Action | None = None, value: Any = None,
                 **kw: object) -> None:
        self.new = new
        self.target = target
        self.value = value  # an old flag that meant "the new option with this value"
        kw.setdefault("help", argparse.SUPPRESS)
        if target is not None and (target.nargs == 0 or value is not None):
            kw["nargs"] = 0
        super().__init__(option_strings, dest, **kw)  # type: ignore[arg-type]

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        import sys

        print(f"triaxcal: {option_string} is now {self.new}; the old spelling goes in the next "
              "release", file=sys.stderr)
        if self.value is not None:
            values = self.value
        if self.target is not None:
            self.target(parser, namespace, values, option_string)
        else:
            setattr(namespace, self.dest, values)


def renamed(parser: Any, old: str, new: str) -> None:
    """Keep ``old`` as a spelling of the option ``new`` (already added to ``parser``, or to one
    of its groups) that warns on use. ``new`` may carry a value (``"--format json"``): then
    ``old`` is a flag that means the new option with that value.

    >>> p = argparse.ArgumentParser()
    >>> _ = p.add_argument("--format", choices=("text", "json"), default="text")
    >>> renamed(p, "--json", "--format json")
    >>> p.parse_args(["--json"]).format  # and on stderr: --json is now --format json
    'json'
    """
    flag, _, value = new.partition(" ")
    target = next(a for a in parser._actions if flag in a.option_strings)
    if target.required:  # either spelling satisfies it: checked after parsing (cli.main)
        target.required = False
        parser.set_defaults(_required=(*(parser.get_default("_required") or ()), target))
    shown = "/".join(target.option_strings) + (f" {value}" if value else "")
    if value:
        parser.add_argument(old, action=_Renamed, dest=target.dest, new=shown, target=target,
                            value=value, default=argparse.SUPPRESS)
        return
    parser.add_argument(old, action=_Renamed, dest=target.dest, new=shown, target=target,
                        metavar=target.metavar, type=target.type, default=argparse.SUPPRESS)


def missing_required(args: argparse.Namespace) -> list[str]:
    """The options made optional by :func:`renamed` that were given in neither spelling."""
    return ["/".join(a.option_strings) for a in getattr(args, "_required", ())
            if getattr(args, a.dest, None) is None]
