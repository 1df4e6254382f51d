"""Where the lanes' step goes, measured: cpu-clock samples on the machine code.

    python benchmarks/profile_lanes.py [--kernel rk4|rk45|verdict] [--text FILE.py] [--seconds 15]
        [--top 12] [--disassembly FILE]

The kernel: ``rk4`` (default), the rk4 lanes' ``erk_run`` on bench_paired's scene, the
clearance double pendulum (its captured arguments: 256 samples, 2,000 steps); ``rk45``, the
rk45 lanes' ``adaptive_run`` on the Flores slider-crank (``configs/slider-crank-flores.toml``
as configured, 512 samples, 4 ms: bench_speed's ``adaptive`` run); ``verdict``, the rk45
lanes of the requirement verdict (``configs/slider-crank-requirement.toml``, its outputs,
``histories = "none"``, 256 samples, 20 ms: bench_paired's ``verdict``). The text (default: this
tree's generated text of that kernel) is compiled (:class:`mcchain.codegen.native.
NativeModule`, its object code cached in a scratch folder) and its entry called on the
captured arguments (1 thread) for ``--seconds`` under ``perf record -e cpu-clock`` (a
software clock: this VM has no hardware counters). Each
sample's instruction address is placed in the entry's object code (read back from the
cache file and disassembled with ``objdump``), and the samples are summed per basic block:
the table gives each hot block's share of the kernel's samples, its size in instructions
and bytes, and its mix (vector fused multiply-adds, other vector FP operations, divisions and square
roots, and the explicit vector loads, stores and register moves: a load folded into an
operation counts with its operation).
llvm-mca (reading.md, sixth stop) models a block's throughput; this measures where the
time is actually spent. A sample lands on the instruction after the one that held the
retirement (skid): within a block that is noise, across blocks it is not.

Needs ``perf`` and ``objdump`` on the PATH. Prints its table (readings:
benchmarks/results/roofline/reading.md).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

_RUN = """
import json, os, sys, time
sys.path.insert(0, {bench!r})
import numba
import profile_lanes as pl
from mcchain.codegen import native
from mcchain.codegen.native import NativeModule
numba.set_num_threads(1)
given = os.path.exists({text!r})
entry, groups, args, source = pl.captured({kernel!r}, with_text=not given)
if not given:
    open({text!r}, "w").write(source)  # this tree's text
module = NativeModule(open({text!r}).read(), "profiled")
pl.call(module, entry, groups, args)  # compiled (or loaded) before the clock
print(json.dumps(native._LOADED), flush=True)
t0 = time.time()
while time.time() - t0 < {seconds}:
    pl.call(module, entry, groups, args)
"""


def captured(kernel: str, with_text: bool) -> tuple[str, int, tuple[Any, ...], str]:
    """The entry, lane groups, arguments and (``with_text``, else "") this tree's text of
    ``kernel``'s call (bench_paired's: see the module docstring)."""
    import bench_paired

    groups, args = bench_paired._captured_call(kernel, 256, 2000)
    source = ""
    if with_text:
        with tempfile.TemporaryDirectory(prefix="mcchain-profile-text-") as scratch:
            source = bench_paired._text(str(REPO), Path(scratch), kernel)
    return bench_paired.ENTRY[kernel], groups, args, source


def call(module: Any, entry: str, groups: int, args: tuple[Any, ...]) -> None:
    """``entry`` of ``module`` over every lane group, on fresh copies of ``args``."""
    import numpy as np

    fresh = [np.copy(a) if isinstance(a, np.ndarray) else a for a in args]
    getattr(module, entry)(0, groups, *fresh)


_INSTRUCTION = re.compile(r"\s+([0-9a-f]+):\t((?:[0-9a-f]{2} )+)\s*\t(\S+)\s*(.*)")


def _instructions(objfile: Path) -> list[tuple[int, int, str, str]]:
    """(offset, length in bytes, mnemonic, operands) of every instruction of the entry's
    code section."""
    command = ["objdump", "-d", "--insn-width=15", "-j", ".ltext", str(objfile)]
    text = subprocess.run(command, check=True, capture_output=True, text=True).stdout
    out = []
    for line in text.splitlines():
        m = _INSTRUCTION.match(line)
        if m:
            out.append((int(m.group(1), 16), len(m.group(2).split()), m.group(3), m.group(4)))
    return out


def _blocks(instructions: list[tuple[int, int, str, str]]) -> list[list[tuple[int, int, str, str]]]:
    """The basic blocks: a new one at every jump target and after every jump."""
    leaders = {instructions[0][0]}
    for k, (_, _, op, arg) in enumerate(instructions):
        if op.startswith("j"):
            target = re.match(r"([0-9a-f]+)", arg)
            if target:
                leaders.add(int(target.group(1), 16))
            if k + 1 < len(instructions):
                leaders.add(instructions[k + 1][0])
    blocks: list[list[tuple[int, int, str, str]]] = []
    for ins in instructions:
        if ins[0] in leaders or not blocks:
            blocks.append([])
        blocks[-1].append(ins)
    return blocks


def _kind(op: str, arg: str) -> str:
    """The class of one instruction for the table's mix."""
    if re.match(r"vf(n?)m(add|sub)", op):
        return "fma"
    if op in ("vmulpd", "vaddpd", "vsubpd", "vmaxpd", "vminpd"):
        return "fp"
    if op in ("vdivpd", "vsqrtpd"):
        return "div"
    if op in ("vmovapd", "vmovupd"):
        if arg.count("%zmm") == 2 or arg.count("%ymm") == 2:
            return "move"
        return "load" if arg.split(",")[-1].strip().startswith("%") else "store"
    return "other"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kernel", choices=("rk4", "rk45", "verdict"), default="rk4")
    parser.add_argument("--text", default=None, help="a generated text (.py); default: this tree's")
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--disassembly", default=None, help="write the entry's objdump here")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="mcchain-profile-") as scratch:
        work = Path(scratch)
        text = work / "text.py"  # written by the first run when not given
        if args.text:
            text.write_text(Path(args.text).read_text())
        env = dict(os.environ, MCCHAIN_CACHE_DIR=str(work / "cache"))
        bench = str(Path(__file__).parent)
        run = _RUN.format(bench=bench, kernel=args.kernel, text=str(text), seconds=0)
        subprocess.run([sys.executable, "-c", run], env=env, check=True, capture_output=True)
        run = _RUN.format(bench=bench, kernel=args.kernel, text=str(text), seconds=args.seconds)
        data = work / "perf.data"
        out = subprocess.run(
            ["perf", "record", "-q", "-e", "cpu-clock", "-F", "10000", "-o", str(data),
             sys.executable, "-c", run],
            env=env, check=True, capture_output=True, text=True,
        )  # fmt: skip
        loaded = json.loads(out.stdout.splitlines()[0])
        ((symbol, address),) = ((k, v) for k, v in loaded.items() if k.startswith("profiled."))
        entry = "erk_run" if args.kernel == "rk4" else "adaptive_run"
        (cached,) = (work / "cache" / "native").glob(f"profiled-{entry}-*.bin")
        from mcchain.codegen.native import _object_code

        objfile = work / "entry.o"
        objfile.write_bytes(_object_code(cached.read_bytes()) or b"")
        ips = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip"], check=True,
                             capture_output=True, text=True).stdout.split()  # fmt: skip
        instructions = _instructions(objfile)
        if args.disassembly:
            command = ["objdump", "-d", "--no-show-raw-insn", "-j", ".ltext", str(objfile)]
            listing = subprocess.run(command, check=True, capture_output=True, text=True)
            Path(args.disassembly).write_text(listing.stdout)
    # the entry's symbol is at offset 0 of its section: an address minus the entry's is
    # the offset objdump prints
    samples = collections.Counter(int(ip, 16) - address for ip in ips)
    end = instructions[-1][0] + instructions[-1][1]
    inside = sum(n for off, n in samples.items() if 0 <= off < end)
    print(f"`python benchmarks/profile_lanes.py --kernel {args.kernel} --seconds {args.seconds:g}"
          f"{' --text ' + args.text if args.text else ''}`: {len(ips):,} samples, "
          f"{inside:,} in {symbol} ({100 * inside / max(len(ips), 1):.0f} %); load average "
          f"{os.getloadavg()[0]:.1f}\n")  # fmt: skip
    rows = []
    for block in _blocks(instructions):
        share = sum(samples.get(off, 0) for off, _, _, _ in block)
        mix = collections.Counter(_kind(op, arg) for _, _, op, arg in block)
        rows.append((share, block[0][0], len(block), sum(n for _, n, _, _ in block), mix))
    print(
        "| share of the kernel's samples | block at | instructions | bytes | fma | other FP "
        "| div/sqrt | loads | stores | moves |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for share, start, count, nbytes, mix in sorted(rows, reverse=True)[: args.top]:
        print(f"| {100 * share / max(inside, 1):.1f} % | {start:#x} | {count} | {nbytes:,} | "
              f"{mix['fma']} | {mix['fp']} | {mix['div']} | {mix['load']} | {mix['store']} | "
              f"{mix['move']} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
