"""Live rerun streaming while a run computes (``mcchain run --rerun SAMPLES``).

* :class:`LiveOptions`, :func:`parse_rerun_samples`, :func:`check_live`: the ``--rerun``
  options, checked before anything is written;
* :class:`LiveRun`: the stream of one run session, an observer of the run's pipeline
  (:class:`mcchain.runner.steps.Observer`) fed each solved chunk; it records what it
  streamed in ``run.json``;
* :class:`LiveStream`: the rerun side, logging the chosen samples of each chunk as
  ``mcchain show`` logs them (:mod:`mcchain.viz.playback`).

This module imports only the standard library at import time: numpy, xarray, the
playback module and rerun are imported when a stream is opened.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.errors import RunError
from mcchain.runner.runs import LIVE_RRD
from mcchain.runner.steps import Observer, RunState, SolvedChunk

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.model import Model

log = logging.getLogger("mcchain")


# -- options -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class LiveOptions:
    """``mcchain run --rerun SAMPLES [--rerun-save FILE.rrd | --rerun-spawn]``.

    Attributes:
        samples: global sample indices to stream (distinct, >= 0).
        save: write the recording to this file (overwritten if it exists).
        spawn: spawn a rerun viewer instead.
        With neither sink: ``<run folder>/live.rrd`` (:data:`LIVE_RRD`; on a resume the first
        free of ``live-2.rrd``, ``live-3.rrd``, ..., so an earlier session's file stays).
    """

    samples: tuple[int, ...]
    save: Path | None = None
    spawn: bool = False

    def __post_init__(self) -> None:
        if not self.samples:
            raise RunError("--rerun: no sample index given")
        if any(not isinstance(s, int) or s < 0 for s in self.samples):
            raise RunError(f"--rerun: sample indices are integers >= 0, got {list(self.samples)}")
        if self.save is not None and self.spawn:
            raise RunError("--rerun-spawn: cannot be combined with --rerun-save (one sink)")
        if self.save is not None and Path(self.save).is_dir():
            raise RunError(f"--rerun-save: {self.save} is a directory")


def parse_rerun_samples(text: str) -> tuple[int, ...]:
    """``"0,3"`` -> ``(0, 3)`` (duplicates dropped); raises :class:`RunError` naming ``--rerun``."""
    parts = [part.strip() for part in text.split(",")]
    try:
        values = [int(part) for part in parts if part]
    except ValueError:
        raise RunError(
            f"--rerun: expected comma-separated sample indices like 0,3, got {text!r}"
        ) from None
    if not values:
        raise RunError(f"--rerun: expected comma-separated sample indices like 0,3, got {text!r}")
    if any(v < 0 for v in values):
        raise RunError(f"--rerun: sample indices are >= 0, got {text!r}")
    return tuple(dict.fromkeys(values))


def check_live(live: LiveOptions | None, nsample: int) -> None:
    """Every ``--rerun`` index is a sample of the run (checked before anything is written)."""
    if live is None:
        return
    outside = [s for s in live.samples if s >= nsample]
    if outside:
        raise RunError(
            f"--rerun: sample {outside[0]} is not in the run "
            f"({nsample} sample{'s' if nsample != 1 else ''}: 0..{nsample - 1})"
        )


# -- the stream of one run session -------------------------------------------------------------


class LiveRun(Observer):
    """The rerun stream of one session (``--rerun``), an observer of the run's pipeline.

    :meth:`on_start` creates the sink before the first chunk (a spawned viewer shows up at
    once); :meth:`on_chunk_done` is handed each solved chunk on the thread where the results
    arrive (the main thread: rerun recording and the chunk loop share it, never a numba
    thread or a Dask worker), builds the chunk's Dataset with the registry as the part
    writer does, and logs the chunk's selected samples with :class:`LiveStream`;
    :meth:`on_chunks_done` completes the file, also after a failure or Ctrl-C. The stream
    only reads the outputs: it never changes ``ensemble.nc``. A stream that fails (no
    viewer, a full disk) is a warning in ``run.log`` and ``run.json`` and the run goes on
    without it. rerun is imported here only, when ``--rerun`` is used.

    ``info`` (the session's ``run.json["sessions"][-1]["rerun"]``, from :meth:`on_start`)
    is kept up to date: samples, sink, streamed, computed_before, seconds, error.
    """

    def __init__(self, options: LiveOptions) -> None:
        self.options = options
        self.stream: Any = None
        self.info: dict[str, Any] = {}

    @staticmethod
    def default_path(folder: Path) -> Path:
        """``live.rrd`` in the run folder, or the first free of ``live-2.rrd``, ...."""
        path = folder / LIVE_RRD
        k = 2
        while path.exists():
            path = folder / f"{Path(LIVE_RRD).stem}-{k}.rrd"
            k += 1
        return path

    def on_start(self, run: RunState) -> None:
        """Open the sink for the selected samples in ``run.todo`` (the chunks this session
        computes)."""
        self.info = run.session.setdefault("rerun", {})
        self.info.update(
            samples=list(self.options.samples),
            sink=None,
            streamed=[],
            computed_before=[],
            seconds=0.0,
            error=None,
        )
        todo = [s for s in self.options.samples if any(a <= s < b for a, b in run.todo)]
        before = [s for s in self.options.samples if s not in todo]
        self.info["computed_before"] = before
        if before:
            log.warning(
                "--rerun: samples %s were computed before this session (replay them with "
                "mcchain show)",
                ", ".join(map(str, before)),
            )
        if not todo:
            self.info["sink"] = "nothing (no selected sample left to compute)"
            return
        if self.options.spawn:
            save, sink = None, "a spawned viewer"
        else:
            save = Path(self.options.save) if self.options.save else self.default_path(run.folder)
            sink = str(save)
        self.info["sink"] = sink
        t0 = time.perf_counter()
        try:
            if save is not None:
                save.parent.mkdir(parents=True, exist_ok=True)
            self.stream = LiveStream(todo, save=save, spawn=self.options.spawn)
            log.info("--rerun: streaming samples %s to %s", ", ".join(map(str, todo)), sink)
        except Exception as exc:
            self._fail(exc)
        self.info["seconds"] += time.perf_counter() - t0

    def on_chunk_done(self, run: RunState, chunk: SolvedChunk) -> None:
        """Log the selected samples of the solved chunk (if it holds any)."""
        stream, start, stop = self.stream, chunk.start, chunk.stop
        if stream is None or not any(start <= s < stop for s in stream.samples):
            return
        from mcchain.ensemble.registry import build_dataset

        t0 = time.perf_counter()
        try:
            model = run.job.model.select(start, stop)
            ds = build_dataset(
                chunk.outputs, model, start=start, history_dtype=run.job.history_dtype
            )
            logged = stream.log_chunk(ds, model, start)
            self.info["streamed"] = self.info["streamed"] + [int(s) for s in logged]
        except Exception as exc:
            self._fail(exc)
        self.info["seconds"] += time.perf_counter() - t0

    def on_chunks_done(self, run: RunState) -> None:
        """Flush and close the sink (a saved file is then complete)."""
        stream, self.stream = self.stream, None
        if stream is None:
            return
        t0 = time.perf_counter()
        try:
            stream.close()
        except Exception as exc:
            self._fail(exc)
        self.info["seconds"] += time.perf_counter() - t0

    def _fail(self, exc: Exception) -> None:
        message = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        self.info["error"] = message
        log.warning("--rerun: the live stream stopped (the run goes on): %s", message, exc_info=exc)
        stream, self.stream = self.stream, None
        if stream is not None:
            with contextlib.suppress(Exception):
                stream.close()


# -- the rerun side ----------------------------------------------------------------------------


class LiveStream:
    """Stream chosen samples to rerun while a run computes them (``mcchain run --rerun 0,1``).

    Call :meth:`log_chunk` with each finished chunk (the Dataset :class:`LiveRun` builds with
    ``mcchain.ensemble.registry.build_dataset(outputs, chunk_model, start=start)``); the
    samples of interest it holds are logged with :func:`mcchain.viz.playback.log_samples`.
    The default blueprint is sent with the first chunk that holds one of them; the force
    scale is fixed then too, so arrows compare across chunks. :meth:`close` (or leaving a
    ``with`` block) flushes and closes the sink, completing a saved file.

    Args:
        samples: global sample indices to stream.
        save, serve, url, spawn: the sink, as :func:`mcchain.viz.playback.open_recording`.
        magnify: clearance offsets are drawn this many times longer (default
            :data:`mcchain.viz.playback.DEFAULT_MAGNIFY`).
        force_scale: force arrows, m per N (default: from the first chunk logged).
    """

    def __init__(
        self,
        samples: Sequence[int],
        *,
        save: str | Path | None = None,
        serve: bool = False,
        url: str | None = None,
        spawn: bool = True,
        magnify: float | None = None,
        force_scale: float | None = None,
    ) -> None:
        from mcchain.viz.playback import DEFAULT_MAGNIFY, open_recording

        self.samples = list(dict.fromkeys(int(s) for s in samples))
        self.magnify = DEFAULT_MAGNIFY if magnify is None else magnify
        self.force_scale = force_scale
        self.logged: list[int] = []
        self.recording = open_recording(save=save, serve=serve, url=url, spawn=spawn)
        self._blueprint_sent = False

    def log_chunk(self, dataset: xr.Dataset, model: Model, start: int = 0) -> list[int]:
        """Log the samples of interest in this chunk; ``model`` is the chunk's model (row 0 =
        global sample ``start``) or the whole run's with ``start=0``. Returns those logged."""
        from mcchain.ensemble.queries import sample_ids
        from mcchain.viz.playback import default_force_scale, log_samples, make_blueprint

        present = set(sample_ids(dataset).tolist())
        wanted = [s for s in self.samples if s in present and s not in self.logged]
        if not wanted:
            return []
        if self.force_scale is None:
            self.force_scale = default_force_scale(dataset, model, wanted, model_offset=start)
        if not self._blueprint_sent:
            blueprint = make_blueprint(dataset, model, self.samples, self.magnify, start)
            self.recording.send_blueprint(blueprint)
            self._blueprint_sent = True
        log_samples(
            dataset,
            model,
            wanted,
            self.recording,
            magnify=self.magnify,
            force_scale=self.force_scale,
            model_offset=start,
        )
        self.logged += wanted
        return wanted

    def close(self) -> None:
        """Flush everything logged and close the sink (a saved file is then complete)."""
        self.recording.flush()
        self.recording.disconnect()

    def __enter__(self) -> LiveStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
