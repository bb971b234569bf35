"""Progress bars for jobs longer than a few seconds (``bench``, ``eval --suite``,
``sim insgnss-report``, ``fleet``; ``record``'s byte count and rate, with no total), drawn by
tqdm on standard error.

A bar is shown only when standard error is a terminal (tqdm's ``disable=None``), so a job under
systemd, in a pipe or in a test prints nothing extra; ``-q`` (log level error or above) turns
it off on a terminal too. A job reports its steps with :meth:`Progress.step`.
"""

from __future__ import annotations

import logging
import shutil
import sys
from types import TracebackType

from tqdm import tqdm


def quiet() -> bool:
    """``-q``: the CLI set the log level to error or above."""
    return logging.getLogger().getEffectiveLevel() >= logging.ERROR


class Progress:
    """A bar of ``total`` steps named ``desc``; a context manager that closes the bar."""

    def __init__(self, total: int | None, desc: str, unit: str = "step", *,
                 unit_scale: bool = False) -> None:
        # The width from the terminal, else $COLUMNS, else 80 (a pty of size 0x0 would make
        # tqdm draw nothing).
        width = shutil.get_terminal_size((80, 24)).columns
        self.bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False,
                        disable=True if quiet() else None, ncols=width, unit_scale=unit_scale)

    @property
    def shown(self) -> bool:
        return not self.bar.disable

    def step(self, label: str = "", n: int = 1) -> None:
        """One step done; ``label`` (what comes next, or what was just done) beside the bar."""
        if label:
            self.bar.set_postfix_str(label, refresh=False)
        self.bar.update(n)

    def total(self, total: int) -> None:
        self.bar.total = total
        self.bar.refresh()

    def close(self) -> None:
        self.bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
