"""What an ``--extend`` leaves behind: files made from the samples the run had before.

``mcchain export``, ``mcchain check``, ``mcchain report`` (and ``confirm``, ``rare``) write
into the run folder's ``export/``, ``check/`` and ``report/`` (:data:`DERIVED`). They
describe the samples the run had when they were made; once ``--extend`` has merged more, a
``requirements.csv`` of 768 samples beside an ``ensemble.nc`` of 1,024 would be read as the
run's. :class:`Extension`, the observer ``extend_run`` adds, moves them (never deletes them)
into ``stale/<n>-samples/`` when the merged ensemble is complete, and says so in a ``note:``
line of the session (``run.json["sessions"][-1]["notes"]``, printed by ``mcchain run``);
the commands write them afresh for the whole run.

This module imports only the standard library.
"""

from __future__ import annotations

import os
from pathlib import Path

from mcchain.runner.steps import Observer, RunState

DERIVED = ("export", "check", "report")
"""The folders of a run whose files are made from its ensemble by later commands."""

STALE = "stale"
"""Where :class:`Extension` moves them: ``stale/<n>-samples/<folder>``."""


def move_stale(folder: Path, samples: int) -> tuple[Path, list[str]] | None:
    """Move the :data:`DERIVED` folders of ``folder`` into ``stale/<samples>-samples/``
    (``-2``, ``-3``, ... when that exists); None when there was none."""
    present = [name for name in DERIVED if (folder / name).exists()]
    if not present:
        return None
    target = folder / STALE / f"{samples}-samples"
    k = 1
    while target.exists():
        k += 1
        target = folder / STALE / f"{samples}-samples-{k}"
    target.mkdir(parents=True)
    for name in present:
        os.replace(folder / name, target / name)
    return target, present


class Extension(Observer):
    """The observer of an ``--extend`` from ``before`` samples: its ``notes`` (e.g. that the
    verdict now comes from the confidence sequence) in the session, and the files made from
    the ``before`` samples moved aside once the merge is done (:func:`move_stale`)."""

    def __init__(self, before: int, notes: list[str] | None = None) -> None:
        self.before = int(before)
        self.notes = list(notes or [])

    def on_start(self, run: RunState) -> None:
        run.session["notes"] = list(self.notes)

    def on_merged(self, run: RunState) -> None:
        moved = move_stale(Path(run.folder), self.before)
        if moved is None:
            return
        target, names = moved
        where = target.relative_to(run.folder)
        listed = ", ".join(f"{name}/" for name in names)
        line = (
            f"{listed} described the run's first {self.before} samples: moved to {where}/ "
            f"(run mcchain {' / '.join(names)} again for all {run.nsample})"
        )
        run.session.setdefault("notes", []).append(line)
        run.record.setdefault("stale", []).append({"samples": self.before, "moved_to": str(where)})
