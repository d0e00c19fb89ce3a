"""What a walker gradient costs (issue 31): the wall time of `walker_gradient` for P = 1, 2, ... parameters
(one step: 1 + 2P worlds in one float64 batch) and for the rest shape's control points (`--shape-points`: n points,
P = 3n coordinates) against the forward run it differentiates (one world, the same batch code, float64), and on a
GPU the device memory each holds.

    wavewarp bench gradient_cost --device cuda --scene sphere-walker --periods 1 --out benchmarks/results
    wavewarp bench gradient_cost --device cuda --scene prism-walker --quick --wrt --shape-points 1,4,16,all

Central differences keep no history: their memory is that of 1 + 2P worlds whatever the horizon (no
tape, no checkpoints). Writes gradient_cost.json and .png (time ratio against P).
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
from datetime import date
from types import SimpleNamespace

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from wavewarp.device import describe_device, resolve_device  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402
from wavewarp.gradients import control_points  # noqa: E402
from wavewarp.walker_gradients import PER_WORLD, walker_gradient  # noqa: E402


def device_memory(device):
    """Bytes the device's memory pool holds now (None on a CPU)."""
    return wp.get_mempool_used_mem_current(device) if device.is_cuda and wp.is_mempool_enabled(device) else None


def timed(make, device) -> tuple:
    """(seconds, device bytes held once the first batch is built) of `make(on_built)`, which calls `on_built()`
    after building each batch (the first call counts)."""
    held = {}
    gc.collect()  # the last run's arrays released before the pool is read
    wp.synchronize_device(device)
    before = device_memory(device)
    start = time.perf_counter()
    make(lambda: held.setdefault("bytes", None if before is None else device_memory(device) - before))
    wp.synchronize_device(device)
    return time.perf_counter() - start, held.get("bytes")


def measure(args, device) -> dict:
    module = load_scene(args.scene)
    p = resolve(module.Parameters, getattr(module, "QUICK", {}) if args.quick else None,
                [*args.set, f"periods={args.periods}", "frames=1", "dtype=float64"])  # fmt: skip

    def forward(on_built):
        batch = module.build_batch([p], seeds=[0], device=device, report=lambda message: None)
        on_built()
        batch.run()

    def gradient(wrt, points=()):
        def make(on_built):
            def build(ps, **options):
                batch = module.build_batch(ps, **options)
                on_built()  # the first call: the main batch
                return batch

            scene = SimpleNamespace(recipe=module.recipe, build_batch=build)
            walker_gradient(scene, p, wrt, points=points, steps=(args.step,), device=device,
                            report=lambda message: None)  # fmt: skip

        return make

    forward(lambda: None)  # compiles every kernel before anything is timed
    seconds, held = timed(forward, device)
    rows = [{"parameters": 0, "worlds": 1, "seconds": seconds, "bytes": held, "ratio": 1.0}]
    vertices = len(module.recipe(p, device=device, report=lambda message: None)[0].vertices)
    runs = [("parameters", args.wrt[:count], ()) for count in range(1, len(args.wrt) + 1)]
    for count in args.shape_points:
        n = vertices if count == "all" else min(int(count), vertices)
        runs.append(("shape", [], control_points(np.linspace(0, vertices - 1, n).round().astype(int), vertices)))
    for kind, wrt, points in runs:
        seconds, held = timed(gradient(wrt, points), device)
        count = len(wrt) + 3 * len(points)
        rows.append({"kind": kind, "parameters": count, "worlds": 1 + 2 * count, "seconds": seconds, "bytes": held,
                     "ratio": seconds / rows[0]["seconds"]})  # fmt: skip
        print(f"{kind} P = {count}: {1 + 2 * count} worlds, {seconds:.2f} s, {rows[-1]['ratio']:.2f} × the forward "
              "run" + (f", {held / 2**20:.1f} MiB" if held is not None else ""))  # fmt: skip
    return {"scene": args.scene, "periods": args.periods, "step": args.step, "wrt": args.wrt,
            "control_points": vertices, "rows": rows}  # fmt: skip


def chart(result: dict, path: str) -> None:
    import matplotlib.pyplot as plt

    rows = result["rows"]
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for kind, marker in (("parameters", "o-"), ("shape", "s-")):
        chosen = [r for r in rows if r.get("kind") == kind]
        if chosen:
            ax.plot([r["parameters"] for r in chosen], [r["ratio"] for r in chosen], marker, label=f"measured: {kind}")
    ax.plot([r["parameters"] for r in rows[1:]], [r["worlds"] for r in rows[1:]], ":", color="grey",
            label="worlds (one after another)")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(5.0, color="tab:red", ls="--", lw=0.8, label="goal: 5 × the forward run")
    ax.set_xlabel("parameters P (1 + 2P worlds)")
    ax.set_ylabel("gradient time / forward time")
    ax.set_title(f"{result['scene']}, {result['periods']:g} T₀, {result['device_name']}", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_png(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench gradient_cost", description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--scene", default="sphere-walker")
    parser.add_argument("--periods", type=float, default=1.0)
    parser.add_argument("--wrt", nargs="*", choices=PER_WORLD, default=list(PER_WORLD))
    parser.add_argument("--shape-points", type=lambda text: [n if n == "all" else int(n) for n in text.split(",") if n],
                        default=[], metavar="N1,N2,...", help="numbers of control points (spread over the mesh, or "
                        "all) whose coordinates the shape gradient takes: one run each")  # fmt: skip
    parser.add_argument("--step", type=float, default=1e-4, help="relative step of the central differences")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="fixed scene parameters")
    parser.add_argument("--quick", action="store_true", help="the scene's quick mesh (a CPU smoke run)")
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    result = {"benchmark": "gradient_cost", "date": date.today().isoformat(), **describe_device(device),
              "quick": args.quick, **measure(args, device)}  # fmt: skip
    write_result(result, args.out, "gradient_cost", chart)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
