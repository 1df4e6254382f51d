"""A page rendered by a real browser: headless Chromium, as the tests and the README's
screenshots use it (``apt-get install chromium`` on Debian; :func:`chromium` is None where
it is absent, and the tests say so when they skip).

Each call starts one browser process with a fresh profile folder (removed after), no
network features and no sandbox (the tests run as root in CI), and waits for it with a
timeout: nothing started outlives the call.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)
"""Flags of every call: headless, no GPU, nothing fetched or synced in the background."""
TIMEOUT = 120.0
"""Seconds a call may take (a loaded 2-core machine takes 1-5 s)."""


def chromium() -> str | None:
    """The Chromium executable on PATH (Debian: ``chromium``), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def _run(page: Path, *flags: str) -> subprocess.CompletedProcess[str]:
    exe = chromium()
    if exe is None:
        raise FileNotFoundError("chromium is not installed (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory(prefix="mcchain-chromium-") as profile:
        return subprocess.run(
            [exe, *FLAGS, f"--user-data-dir={profile}", *flags, Path(page).resolve().as_uri()],
            capture_output=True,
            text=True,
            timeout=TIMEOUT,
            check=True,
            stdin=subprocess.DEVNULL,
        )


def dump_dom(page: Path) -> str:
    """The DOM of ``page`` after the browser loaded it, serialised (``--dump-dom``)."""
    return _run(page, "--dump-dom").stdout


def screenshot(page: Path, png: Path, width: int = 1280, height: int = 2000) -> Path:
    """A screenshot of the top ``width`` × ``height`` CSS pixels of ``page`` into ``png``."""
    _run(page, f"--screenshot={Path(png).resolve()}", f"--window-size={width},{height}")
    return png


def print_pdf(page: Path, pdf: Path) -> Path:
    """``page`` printed to ``pdf`` as the browser prints it (its print CSS, no header)."""
    _run(page, f"--print-to-pdf={Path(pdf).resolve()}", "--no-pdf-header-footer")
    return pdf
