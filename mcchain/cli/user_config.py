"""The user's settings file, for what a user sets once rather than at every run.

``$XDG_CONFIG_HOME/mcchain/config.toml`` (default ``~/.config/mcchain/config.toml``;
``MCCHAIN_CONFIG`` names another file). Every key is optional; today there is one::

    [run]
    background_compile = false  # a cold first run never starts a background compile

A key this version does not know, or a value of the wrong type, is refused in one line
naming the file and the key (exit 2), as a scene's would be.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from mcchain.errors import RunError

KEYS: dict[str, dict[str, type]] = {"run": {"background_compile": bool}}
"""The keys of the file, by table, with their types."""


def config_path() -> Path:
    """Where the user's settings file is (it need not exist)."""
    named = os.environ.get("MCCHAIN_CONFIG")
    if named:
        return Path(named)
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "mcchain" / "config.toml"


def load_user_config() -> dict[str, dict[str, Any]]:
    """The user's settings, checked against :data:`KEYS` (empty without a file)."""
    import tomllib

    path = config_path()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return {}
    except OSError as exc:
        raise RunError(f"{path}: cannot be read ({exc.strerror})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RunError(f"{path}: {exc}") from None
    for table, values in data.items():
        known = KEYS.get(table)
        if known is None or not isinstance(values, dict):
            raise RunError(f"{path}: [{table}]: unknown table (known: {', '.join(KEYS)})")
        for key, value in values.items():
            if key not in known:
                raise RunError(f"{path}: {table}.{key}: unknown key (known: {', '.join(known)})")
            if not isinstance(value, known[key]):
                kind = known[key].__name__
                raise RunError(f"{path}: {table}.{key}: expected a {kind}, got {value!r}")
    return data


def background_compile_off() -> str | None:
    """What switches the background compile of a cold first run off in the user's settings
    (for the run's note), or None."""
    if load_user_config().get("run", {}).get("background_compile", True):
        return None
    return f"{config_path()} (run.background_compile = false)"
