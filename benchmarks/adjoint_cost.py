"""What the reverse mode costs (issue 31): the wall time of `WalkAdjoint.gradient` against the plain walk it
differentiates, and the states it holds, against the horizon N (chemistry steps), with checkpoints at the spacing
that holds the fewest bytes (`checkpoint_spacing`, O(√N)) and with every substep stored (one stretch), on one
settled walker (float64, the paper's walker model: overdamped, explicit point contact, k_f = 0.1, the insensitive
wave); and at the longest horizon the gradient through the whole run (back through the settling too) against the
settling's replay plus the walk.

    wavewarp bench adjoint_cost --device cuda --periods 0.25 0.5 1 2 --out benchmarks/results
    wavewarp bench adjoint_cost --device cpu --set level=1 --periods 0.25 0.5 1

Every horizon starts from the same settled state; the walk, the stored pass and the checkpointed pass run side by
side in one process, each timed the second time it runs (kernels compiled, its graphs captured). Writes adjoint_cost_<device>.json and .png (time ratio and state bytes against N).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import date

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from wavewarp.adjoint import ADJOINT_PARAMETERS, WalkAdjoint  # noqa: E402
from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402

GOAL = 5.0  # issue 31: the gradient at most 5× the walk's time
PAPER_WALK = ["dtype=float64", "mechanics=overdamped", "contact_solve=explicit", "sharpness=0.1", "sensitive=false",
              "drag=60", "frames=1"]  # fmt: skip


def timed(call, device) -> tuple:
    wp.synchronize_device(device)
    start = time.perf_counter()
    value = call()
    wp.synchronize_device(device)
    return time.perf_counter() - start, value


def measure(args, device) -> dict:
    module = load_scene(args.scene)
    longest = max(args.periods)
    p = resolve(module.Parameters, None, [*PAPER_WALK, *args.set, f"periods={longest}"])
    run = module.build(p, device=device, report=lambda message: None)
    steps_per_period = run.frames * run.steps_per_frame / longest
    start = [wp.clone(a) for a in run.wave.state.arrays() + [run.dynamics.state.x, run.dynamics.state.v]]

    def from_start():
        for live, saved in zip(run.wave.state.arrays() + [run.dynamics.state.x, run.dynamics.state.v], start):
            wp.copy(live, saved)
        run.shell.update_reference(run.wave.c)

    rows, walker = [], WalkAdjoint(run)
    passes = {"checkpointed": WalkAdjoint(run, args.wrt), "stored": None}
    for periods in sorted(args.periods):
        steps = max(1, round(periods * steps_per_period))
        passes["stored"] = WalkAdjoint(run, args.wrt, checkpoint_every=steps)
        for _ in range(2):  # the second of each: kernels compiled, graphs of these lengths captured
            from_start()
            walk_seconds, objective = timed(lambda: walker.walk(steps), device)
        row = {"periods": periods, "steps": steps, "forward_seconds": walk_seconds, "objective": objective}
        for label, adjoint in passes.items():
            for _ in range(2):
                from_start()
                seconds, result = timed(lambda: adjoint.gradient(steps), device)
            row[label] = {"seconds": seconds, "ratio": seconds / walk_seconds, "state_bytes": result["state_bytes"],
                          "checkpoints": result["checkpoints"], "checkpoint_every": result["checkpoint_every"],
                          "stored_substeps": result["stored_substeps"], "gradient": result["gradient"]}  # fmt: skip
        print(f"N = {steps:5d} ({periods:g} T): walk {walk_seconds:.3g} s; checkpointed "
              f"{row['checkpointed']['seconds']:.3g} s ({row['checkpointed']['ratio']:.2f}×, "
              f"{row['checkpointed']['state_bytes'] / 2**20:.3g} MiB); stored {row['stored']['seconds']:.3g} s "
              f"({row['stored']['ratio']:.2f}×, {row['stored']['state_bytes'] / 2**20:.3g} MiB)", flush=True)
        rows.append(row)
    whole = whole_run(run, args.wrt, rows[-1], from_start, device)
    substeps, n = run.coupled.substeps, run.mesh.n_vertices
    return {"scene": module.NAME, "set": [*PAPER_WALK, *args.set], "wrt": list(args.wrt), "vertices": n,
            "substeps": substeps, "rows": rows, "memory_exponents": memory_exponents(rows), "whole_run": whole}  # fmt: skip


def whole_run(run, wrt, row: dict, from_start, device) -> dict:
    """The longest horizon back through the settling too, against the settling's replay plus the walk."""
    adjoint = WalkAdjoint(run, wrt)
    for _ in range(2):
        settle_seconds, _ = timed(adjoint.replay_settling, device)
    for _ in range(2):
        from_start()
        seconds, result = timed(lambda: adjoint.gradient(row["steps"], settle=True), device)
    forward = settle_seconds + row["forward_seconds"]
    print(f"whole run (settling {run.settle_steps} steps + N = {row['steps']}): forward {forward:.3g} s, gradient "
          f"{seconds:.3g} s ({seconds / forward:.2f}×)", flush=True)
    return {"steps": row["steps"], "settle_steps": list(run.settle_steps), "settle_seconds": settle_seconds,
            "forward_seconds": forward, "seconds": seconds, "ratio": seconds / forward, "gradient": result["gradient"]}


def memory_exponents(rows) -> dict:
    """The least-squares slope of log(state bytes) against log N, per pass (1/2: O(√N); 1: every state)."""
    steps = np.log([row["steps"] for row in rows])
    if len(rows) < 2:
        return {}
    return {label: float(np.polyfit(steps, np.log([row[label]["state_bytes"] for row in rows]), 1)[0])
            for label in ("checkpointed", "stored")}  # fmt: skip


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    steps = np.array([row["steps"] for row in rows])
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for label, style in (("checkpointed", "o-"), ("stored", "s--")):
        left.plot(steps, [row[label]["ratio"] for row in rows], style, label=label)
        right.loglog(steps, [row[label]["state_bytes"] / 2**20 for row in rows], style, label=label)
    reference = rows[0]["checkpointed"]["state_bytes"] / 2**20 * np.sqrt(steps / steps[0])
    right.loglog(steps, reference, ":", color="grey", label="∝ √N")
    left.axhline(GOAL, color="grey", linestyle=":", label=f"goal: {GOAL:g}×")
    left.set_ylim(0, max(GOAL, *[row[label]["ratio"] for row in rows for label in ("checkpointed", "stored")]) * 1.15)
    left.set_xlabel("chemistry steps N")
    left.set_ylabel("gradient time / walk time")
    left.set_title(f"{len(result['wrt'])} parameters, one pass back")
    right.set_xlabel("chemistry steps N")
    right.set_ylabel("states held (MiB)")
    for ax in (left, right):
        ax.legend(fontsize=8)
    fig.suptitle(f"reverse mode, {result['scene']} ({result['vertices']} vertices, {result['substeps']} substeps a step), "
                 f"{result['device_name']}", fontsize=9)  # fmt: skip
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench adjoint_cost", description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="sphere-walker")
    parser.add_argument("--periods", type=float, nargs="+", default=[0.25, 0.5, 1.0], help="horizons, in FHN periods")
    parser.add_argument("--wrt", nargs="*", default=list(ADJOINT_PARAMETERS))
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="scene parameters")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    result = {"benchmark": "adjoint_cost", "date": date.today().isoformat(), **describe_device(device),
              **measure(args, device)}  # fmt: skip
    print(f"memory exponents (log bytes / log N): {result['memory_exponents']}")
    write_result(result, args.out, f"adjoint_cost_{device_tag(device)}", chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())
