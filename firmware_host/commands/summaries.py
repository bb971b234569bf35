"""Human summaries of results (the ``--json`` forms are the dictionaries themselves).

:func:`replay_text` is ``fdi-bridge replay``'s end summary (an aligned table with units, see
:mod:`firmware_host.commands.tables`); :func:`replay_problems` says what makes a replay useless
or doubtful: no NMEA sentence at all (exit 1); NMEA without a position, a damaged capture, an
output that lost bytes (warnings).
"""

from __future__ import annotations

from typing import Any

from firmware_host.commands.tables import fields, fmt


def _counts(d: dict[str, Any] | None) -> str:
    """``{'accept': 5915, 'replace': 12}`` -> ``accept 5915, replace 12`` (``-`` when empty)."""
    return fmt(dict(sorted((d or {}).items(), key=lambda kv: (-kv[1], kv[0]))))


def replay_text(s: dict[str, Any]) -> str:
    inp = s.get("input", {})
    proc = s.get("processing_ms", {})
    period = s.get("epoch_period_s")
    rows: list[tuple[str, Any, str]] = [
        ("input", f"{inp.get('file', '?')} ({inp.get('kind', '?')})", ""),
        ("config", s.get("config"), ""),
        ("epochs", s.get("epochs"), "" if not period else f"at {fmt(1 / period)} Hz"),
        ("faults", s.get("faults"), "epochs flagged"),
        ("alarms", s.get("alarms"), ""),
        ("actions", _counts(s.get("actions")), ""),
        ("sentences", inp.get("sentences"), f"from {fmt(inp.get('bytes_in'))} bytes"),
        ("rejected lines", inp.get("rejected_total"), _counts(inp.get("rejected"))
         if inp.get("rejected") else ""),
        ("ignored", _counts(inp.get("ignored")), ""),
        ("processing p50", proc.get("p50"), "ms/epoch"),
        ("processing p99", proc.get("p99"), "ms/epoch"),
        ("overruns", s.get("overruns"), ""),
        ("throughput", s.get("epochs_per_s"), "epochs/s"),
        ("output errors", s.get("output_errors"), ""),
    ]
    for name, st in (s.get("outputs") or {}).items():
        if st:
            rows.append((f"  {name}", st.get("bytes_out", st.get("sent")),
                         f"bytes out, {fmt(st.get('dropped_bytes', 0))} dropped"
                         if "bytes_out" in st else _counts(st)))
    if s.get("partial"):
        rows.append(("partial", True, "interrupted: only what was read before "
                     f"{s.get('interrupted_by', 'SIGINT')}"))
    return fields(rows)


def replay_problems(s: dict[str, Any]) -> tuple[str | None, list[str]]:
    """(why the replay is useless or None, warnings to show on the console)."""
    inp = s.get("input", {})
    warnings = [f"{inp.get('file', 'input')}: {note}" for note in inp.get("notes") or []]
    for name, st in (s.get("outputs") or {}).items():
        dropped = (st or {}).get("dropped_bytes", 0)
        if dropped:
            warnings.append(f"output {name}: {dropped} bytes dropped (nobody reading, or the "
                            "port was down)")
    if s.get("output_errors"):
        warnings.append(f"{s['output_errors']} output errors (see the log)")
    if not inp.get("sentences") and not s.get("partial"):
        ignored = inp.get("ignored") or {}
        if not ignored:
            what = "empty" if not inp.get("bytes_in") else f"{inp.get('bytes_in')} bytes"
            return f"no NMEA sentences found in {inp.get('file', 'the input')} ({what})", warnings
        # NMEA, but nothing with a position (a heading or autopilot log): said, not an error.
        warnings.append(f"{inp.get('file', 'input')}: no position sentences (GGA, RMC, GLL), "
                        f"only {_counts(ignored)}: 0 epochs")
    return None, warnings
