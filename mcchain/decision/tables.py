"""The decision layer's CSV files: written atomically, floats exactly, NaN as NaN."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any


def _csv_value(value: Any) -> Any:
    if isinstance(value, float):
        return "NaN" if math.isnan(value) else repr(value)
    return value


def write_csv(path: Path, columns: tuple[str, ...], rows: list[dict[str, Any]]) -> None:
    """A CSV of ``rows`` under ``columns``, written atomically (floats exactly, NaN as NaN)."""
    from mcchain.ensemble.io import write_text_atomic

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_value(v) for k, v in row.items()})
    write_text_atomic(path, buffer.getvalue())
