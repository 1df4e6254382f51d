"""Per-test CPU of the native compiles of generated lane modules (issue 36, item 5; ci.md).

A pytest plugin (``-p native_profile`` with this folder on ``PYTHONPATH``, ``NATPLUG_DIR``
naming an output folder): every compile of a ``NativeModule`` entry (not a load from the
cache) appends ``{"test", "module", "entry", "cpu"}`` to ``<worker>.jsonl`` at the end of
the run. Run the suite with an empty ``MCCHAIN_CACHE_DIR`` so that every module compiles
once (numba's own compiles: ``cold_profile.py`` in this folder)."""

import json
import os
import time

_cur = {"test": None}
_rec = []


def pytest_configure(config):
    import mcchain.codegen.native as n

    orig = n.NativeModule._load_or_compile

    def wrapped(self, name, argtypes):
        t = time.process_time()
        before = n.COUNTS["compiled"]
        try:
            return orig(self, name, argtypes)
        finally:
            if n.COUNTS["compiled"] > before:
                _rec.append(
                    {
                        "test": _cur["test"],
                        "module": self.name,
                        "entry": name,
                        "cpu": time.process_time() - t,
                    }
                )

    n.NativeModule._load_or_compile = wrapped


def pytest_runtest_protocol(item, nextitem):
    _cur["test"] = item.nodeid


def pytest_unconfigure(config):
    w = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(os.path.join(os.environ["NATPLUG_DIR"], f"{w}.jsonl"), "w") as f:
        for r in _rec:
            f.write(json.dumps(r) + "\n")
