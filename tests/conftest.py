"""Test-wide settings.

Hypothesis: under CI (``CI`` set, as ``.ci/run`` does) every property test is derandomized,
so a CI run cannot fail on a draw that a developer's run never made; the example database is
off there too. Developers' runs keep random draws (and the database) to find new failures.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture
def mcchain(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> Callable[..., Any]:
    """The CLI run in this process: ``mcchain(*args, cwd=...)`` returns its exit code and
    output (:func:`test_cli_commands.in_process`)."""
    from test_cli_commands import in_process

    return in_process(monkeypatch, capsys)
