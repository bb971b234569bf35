"""Human summaries of results (the ``--json`` forms are the dictionaries themselves).

:func:`replay_text` is ``fdi-bridge replay``'s end summary (an aligned table with units, see
:mod:`firmware_host.commands.tables`), :func:`rov_replay_text` and :func:`insgnss_replay_text`
those of an ROV and an INS/GNSS recording, :func:`wrote_text` the files a replay wrote;
:func:`replay_problems` says what makes a replay useless or doubtful: no NMEA sentence at all
(exit 1); NMEA without a position, a damaged capture, an output that lost bytes (warnings).
"""

from __future__ import annotations

from pathlib import Path
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


def rov_replay_text(s: dict[str, Any]) -> str:
    """An ROV recording's replay (Outland or ArduSub): steps, epochs, commands as recorded."""
    r = s["replay"]
    return (f"ROV replay: {r['steps']} steps, {s['epochs']} epochs, commands "
            f"{'as recorded' if r['tx_match'] else 'DIFFERENT from the recording'} "
            f"({r['tx_steps_same']} steps same, {r['tx_steps_differ']} differ)")


def insgnss_replay_text(s: dict[str, Any]) -> str:
    """A live INS/GNSS recording's replay: records, bytes, epochs by who passed them."""
    modes = s.get("ins", {}).get("epochs", {})
    r = s["replay"]
    return (f"INS/GNSS replay: {r['records']} records ({r['bytes_imu']} IMU bytes, "
            f"{r['bytes_gps']} GNSS bytes), {s['epochs']} epochs: "
            f"{modes.get('ins', 0)} by the INS, {modes.get('rover', 0)} by the rover detector")


def wrote_text(out_dir: Path, records: bool = True) -> str:
    """The line a replay ends with: the files it wrote (``records=False``: ``--no-records``)."""
    if not records:
        return f"wrote {out_dir / 'summary.json'} (no epochs.jsonl: --no-records)"
    return f"wrote {out_dir / 'epochs.jsonl'} and {out_dir / 'summary.json'}"
