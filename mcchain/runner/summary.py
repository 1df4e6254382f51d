"""What a run says when it ends: the lines ``mcchain run`` (and ``mcchain confirm``) print
from its ``run.json`` (:func:`run_summary`), counts, timings, throughput and what its
observers noted.

This module imports only the standard library.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def status_line(record: Mapping[str, Any]) -> str:
    """``ok 0, diverged 10, ...``: a run's status counts (``run.json``) that are not 0,
    ``ok`` always."""
    counts = record.get("status_counts") or {}
    return ", ".join(f"{k} {v}" for k, v in counts.items() if k != "samples" and (v or k == "ok"))


def run_summary(record: Mapping[str, Any]) -> list[str]:
    """What ``mcchain run`` prints of a run from its ``run.json`` (the folder is printed
    after these lines): counts, timings, throughput, and what its observers noted
    (``until``, the live stream, the requirements)."""
    r = record
    counts = r.get("status_counts") or {}
    flags = ", ".join(f"{k} {v}" for k, v in counts.items() if v and k != "samples")
    t = r.get("timings", {})
    tp = r.get("throughput", {})
    lines = [
        f"{r['scene']}: {r['samples']} samples in {r['chunks']} chunks "
        f"({r['sessions'][-1]['chunks_computed']} computed now); {flags or 'no samples'}",
        f"end to end {t.get('total', 0):.2f} s: prepare {t.get('prepare', 0):.2f} s, "
        f"kernel compile or cache load {t.get('warmup', 0):.2f} s, compute "
        f"{t.get('compute', 0):.2f} s (in the kernels {t.get('kernel', 0):.2f} s), merge "
        f"{t.get('merge', 0):.2f} s",
        f"compute only: {tp.get('samples_per_s') or 0:,.0f} samples/s"
        + (
            f", {tp['instance_steps_per_s']:.3g} instance-steps/s"
            if tp.get("instance_steps_per_s")
            else ""
        ),
    ]
    session = r["sessions"][-1] if r.get("sessions") else {}
    lines += [f"note: {line}" for line in session.get("notes") or []]
    retried = (r.get("retries") or {}).get("line")
    if retried:
        lines.append(f"note: {retried}")
    until = r.get("until")
    if until and until.get("stopped"):
        looks = len(until.get("looks", []))
        lines.append(f"until decided: {until['stopped']} ({looks} looks, {until['method']})")
    live = r["sessions"][-1].get("rerun") if r.get("sessions") else None
    if live:
        lines.append(live_summary(live))
    lines += r.get("requirements") or []
    return lines


def live_summary(live: Mapping[str, Any]) -> str:
    """The line ``mcchain run`` prints about a session's live rerun stream (its ``run.json``
    entry, :class:`mcchain.viz.live.LiveRun`)."""
    streamed = ", ".join(map(str, live.get("streamed") or [])) or "none"
    line = f"rerun: samples {streamed} streamed to {live.get('sink')}"
    if live.get("computed_before"):
        before = ", ".join(map(str, live["computed_before"]))
        line += f"; {before} computed before this session (replay with mcchain show)"
    if live.get("error"):
        line += f"; stream stopped: {live['error']}"
    return line
