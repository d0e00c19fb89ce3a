"""Soak (issue 57): a long run of the sphere walker on one device, watched for drift and leaks.

    wavewarp bench soak --device cuda --out benchmarks/results [--steps 100000] [--every N] [--quick] [--set NAME=V]

Runs the sphere walker (the scene's defaults, or --quick's; at least FRAMES frames over its periods, so that a
frame is a few steps) for `--steps` chemistry steps, whole frames of the run (`WalkerRun.advance_frame`), past
the scene's own end when the steps ask for more, and samples about every `--every` steps (default: 100
samples):

* the chemical's invariant: |C - C(0) - produced| / max(|C(0) + produced|, ∫|c| dω), C = Σ M_I(x) c_I on the
  surface the wave runs on (with conservative transport it holds to round-off: docs/theory/chemistry.md);
* the enclosed volume relative to the first sample's;
* memory: on CUDA the device's memory pool in use (`wp.get_mempool_used_mem_current`) and the device's used
  memory (total - free); on the CPU the process's resident memory (VmRSS);
* the wall time per step since the last sample.

Writes soak_<device>.json (the samples and a summary: the largest invariant error, the volume's range, the
memory's growth from the first to the last sample, steps per second) and soak_<device>.png (the three
quantities against the step). `_quick` is appended to the names with --quick.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import replace
from datetime import date

import numpy as np
import warp as wp

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.io import write_json, write_png
from wavewarp.parameters import load_scene, resolve

SCENE = "sphere-walker"
FRAMES = 400  # frames of the scene's periods at least: samples a few steps apart


def resident_bytes() -> float:
    """This process's resident memory (VmRSS), 0 where unknown."""
    try:
        with open("/proc/self/status") as status:
            return next(float(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return 0.0


def memory(device) -> dict:
    """The memory a leak would grow: the device's pool and used memory on CUDA, the process's on the CPU."""
    if not device.is_cuda:
        return {"host_rss_bytes": resident_bytes()}
    pool = float(wp.get_mempool_used_mem_current(device)) if wp.is_mempool_enabled(device) else math.nan
    return {"mempool_used_bytes": pool, "device_used_bytes": float(device.total_memory - device.free_memory),
            "host_rss_bytes": resident_bytes()}


def invariant_error(run) -> float:
    """The relative error of C = Σ M_I c_I against C(0) plus what the reaction added (module docstring)."""
    c = run.wave.concentration().astype(np.float64)
    mass = run.operator.mass().astype(np.float64)
    expected = run.initial_total + run.wave.produced()
    return abs(float(mass @ c) - expected) / max(abs(expected), float(mass @ np.abs(c)), np.finfo(float).tiny)


def sample(run, device, steps: int, wall: float) -> dict:
    return {"step": steps, "time": run.time, "invariant_error": invariant_error(run),
            "volume": float(run.shell.volume(run.dynamics.positions())), "wall_time_s": wall, **memory(device)}


def soak(p, device, steps: int, every: int, report=print, on_sample=None) -> dict:
    """Run the walker `steps` chemistry steps (whole frames), sampling about every `every` steps; `on_sample(samples)`
    after each sample (a run cut short keeps what it measured)."""
    module = load_scene(SCENE)
    run = module.build(p, device=device.alias, report=report)
    frames = max(1, math.ceil(steps / run.steps_per_frame))
    per_sample = max(1, round(every / run.steps_per_frame))
    samples, done, start = [sample(run, device, 0, 0.0)], 0, time.perf_counter()
    for frame in range(1, frames + 1):
        run.advance_frame()
        done += run.steps_per_frame
        if frame % per_sample == 0 or frame == frames:
            wp.synchronize_device(device)
            samples.append(sample(run, device, done, time.perf_counter() - start))
            if on_sample is not None:
                on_sample(samples)
    return {"steps": done, "steps_per_frame": run.steps_per_frame, "frames": frames, "vertices": run.mesh.n_vertices,
            "samples": samples}


def summary(samples: list) -> dict:
    volumes = np.array([s["volume"] for s in samples])
    keys = [key for key in ("mempool_used_bytes", "device_used_bytes", "host_rss_bytes") if key in samples[0]]
    wall = samples[-1]["wall_time_s"]
    return {"invariant_error_max": max(s["invariant_error"] for s in samples),
            "volume_relative_range": float((volumes.max() - volumes.min()) / volumes[0]),
            **{f"{key}_growth": samples[-1][key] - samples[1 if len(samples) > 2 else 0][key] for key in keys},
            "steps_per_second": samples[-1]["step"] / wall if wall > 0 else None}


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples = result["samples"]
    step = [s["step"] for s in samples]
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    axes[0].semilogy(step, [max(s["invariant_error"], 1e-17) for s in samples], "o-", ms=3)
    axes[0].set_ylabel("invariant error |ΔC| / C")
    axes[1].plot(step, [s["volume"] / samples[0]["volume"] - 1 for s in samples], "o-", ms=3)
    axes[1].set_ylabel("volume / V(0) - 1")
    for key, label in (("mempool_used_bytes", "CUDA mempool in use"), ("device_used_bytes", "device memory used"),
                       ("host_rss_bytes", "process resident memory")):
        if key in samples[0]:
            axes[2].plot(step, [s[key] / 2**20 for s in samples], "o-", ms=3, label=label)
    axes[2].set_ylabel("memory (MiB)")
    axes[2].legend(fontsize=8)
    axes[2].set_xlabel("chemistry step")
    fig.suptitle(f"soak: {SCENE}, {result['machine']['device']} ({result['date']})")
    fig.tight_layout()
    write_png(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench soak", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default="benchmarks/results", help="folder of soak_<device>.json and .png")
    parser.add_argument("--steps", type=int, default=100_000, help="chemistry steps to run (default 100000)")
    parser.add_argument("--every", type=int, default=None, help="steps between samples (default: steps / 100)")
    parser.add_argument("--quick", action="store_true", help="the scene's --quick settings (a level-2 sphere)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a scene parameter")
    args = parser.parse_args(argv)
    if args.steps < 1 or (args.every is not None and args.every < 1):
        parser.error("--steps and --every must be integers >= 1")
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    module = load_scene(SCENE)
    p = resolve(module.Parameters, module.QUICK if args.quick else None, args.set)
    p = replace(p, frames=max(p.frames, FRAMES))
    os.makedirs(args.out, exist_ok=True)
    stem = os.path.join(args.out, f"soak_{device_tag(device)}" + ("_quick" if args.quick else ""))
    about = dict(scene=SCENE, parameters=vars(p), machine=describe_device(device), date=date.today().isoformat())

    def so_far(samples):  # the samples so far, marked unfinished
        write_json(stem + ".json", {**about, "finished": False, "samples": samples, "summary": summary(samples)})

    result = soak(p, device, args.steps, args.every or max(1, args.steps // 100), report=lambda message: None,
                  on_sample=so_far)
    result.update(about, finished=True, summary=summary(result["samples"]))
    write_json(stem + ".json", result)
    chart(result, stem + ".png")
    print(f"wrote {stem}.json, {stem}.png: {result['steps']} steps; " +
          ", ".join(f"{k} {v:.3g}" for k, v in result["summary"].items() if v is not None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
