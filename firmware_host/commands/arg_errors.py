"""A usage error that names the real mistake.

argparse checks the required options before it reports the unknown ones, so a misspelt
required option (``record --outt x``) was reported as ``--out`` missing.
:func:`unknown_option_error` finds the misspelt option first and names the option meant
(``difflib``, as git's "did you mean"); the CLI's parser calls it from its ``error``.
"""

from __future__ import annotations

import argparse
import difflib
from collections.abc import Sequence


def unknown_options(parser: argparse.ArgumentParser, args: Sequence[str]) -> list[str]:
    """The ``-x``/``--xx`` words of ``args`` that none of ``parser``'s options takes (a unique
    prefix of a long option is taken, as argparse takes it; everything after ``--`` is a
    value)."""
    known = parser._option_string_actions  # argparse's own table of option strings
    longs = [o for o in known if o.startswith("--")]
    out = []
    for word in args:
        if word == "--":
            break
        if not word.startswith("-") or word == "-" or _is_number(word):
            continue
        name = word.split("=", 1)[0]
        if name in known:
            continue
        if name.startswith("--") and parser.allow_abbrev \
                and len([o for o in longs if o.startswith(name)]) == 1:
            continue
        if not name.startswith("--") and len(name) > 2 and name[:2] in known:
            continue  # -v3 style: a short option with its value attached
        out.append(name)
    return out


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def unknown_option_error(parser: argparse.ArgumentParser, args: Sequence[str] | None,
                         message: str) -> str:
    """``message`` unless it is argparse's "the following arguments are required" while
    ``args`` holds an option the parser does not know: then that option, with the nearest
    known one ("unrecognized arguments: --outt (did you mean --out?)")."""
    if args is None or not message.startswith("the following arguments are required"):
        return message
    bad = unknown_options(parser, args)
    if not bad:
        return message
    longs = sorted(o for o in parser._option_string_actions if o.startswith("--"))
    near = difflib.get_close_matches(bad[0], longs, n=1)
    hint = f" (did you mean {near[0]}?)" if near else ""
    return f"unrecognized arguments: {' '.join(bad)}{hint}"
