"""Soak (issue 57): a long run of the sphere walker on one device, watched for drift and leaks.

    wavewarp bench soak --device cuda --out benchmarks/results [--steps 100000] [--every N] [--quick] [--set NAME=V]
                        [--resume | --overwrite]

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
memory's largest growth within one process, steps per second) and soak_<device>.png (the three quantities against
the step). `_quick` is appended to the names with --quick. At every sample the run's state (its frame: x, v, c, w,
the reaction's amounts, the time) is saved beside them (soak_<device>.checkpoint.npz): `--resume` continues an
unfinished soak from it in a new process (a soak longer than one job or lease; the walker resumes bit for bit),
to `--steps` counted from the first step; its samples carry the process's `segment`. An existing soak is neither
replaced nor continued unless asked: `--resume` or `--overwrite`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import replace
from datetime import date

import numpy as np
import warp as wp

from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.io import atomic_path, write_json, write_png
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


def soak(p, device, steps: int, every: int, report=print, on_sample=None, resume=None) -> dict:
    """Run the walker `steps` chemistry steps (whole frames), sampling about every `every` steps; `on_sample(samples,
    run)` after each sample (a run cut short keeps what it measured). `resume`: (the samples so far, the frame saved
    at the last) to continue from."""
    module = load_scene(SCENE)
    run = module.build(p, device=device.alias, report=report)
    frames = max(1, math.ceil(steps / run.steps_per_frame))
    per_sample = max(1, round(every / run.steps_per_frame))
    if resume is None:
        samples, segment, wall = [sample(run, device, 0, 0.0)], 0, 0.0
    else:
        samples, frame = resume
        run.restore(frame)
        segment, wall = samples[-1].get("segment", 0) + 1, samples[-1]["wall_time_s"]
    done = samples[-1]["step"]
    if done % run.steps_per_frame:
        raise ValueError(f"the saved soak stopped at step {done}, not a whole frame of {run.steps_per_frame} steps: "
                         "its parameters differ from these")
    start = time.perf_counter()
    for frame in range(done // run.steps_per_frame + 1, frames + 1):
        run.advance_frame()
        done += run.steps_per_frame
        if frame % per_sample == 0 or frame == frames:
            wp.synchronize_device(device)
            samples.append({**sample(run, device, done, wall + time.perf_counter() - start), "segment": segment})
            if on_sample is not None:
                on_sample(samples, run)
    return {"steps": done, "steps_per_frame": run.steps_per_frame, "frames": frames, "vertices": run.mesh.n_vertices,
            "samples": samples}


def save_frame(run, path: str) -> None:
    """The run's state now (`WalkerRun.frame` and its time), atomically, for `--resume`."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, time=np.array(run.time), **{key: np.asarray(value) for key, value in run.frame().items()})


def load_frame(path: str) -> dict:
    with np.load(path) as saved:
        frame = {key: saved[key] for key in saved.files}
    frame["time"] = float(frame["time"])
    return frame


def memory_growth(samples: list, key: str) -> float:
    """The largest growth of `key` within one process (segment): from its first sample after the start (the pool
    fills at the first steps) to its last."""
    growth = 0.0
    for segment in sorted({s.get("segment", 0) for s in samples}):
        values = [s[key] for s in samples if s.get("segment", 0) == segment]
        growth = max(growth, values[-1] - values[1 if len(values) > 2 else 0])
    return growth


def summary(samples: list) -> dict:
    volumes = np.array([s["volume"] for s in samples])
    keys = [key for key in ("mempool_used_bytes", "device_used_bytes", "host_rss_bytes") if key in samples[0]]
    wall = samples[-1]["wall_time_s"]
    return {"invariant_error_max": max(s["invariant_error"] for s in samples),
            "volume_relative_range": float((volumes.max() - volumes.min()) / volumes[0]),
            **{f"{key}_growth": memory_growth(samples, key) for key in keys},
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


def previous(path: str, checkpoint: str, about: dict, args) -> tuple:
    """(samples, frame) of the unfinished soak at `path` to continue; ValueError in the user's terms if there is none,
    it finished, or it ran other parameters or another kind of device."""
    if not os.path.exists(path) or not os.path.exists(checkpoint):
        raise ValueError(f"--resume: no soak to continue at {path} (and its {os.path.basename(checkpoint)})")
    with open(path) as f:
        stored = json.load(f)
    if stored["parameters"] != json.loads(json.dumps(about["parameters"])):
        differ = sorted(k for k in about["parameters"] if stored["parameters"].get(k) != about["parameters"][k])
        raise ValueError(f"--resume: {path} ran other parameters ({', '.join(differ)}); give the same --set and "
                         "--quick, or --overwrite")
    if stored["machine"]["device"].split(":")[0] != about["machine"]["device"].split(":")[0]:
        raise ValueError(f"--resume: {path} ran on {stored['machine']['device']}, not {about['machine']['device']}")
    if stored["finished"] and stored["samples"][-1]["step"] >= args.steps:
        raise ValueError(f"--resume: {path} finished its {stored['samples'][-1]['step']} steps; ask for more --steps")
    return stored["samples"], load_frame(checkpoint)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench soak", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default="benchmarks/results", help="folder of soak_<device>.json and .png")
    parser.add_argument("--steps", type=int, default=100_000, help="chemistry steps to run (default 100000)")
    parser.add_argument("--every", type=int, default=None, help="steps between samples (default: steps / 100)")
    parser.add_argument("--quick", action="store_true", help="the scene's --quick settings (a level-2 sphere)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a scene parameter")
    again = parser.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="continue the unfinished soak in --out to --steps")
    again.add_argument("--overwrite", action="store_true", help="replace a soak already in --out")
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
    checkpoint = stem + ".checkpoint.npz"
    resume = previous(stem + ".json", checkpoint, about, args) if args.resume else None
    if resume is None and not args.overwrite and os.path.exists(stem + ".json"):
        parser.error(f"{stem}.json exists: --resume continues it (if unfinished), --overwrite replaces it")

    def so_far(samples, run):  # the samples so far, marked unfinished, and the state to resume from
        save_frame(run, checkpoint)
        write_json(stem + ".json", {**about, "finished": False, "samples": samples, "summary": summary(samples)})

    result = soak(p, device, args.steps, args.every or max(1, args.steps // 100), report=lambda message: None,
                  on_sample=so_far, resume=resume)
    result.update(about, finished=True, summary=summary(result["samples"]))
    write_json(stem + ".json", result)
    chart(result, stem + ".png")
    print(f"wrote {stem}.json, {stem}.png: {result['steps']} steps; " +
          ", ".join(f"{k} {v:.3g}" for k, v in result["summary"].items() if v is not None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
