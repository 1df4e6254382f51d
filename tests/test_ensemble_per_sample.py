"""The netCDF4 read of a merged ensemble (:mod:`mcchain.ensemble.per_sample`) against
xarray's: the same variables, dtypes, bytes and attributes, and the same verdict lines and
retry counts from the run's observers — with failed (NaN, -1) samples, never-events, no
failure and every sample failed; a file that needs CF decoding read by xarray instead; and a
``mcchain run`` of a requirement scene, ``mcchain verdict`` of it and ``mcchain confirm``
from it, that import no xarray, pandas or dask."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import xarray as xr
from test_cli_commands import fresh_interpreter
from test_decision_verdict import slider_crank_like

from mcchain.decision.allocation_table import allocations, box_allocations
from mcchain.decision.sampled import design_of
from mcchain.decision.summary import requirement_lines, summarize, summary_lines
from mcchain.decision.until import sequential_settings
from mcchain.decision.verdict import VerdictTable
from mcchain.ensemble.io import DamagedEnsemble, open_ensemble
from mcchain.ensemble.per_sample import (
    NeedsDecoding,
    PerSampleEnsemble,
    open_per_sample,
    open_stored,
)
from mcchain.runner.observers import RetryCounts, VerdictLines
from mcchain.scene import load_scene
from mcchain.solvers.retry import SOLVED_BY, retry_counts

REPO = Path(__file__).resolve().parents[1]
SIMULATE = load_scene(REPO / "configs" / "slider-crank-requirement.toml").simulate
"""The shipped scene's ``[simulate]`` (rk45, retries on): what the retry counts name."""


def with_parameters(ds: xr.Dataset, seed: int = 5) -> xr.Dataset:
    """``ds`` with two sampled parameters (for the allocation lines), their units, a
    ``solved_by`` and a [sample.vary] in its settings, as a run stores them."""
    n = ds.sizes["sample"]
    rng = np.random.default_rng(seed)
    values = np.stack([rng.uniform(1e-4, 5e-4, n), rng.uniform(0.7, 0.95, n)], axis=1)
    paths = ["joint.B.clearance", "joint.B.contact.restitution"]
    settings = json.loads(ds.attrs["settings"])
    settings["scene"]["sample"]["vary"] = {
        paths[0]: {"uniform": [1e-4, 5e-4]},
        paths[1]: {"uniform": [0.7, 0.95]},
    }
    solved_by = (np.arange(n) % 5).astype(np.int8)  # every code, 4 = unsolved
    out = ds.assign(
        parameters=(("sample", "param"), values, {"units": "mixed"}),
        solved_by=(("sample",), solved_by, {"units": "1"}),
    )
    out = out.assign_coords(param=paths, param_units=("param", ["m", "1"]))
    out.attrs["settings"] = json.dumps(settings)
    return out


def write_as_a_run(ds: xr.Dataset, path: Path) -> Path:
    """``ds`` written as mcchain's merge writes: no fill values, labels as strings."""
    encoding = {name: {"_FillValue": None} for name in ds.variables}
    ds.to_netcdf(path, engine="netcdf4", encoding=encoding)
    return path


def lines_by_xarray(path: Path) -> list[str]:
    """The verdict lines as the run computed them before: from xarray's Dataset."""
    with open_ensemble(path, dask=False) as ds:
        return summary_lines(
            summarize(ds), allocations(ds), design_of(ds), sequential_settings(ds.attrs)
        )


def observed(path: Path) -> dict[str, Any]:
    """What the run's two observers record for the ensemble ``path`` (its run folder)."""
    scene = SimpleNamespace(simulate=SIMULATE)
    run: Any = SimpleNamespace(folder=path.parent, record={}, job=SimpleNamespace(scene=scene))
    VerdictLines().on_merged(run)
    RetryCounts().on_merged(run)
    return run.record


def assert_same_as_xarray(light: PerSampleEnsemble, ds: xr.Dataset) -> None:
    assert sorted(light.data_vars) == sorted(ds.data_vars)
    assert sorted(light.coords) == sorted(ds.coords)
    assert light.sizes == dict(ds.sizes)
    assert light.attrs.keys() == ds.attrs.keys()
    for name in [*ds.data_vars, *ds.coords]:
        mine, theirs = light[name], ds[name]
        assert mine.dims == theirs.dims, name
        assert mine.dtype == theirs.dtype, name
        assert mine.values.dtype == theirs.values.dtype, name
        assert mine.values.tobytes() == theirs.values.tobytes(), name
        assert {k: repr(v) for k, v in mine.attrs.items()} == {
            k: repr(v) for k, v in theirs.attrs.items()
        }, name


def assert_same_decisions(light: PerSampleEnsemble, ds: xr.Dataset) -> None:
    """Every table ``mcchain export --requirements`` writes (the requirements, the
    allocation, the box) is the same from either read (NaN compared as text)."""
    assert repr(summarize(light)) == repr(summarize(ds))
    assert repr(allocations(light)) == repr(allocations(ds))
    assert repr(box_allocations(light)) == repr(box_allocations(ds))


CASES = {
    "failed, never and met": {},  # 102 diverged (NaN, -1), 154 never separate
    "no failure bit": {"diverged": 0, "never": 0},
    "every sample failed": {"diverged": 256, "never": 0},
}


@pytest.mark.parametrize("case", list(CASES))
def test_per_sample__values_and_verdict_lines_equal_xarrays(tmp_path: Path, case: str) -> None:
    path = write_as_a_run(
        with_parameters(slider_crank_like(**CASES[case])), tmp_path / "ensemble.nc"
    )
    with open_per_sample(path) as light, open_ensemble(path, dask=False) as ds:
        assert_same_as_xarray(light, ds)
        assert_same_decisions(light, ds)
        values = light["peak_contact_force"].isel({"joint": 0}).values
        assert values.tobytes() == ds["peak_contact_force"].isel(joint=0).values.tobytes()
        swapped = light["parameters"].transpose("param", "sample")
        assert swapped.dims == ("param", "sample")
        assert (swapped.values == ds["parameters"].values.T).all()
    expected = lines_by_xarray(path)
    record = observed(path)
    assert record["requirements"] == expected
    with open_ensemble(path, dask=False) as ds:
        assert record["retries"] == retry_counts(ds[SOLVED_BY].values, SIMULATE)
    assert record["retries"]["counts"]["unsolved"] == 256 // 5 + (256 % 5 > 4)
    with open_per_sample(path) as light:
        summaries = summarize(light)
    if case == "no failure bit":
        assert [s.failures for s in summaries] == [0, 256, 256]
        assert [s.undefined for s in summaries] == [0, 0, 0]
    elif case == "every sample failed":
        assert all(s.failures == s.undefined == 256 for s in summaries)
        assert any("no sample has a value to compare (all 256 undefined" in x for x in expected)
    else:
        assert [(s.failures, s.undefined) for s in summaries][:2] == [(102, 102), (102, 102)]
    assert any(x.startswith("  joint.B.clearance") for x in expected)  # allocations, too


def test_per_sample__a_file_to_decode_is_read_by_xarray(tmp_path: Path) -> None:
    """xarray's default encoding writes a ``_FillValue`` (NaN) on every float variable: the
    netCDF4 read refuses the file, :func:`open_stored` gives xarray's Dataset, and the
    observers still record the lines xarray computes."""
    path = tmp_path / "ensemble.nc"
    with_parameters(slider_crank_like()).to_netcdf(path, engine="netcdf4")
    with pytest.raises(NeedsDecoding, match="_FillValue"):
        open_per_sample(path)
    with open_stored(path) as ds:
        assert isinstance(ds, xr.Dataset)
    assert observed(path)["requirements"] == lines_by_xarray(path)


def test_per_sample__a_damaged_file_says_how_to_rebuild(tmp_path: Path) -> None:
    path = tmp_path / "ensemble.nc"
    path.write_bytes(b"CDF\x01 cut short")
    with pytest.raises(DamagedEnsemble, match="--remerge"):
        open_per_sample(path)


@pytest.mark.slow  # a fresh interpreter loads the kernels (2-5 s)
def test_run_verdict_and_confirm__read_without_xarray_and_equal_to_it(tmp_path: Path) -> None:
    """A ``mcchain run`` of the shipped requirement scene (4 samples, retries on) records
    the verdict lines and retry counts xarray gives on its ensemble; ``mcchain verdict`` of
    the run prints the table xarray's Dataset gives, and ``mcchain confirm`` of a range the
    verdict lines xarray gives on its new run: each without importing xarray, pandas or
    dask (0.7-0.95 s of import, then the CF decoding of every variable)."""
    from mcchain.testing.scenes import config_text, with_lines

    scene = tmp_path / "slider.toml"
    scene.write_text(
        with_lines(config_text("slider-crank-requirement.toml"), {"count": "count = 4"})
    )
    folder = tmp_path / "run"
    code = (
        "import sys\n"
        "from mcchain.runner import plan\n"
        f"plan.start_run({str(scene)!r}, run_dir={str(folder)!r}, progress=False)\n"
        "print(sorted(m for m in ('xarray', 'pandas', 'dask') if m in sys.modules))"
    )
    assert fresh_interpreter(code).splitlines()[-1] == "[]"
    record = json.loads((folder / "run.json").read_text())
    path = folder / "ensemble.nc"
    assert record["requirements"] == lines_by_xarray(path)
    assert len(record["requirements"]) > 3 and record["requirements"][0].startswith("requirement")
    with open_ensemble(path, dask=False) as ds, open_per_sample(path) as light:
        assert_same_as_xarray(light, ds)
        assert_same_decisions(light, ds)
        assert record["retries"] == retry_counts(ds[SOLVED_BY].values, SIMULATE)
        by_xarray = VerdictTable(
            summarize(ds), design_of(ds), sequential_settings(ds.attrs), []
        ).lines()
    code = (
        "import json, sys\n"
        "from mcchain.decision.verdict import run_verdict\n"
        f"print(json.dumps(run_verdict({str(folder)!r}).lines()))\n"
        "print(sorted(m for m in ('xarray', 'pandas', 'dask') if m in sys.modules))"
    )
    printed, modules = fresh_interpreter(code).splitlines()[-2:]
    assert modules == "[]"
    assert json.loads(printed) == by_xarray and by_xarray[0].startswith("requirement")
    confirmed = tmp_path / "confirmed"
    code = (
        "import sys\n"
        "from mcchain.decision.confirm import confirm_run\n"
        f"result = confirm_run({str(folder)!r}, 'slider-accuracy', samples=4, progress=False,\n"
        f"    ranges=['joint.B.clearance=:1.5e-4'], run_dir={str(confirmed)!r})\n"
        "print(*result.lines(), sep='\\n')\n"
        "print(sorted(m for m in ('xarray', 'pandas', 'dask') if m in sys.modules))"
    )
    *printed_lines, modules = fresh_interpreter(code).splitlines()
    assert modules == "[]"
    with open_ensemble(confirmed / "ensemble.nc", dask=False) as ds:
        summary = next(s for s in summarize(ds) if s.name == "slider-accuracy")
    by_xarray = requirement_lines(summary, "random" if summary.exact else None)[:2]
    assert summary.samples == 4 and printed_lines[-2:] == by_xarray
