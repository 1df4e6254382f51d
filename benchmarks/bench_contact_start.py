"""The start-up transient of a contact-law pin, seated against pressed (issue 35, item 3).

``configs/slider-crank-requirement.toml`` with ``model = "contact"`` at the piston pin B,
from its assembled state (crank at top dead centre, 5000 rpm), each ``[joint.contact]
start``: the nominal instance over the config's whole run (stored every ``--output-dt``),
and ``--samples`` instances of the config's sweep (clearance, restitution) over the first
0.5 ms. Reports the continuous peak of the pin force in [0, 0.5 ms] (the run to 0.5 ms: its
``peak_contact_force``) and the largest stored force in later windows, and draws the pin
force over the first 3 ms.

    python benchmarks/bench_contact_start.py [--samples 64] [--output-dt 1e-6]

Prints a Markdown table and writes ``benchmarks/results/contact_start/bench.md`` and
``docs/images/contact-start.png``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "contact_start"
IMAGE = ROOT / "docs" / "images" / "contact-start.png"
CONFIG = ROOT / "configs" / "slider-crank-requirement.toml"
STARTS = ("seated", "pressed", "centred")
LIMIT = 5000.0  # N: the config's requirement
PIN = 2  # joint B
WINDOWS = ((0.5e-3, 2e-3), (2e-3, 3e-3), (3e-3, 12e-3), (12e-3, 24e-3))  # s


def scene_text(start: str, sampled: bool) -> str:
    """The config with model contact at B and ``start``; without its ``[sample]`` unless
    ``sampled`` (its requirement dropped either way: not evaluated here)."""
    text = CONFIG.read_text(encoding="utf-8").split("[[requirement]]")[0]
    text = text.replace('model = "auto"', 'model = "contact"')
    text = text.replace("restitution = 0.9", f'restitution = 0.9\nstart = "{start}"')
    return text if sampled else text.split("[sample]")[0]


def run(text: str, nsample: int | None, **settings: float) -> dict[str, np.ndarray]:
    scene = load_scene_text(text)
    model = compile_model(scene, nsample=nsample)
    start = assemble(model)
    sim = scene.simulate.model_copy(update=settings)
    return simulate(
        model, sim, q_start=start.q, v_start=start.v, status=start.status,
        history_dtype=np.float64,
    )  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--output-dt", type=float, default=1e-6)
    args = parser.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    histories, rows, sweep = {}, [], []
    for start in STARTS:
        began = time.perf_counter()
        whole = run(scene_text(start, False), None, output_dt=args.output_dt)
        early = run(scene_text(start, False), None, t_end=0.5e-3, output_dt=args.output_dt)
        t, force = whole["time"], whole["contact_force"][0, :, PIN]
        histories[start] = (t, force)
        later = [float(np.max(force[(t >= lo) & (t <= hi)])) for lo, hi in WINDOWS]
        peaks = (early["peak_contact_force"][0, PIN], whole["peak_contact_force"][0, PIN])
        impacts = int(whole["impact_count"][0, PIN])
        rows.append((start, float(force[0]), float(peaks[0]), *later, float(peaks[1]), impacts))
        for t_end in (0.5e-3, None):  # the start-up, then the config's whole run
            ensemble = run(scene_text(start, True), args.samples, output_dt=1e-4,
                           **({} if t_end is None else {"t_end": t_end}))  # fmt: skip
            peaks = ensemble["peak_contact_force"][:, PIN]
            spread = np.percentile(peaks, [0, 50, 100])
            sweep.append((start, "0.5 ms" if t_end else "24 ms", *spread,
                          int(np.count_nonzero(peaks > LIMIT)),
                          int(np.count_nonzero(ensemble["status"]))))  # fmt: skip
        print(f"{start}: {time.perf_counter() - began:.0f} s", flush=True)
    head = ["start", "F_n(0), N", "peak [0, 0.5] ms, N"]
    head += [f"stored max [{lo * 1e3:g}, {hi * 1e3:g}] ms, N" for lo, hi in WINDOWS]
    head += ["peak over 24 ms, N", "impacts"]
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for start, *values, impacts in rows:
        lines.append(f"| {start} | " + " | ".join(f"{x:,.1f}" for x in values) + f" | {impacts} |")
    lines += ["", f"The config's sweep, {args.samples} instances (clearance 0.1–0.5 mm, "
              "restitution 0.7–0.95): the continuous peak of the pin force over the first "
              "0.5 ms and over the config's 24 ms:", "",
              "| start | run | peak: min, N | median, N | max, N | instances above 5 kN | failed |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    for start, span, low, median, high, above, failed in sweep:
        lines.append(f"| {start} | {span} | {low:,.1f} | {median:,.1f} | {high:,.1f} | "
                     f"{above} of {args.samples} | {failed} |")  # fmt: skip
    table = "\n".join(lines)
    print(table)
    command = "python benchmarks/bench_contact_start.py " + " ".join(
        f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items()
    )
    (RESULTS / "bench.md").write_text(
        f"# Start-up transient of a contact-law pin\n\n`{command}`\n\n"
        'configs/slider-crank-requirement.toml, model = "contact" at the piston pin B, '
        "rk45 at the config's rtol 1e-7; the nominal instance (c = 0.5 mm, e = 0.9) over the "
        f"config's 24 ms, stored every {args.output_dt:g} s (F_n(0) and the peak in the first "
        "0.5 ms: continuous, the peak of a run to 0.5 ms).\n\n" + table + "\n",
        encoding="utf-8",
    )
    plot(histories)


def plot(histories: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(8, 6.4), sharex=True, constrained_layout=True)
    styles = {"seated": "tab:red", "pressed": "tab:blue", "centred": "tab:gray"}
    panels = ((axes[0], ("seated", "pressed")), (axes[1], ("centred",)))
    for ax, starts in panels:
        for start in starts:
            t, force = histories[start]
            shown = t <= 3e-3
            ax.plot(t[shown] * 1e3, force[shown] / 1e3, color=styles[start], lw=1.4,
                    label=f'start = "{start}"')  # fmt: skip
        ax.axhline(LIMIT / 1e3, color="k", lw=0.8, ls="--", label="requirement: 5 kN")
        ax.set_ylabel("pin force F_n at B, kN")
        ax.set_ylim(bottom=0.0)
        ax.legend(loc="upper right")
    axes[1].set_xlabel("time, ms")
    axes[1].set_xlim(0.0, 3.0)
    axes[0].set_title(
        'Slider-crank at 5000 rpm, model = "contact" at the piston pin: the first 3 ms'
    )
    fig.savefig(IMAGE, dpi=130)
    plt.close(fig)


if __name__ == "__main__":
    main()
