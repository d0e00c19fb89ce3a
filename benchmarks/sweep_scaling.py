"""Sweep scaling benchmark (docs/theory/sweeps.md): one sweep on 1, 2, 4, ... GPUs (or CPU workers).

    wavewarp bench sweep_scaling --device cuda --workers 1,2 --out benchmarks/results [--deterministic] [--kept-cluster]
    wavewarp bench sweep_scaling --sweep fig-s1b --device cuda --workers 1,2 --deterministic
    wavewarp bench sweep_scaling --quick --device cpu --workers 1,2 --out DIR     # a CPU smoke run

Runs the same sweep (default `--sweep locomotion`: the sphere walker at level 3 over 2 periods, AC ∈
{0, 0.1, 0.2, 0.3} × sensitive/insensitive × 2 seeds with noise 1e-3; `fig-s1b`: buckling-modes over
AI × thickness, 16 points as 4 batched runs; `--quick`: cube-waves, 4 quick points) with the
embedded Dask cluster on the first N GPUs (CUDA_VISIBLE_DEVICES) or N CPU workers, for every N
of `--workers`, each in a fresh process and folder, after one warm-up sweep that fills the kernel
cache (`--no-warm-up`: the cache is warm from an earlier sweep; no warm-up and no run-to-run baseline). Writes sweep_scaling_DEVICE[_deterministic].json: per N the wall time, the aggregate mechanics (or wave)
steps per second, the parallel efficiency against the smallest N, the points' own wall times
(summed, and the longest: what the workers could not share), and how many table values
differ from the smallest N's (0 expected with --deterministic; on a GPU float atomics otherwise
reorder sums from run to run: the warm-up sweep, the same sweep run again on the smallest N, gives
that run-to-run baseline); and the chart, sweep_scaling_DEVICE[_deterministic].png. With
`--kept-cluster`, each N is also timed on a `wavewarp cluster` kept running (the second sweep sent
there: no cluster start, imports or kernel loading in its wall time).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import os
import signal
import subprocess
import sys
import tempfile
import time
from datetime import date

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.io import write_json, write_png  # noqa: E402

SWEEPS = {
    "locomotion": ["sphere-walker", "--grid", "AC=0,0.1,0.2,0.3", "--grid", "sensitive=true,false", "--seeds", "2",
                   "--set", "noise=1e-3", "--set", "level=3", "--set", "periods=2"],
    # Fig. S1b's sweep made small: 16 points in 4 batched runs of 4 worlds (level 3, the steep front to t = 12)
    "fig-s1b": ["buckling-modes", "--grid", "AI=10.5,11.5,12.5,13.5", "--grid", "thickness=0.1,0.3,0.5,0.75",
                "--set", "level=3", "--set", "k=3", "--set", "t_end=12", "--set", "relax_iterations=500",
                "--set", "adaptive_dt=false", "--set", "self_contact=false", "--batch", "4"],
    "quick": ["cube-waves", "--quick", "--grid", "gamma=0.8,0.9,1.0,1.1"],
}  # fmt: skip
TIMING = ("wall_time_s", "device")  # columns that may differ between equal runs


def workers_command(command: list, workers: int, device: str):
    """`command` and its environment for `workers` GPUs (the first ones) or CPU workers."""
    env = dict(os.environ)
    if device == "cuda":
        env["CUDA_VISIBLE_DEVICES"] = ",".join(str(k) for k in range(workers))
        return command, env
    return command + ["--workers", str(workers)], env


def run_sweep(arguments, out: str, workers: int, device: str, scheduler: str | None = None) -> float:
    """One sweep in a fresh process, on its own cluster of `workers` or sent to `scheduler`; its wall time."""
    command = [sys.executable, "-m", "wavewarp.cli", "sweep", *arguments, "--device", device, "--out", out]
    if scheduler:
        command, env = command + ["--scheduler", scheduler], dict(os.environ)
    else:
        command, env = workers_command(command, workers, device)
    start = time.perf_counter()
    subprocess.run(command, env=env, check=True, capture_output=True, text=True)
    return time.perf_counter() - start


@contextlib.contextmanager
def kept_cluster(workers: int, device: str):
    """`wavewarp cluster` on `workers` GPUs or CPU workers, stopped at the end; yields its scheduler's address."""
    command, env = workers_command([sys.executable, "-m", "wavewarp.cli", "cluster", "--device", device, "--port", "0"],
                                   workers, device)  # fmt: skip
    cluster = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        yield cluster.stdout.readline().split("scheduler ")[1].split(";")[0]
    finally:
        cluster.send_signal(signal.SIGTERM)
        cluster.communicate(timeout=120)


def table(out: str) -> dict:
    with open(os.path.join(out, "table.csv")) as f:
        return {row["point"]: row for row in csv.DictReader(f)}


def steps(rows: dict) -> float:
    """The sweep's work: the walkers' mechanics steps, else the waves' steps, summed over points."""
    column = "mechanics_steps" if all(r.get("mechanics_steps") for r in rows.values()) else "steps"
    return sum(float(r[column]) for r in rows.values())


def differing(rows: dict, reference: dict) -> int:
    return sum(rows[p][k] != reference[p][k] for p in reference for k in reference[p] if k not in TIMING)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench sweep_scaling", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", choices=("cpu", "cuda"))
    parser.add_argument("--workers", default="1,2", help="numbers of GPUs (or CPU workers), comma-separated")
    parser.add_argument("--sweep", default="locomotion", choices=tuple(SWEEPS),
                        help="locomotion: 16 sphere walkers; fig-s1b: 16 buckling-modes points in 4 batched runs; "
                        "quick: 4 quick cube-waves points (a CPU smoke run)")  # fmt: skip
    parser.add_argument("--quick", action="store_true", help="the same as --sweep quick")
    parser.add_argument("--deterministic", action="store_true",
                        help="bit-exact runs (wavewarp.device.set_deterministic) in every sweep")
    parser.add_argument("--no-warm-up", action="store_true",
                        help="the kernel cache is warm already (an earlier sweep on this machine, same WARP_CACHE_PATH): "
                        "skip the warm-up sweep and its run-to-run baseline")  # fmt: skip
    parser.add_argument("--kept-cluster", action="store_true",
                        help="also time each sweep sent to a `wavewarp cluster` kept running (its second sweep)")
    parser.add_argument("--out", default="benchmarks/results")
    args = parser.parse_args(argv)
    counts = sorted({int(n) for n in args.workers.split(",")})
    device = resolve_device("cuda:0" if args.device == "cuda" else "cpu")
    sweep = "quick" if args.quick else args.sweep
    arguments = SWEEPS[sweep] + (["--deterministic"] if args.deterministic else [])
    os.makedirs(args.out, exist_ok=True)
    tag = "" if sweep in ("locomotion", "quick") else f"_{sweep.replace('-', '_')}"
    name = f"sweep_scaling{tag}_{device_tag(device)}{'_deterministic' if args.deterministic else ''}"
    rows, reference = [], None
    with tempfile.TemporaryDirectory(prefix="wavewarp-sweep-scaling-") as scratch:
        result = {"benchmark": "sweep_scaling", **describe_device(device), "date": date.today().isoformat(),
                  "sweep": arguments, "rows": rows}  # fmt: skip
        if not args.no_warm_up:
            result["warm_up_s"] = run_sweep(arguments, os.path.join(scratch, "warm-up"), counts[0], args.device)
        for n in counts:
            wall = run_sweep(arguments, os.path.join(scratch, f"workers-{n}"), n, args.device)
            results = table(os.path.join(scratch, f"workers-{n}"))
            reference = reference or results
            if n == counts[0] and not args.no_warm_up:  # the warm-up ran the same sweep on as many workers: the run-to-run baseline
                result["warm_up_differing_values"] = differing(table(os.path.join(scratch, "warm-up")), reference)
                print(f"the warm-up sweep on {n} workers (the same sweep, run again) differs from it in "
                      f"{result['warm_up_differing_values']} values")  # fmt: skip
            point_walls = [float(r["wall_time_s"]) for r in results.values()]
            row = {"workers": n, "wall_s": wall, "points": len(results), "steps_per_s": steps(results) / wall,
                   "points_wall_sum_s": sum(point_walls), "longest_point_s": max(point_walls),
                   "differing_values": differing(results, reference)}  # fmt: skip
            row["efficiency"] = rows[0]["wall_s"] * rows[0]["workers"] / (wall * n) if rows else 1.0
            print(f"{n:3d} {args.device} workers: {wall:7.1f} s, {row['steps_per_s']:10.4g} steps/s, efficiency "
                  f"{row['efficiency']:.2f}, points {row['points_wall_sum_s']:.1f} s in all (longest "
                  f"{row['longest_point_s']:.1f} s), {row['differing_values']} table values differ from {counts[0]}",
                  flush=True)  # fmt: skip
            if args.kept_cluster:  # a second sweep sent to a cluster kept running: no start-up in its wall time
                with kept_cluster(n, args.device) as address:
                    run_sweep(arguments, os.path.join(scratch, f"kept-warm-up-{n}"), n, args.device, address)
                    row["kept_cluster_wall_s"] = run_sweep(arguments, os.path.join(scratch, f"kept-{n}"), n, args.device,
                                                           address)  # fmt: skip
                first = rows[0] if rows else row
                kept = first["kept_cluster_wall_s"] * first["workers"]
                row["kept_cluster_efficiency"] = kept / (row["kept_cluster_wall_s"] * n)
                row["kept_cluster_differing_values"] = differing(table(os.path.join(scratch, f"kept-{n}")), reference)
                print(f"    with the cluster kept running: {row['kept_cluster_wall_s']:7.1f} s, efficiency "
                      f"{row['kept_cluster_efficiency']:.2f}, {row['kept_cluster_differing_values']} table values "
                      f"differ from {counts[0]}", flush=True)  # fmt: skip
            rows.append(row)
            write_results(result, args, device, os.path.join(args.out, name))  # each worker count as it ends
    return 0


def write_results(result: dict, args, device, stem: str) -> None:
    """STEM.json and the chart STEM.png of the worker counts measured so far."""
    write_json(f"{stem}.json", result)
    rows = result["rows"]
    counts = [r["workers"] for r in rows]
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    ax.plot(counts, [r["steps_per_s"] for r in rows], "o-", label="a cluster started by each sweep")
    if "kept_cluster_wall_s" in rows[0]:
        work = rows[0]["steps_per_s"] * rows[0]["wall_s"]
        ax.plot(counts, [work / r["kept_cluster_wall_s"] for r in rows], "s-", label="a cluster kept running")
    ax.plot(counts, [rows[0]["steps_per_s"] * n / counts[0] for n in counts], "k--", lw=1, label="ideal")
    ax.set_xlabel(f"{'GPUs' if args.device == 'cuda' else 'CPU workers'} (one Dask worker each)")
    ax.set_ylabel("aggregate steps per second")
    ax.set_title(f"sweep scaling{', deterministic' if args.deterministic else ''}, {device.name}", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_png(fig, f"{stem}.png")


if __name__ == "__main__":
    sys.exit(main())
