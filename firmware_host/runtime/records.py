"""The run's two files: ``epochs.jsonl`` (one JSON object a line) and ``summary.json``.

:class:`EpochLog` is the one JSON Lines writer of the runtime: the ROV's records go through
:meth:`EpochLog.write`; the rover pipeline writes its records (the replay contract, in the same
compact encoding) to :attr:`EpochLog.stream`. Without a directory both are no-ops, so a vehicle
never asks whether there is an output.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, TextIO

EPOCHS = "epochs.jsonl"
SUMMARY = "summary.json"


def encode_line(record: dict[str, Any]) -> str:
    """One line of ``epochs.jsonl`` (compact separators, as the replay contract has them)."""
    return json.dumps(record, separators=(",", ":")) + "\n"


class EpochLog:
    """``DIR/epochs.jsonl`` (or nothing, with ``directory=None``); or a caller's open ``stream``
    (an embedding, a test), which is flushed but not closed."""

    def __init__(self, directory: Path | None, stream: TextIO | None = None) -> None:
        self.dir = directory
        self.stream: TextIO | None = stream
        self._borrowed = stream is not None
        self.lines = 0
        if directory is not None and stream is None:
            directory.mkdir(parents=True, exist_ok=True)
            self.stream = open(directory / EPOCHS, "w", encoding="utf-8")  # noqa: SIM115

    def write(self, record: dict[str, Any]) -> None:
        if self.stream is not None:
            self.stream.write(encode_line(record))
            self.lines += 1

    def flush(self) -> None:
        if self.stream is not None:
            self.stream.flush()

    def close(self) -> None:
        if self.stream is not None:
            if self._borrowed:
                self.stream.flush()
            else:
                self.stream.close()
            self.stream = None

    def write_summary(self, summary: dict[str, Any]) -> Path | None:
        """``DIR/summary.json`` (None without a directory)."""
        if self.dir is None:
            return None
        path = self.dir / SUMMARY
        path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        return path
