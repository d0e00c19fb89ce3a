"""Fig. 3a on the paper's footing (issue 58): each walker's displacement from t = 0 against t/T, its own period T.

    wavewarp bench fig3a [--device D] [--seeds 8] [--batch N] [--level L] [--regimes ...] [--periods 12]
                         [--workers N] [--out benchmarks/results/fig3a] [--quick] [--max-seconds S] [--scenes ...]
                         [--h5] [--set NAME=VALUE ...] [--paper-young SCENE=Y ...]

Runs the sensitive and insensitive sphere and prism walkers, `--seeds` rest shapes each (noise 1e-3 R, seeded), in
each regime of REGIMES: `default` (the scenes' defaults), `paper-literal` (inertia, the explicit tanh contact with
k_f = 0.1 and μ = 0.1, on a shell soft enough to sag 1–10 % of R: PAPER_YOUNG; a Y whose settled sag falls outside
is refused, the run recorded as failed) and `drag-60` … `drag-2` (the default regime at the lab-frame drag ζ; the
explicit overdamped step shrinks with ζ by itself, the substeps are recorded). `--level` is the sphere's icosphere
level; the prism gets the divisions of the same mean edge (`prism_divisions`). A run lasts `--periods` kinetic
periods T₀ and 5 % more, so that t/T reaches `--periods` with the measured T up to 1.05 T₀.

A job is one twin in one regime with its seeds — all of `--seeds`, or chunks of `--batch N` — stepped together as
one batched run (wavewarp/batch.py: a GPU run is launch-bound, so a batch costs little more than one run); the
seeds share the strictest seed's mechanics steps, so a seed's walk equals its single run settled with those steps
(`settle_dt`). A job of one seed is a single run as before. Each seed is one JSON in OUT/points (NAME.json, with
`batch_seeds`, the job's), written by a worker process (`--workers`, costliest jobs first; `--device cuda` deals
them over every GPU of the host in turn): a re-run skips a job whose seeds are all done and runs again, whole, a job
with a failed or missing seed. A seed that raises or stops is recorded with its error; in a batch the others keep
their results, and a paper-literal seed refused for its sag still steps with the others (they share the settling's
steps), but a batch whose every seed is refused does not run. `--h5` writes each run's trajectory NAME.h5, from
whose last frame a run killed part-way continues (a run longer than a job's time limit): a single-run feature, so
`--h5` runs each seed alone (`--batch 1`). `--max-seconds`: no job starts after that many seconds (the rest are
left for a re-run).

Writes OUT/fig3a.json — `level`, `front_speed_ratio` (the `front` accuracy case at this level and chemistry dt over
the continuum front), `device`, `date`, `runs` (per run: `scene`, `regime`, `sensitive`, `seed`, `period`,
`t_over_T`, `displacement_R` (from t = 0 along the wave, in R), `pulse_displacements_R` (one per whole period), and
what ran: `time`, `sag_R`, `chemistry_dt`, `mechanics_dt`, `substeps`, `overrides`, `status`, `error`), `claims`
(benchmarks/fig3a_summary.py) — and OUT/fig3a.png, laid out like the paper's Fig. 3a.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import multiprocessing
import os
import time
from dataclasses import dataclass
from datetime import date

import numpy as np

from wavewarp.benchmarks.fig3a_summary import CHECKPOINTS, claims, fig3a_png

SCENES = ("sphere-walker", "prism-walker")
REGIMES = {
    "default": [],
    "paper-literal": ["mechanics=inertial", "contact_solve=explicit", "sharpness=0.1", "friction=0.1", "settle=100"],
    "drag-60": ["drag=60"],
    "drag-20": ["drag=20"],
    "drag-6": ["drag=6"],
    "drag-2": ["drag=2"],
}
PAPER_YOUNG = {"sphere-walker": 55.0, "prism-walker": 3.0}  # level 4: sags 5.5 % and 4.6 % of R (BENCHMARKS.md)
SAG_RANGE = (0.01, 0.10)  # the paper-literal shells' settled sag, in R
PERIOD_MARGIN = 1.05  # a run lasts this many times --periods T₀: the measured T is 0.93–1.0 T₀
NOISE = 1e-3  # the seeds' rest-shape noise, in R (as walker_regimes)
QUICK = ["frames=4", "contact_sweeps=2"]  # the scenes' --quick settings besides the mesh and the length


def prism_divisions(level: int) -> int:
    """The prism's (even) divisions with the mean edge of the sphere's icosphere `level`: 34 at level 4, the scene's."""
    return max(2, 2 * round(17 * 2.0 ** (level - 4)))


@dataclass(frozen=True)
class Point:
    """One run: a walker twin in a regime, its rest shape seeded."""

    scene: str
    regime: str
    sensitive: bool
    seed: int

    @property
    def name(self) -> str:
        return f"{self.regime}_{self.scene}_{'sensitive' if self.sensitive else 'insensitive'}_seed{self.seed}"

    def overrides(self, level: int, periods: float, extra=(), paper_young=None) -> list:
        """The scene's --set overrides for this run, in the order they apply (later ones win)."""
        mesh = f"level={level}" if self.scene == "sphere-walker" else f"divisions={prism_divisions(level)}"
        young = []
        if self.regime == "paper-literal":
            young = [f"young={(paper_young or PAPER_YOUNG)[self.scene]}"]
        return [mesh, f"noise={NOISE}", f"periods={periods * PERIOD_MARGIN:.6g}", *REGIMES[self.regime], *young,
                *extra, f"sensitive={str(self.sensitive).lower()}"]


@dataclass(frozen=True)
class Job:
    """A worker's job: seeds of a walker twin in a regime, run as one batch (one seed: a single run)."""

    scene: str
    regime: str
    sensitive: bool
    seeds: tuple

    @property
    def points(self) -> list:
        return [Point(self.scene, self.regime, self.sensitive, seed) for seed in self.seeds]


def paper_footing(trace: np.ndarray, forward, radius: float, period: float, frame_times) -> dict:
    """From a walker's trace (rows: t, c at the origin, centre of mass, ...): the centre of mass's displacement from
    t = 0 along `forward`, in R, sampled at every whole t/T and at `frame_times`; and per whole period its change
    (`pulse_displacements_R`: they sum to the displacement at the last whole period)."""
    t, first = np.unique(trace[:, 0], return_index=True)
    along = (trace[first, 2:5] - trace[first[0], 2:5]) @ np.asarray(forward, dtype=np.float64) / radius
    whole = np.arange(math.floor(t[-1] / period + 1e-9) + 1) * period
    times = np.unique(np.concatenate([whole, np.clip(frame_times, t[0], t[-1])]))
    return {"time": times.tolist(), "t_over_T": (times / period).tolist(),
            "displacement_R": np.interp(times, t, along).tolist(),
            "pulse_displacements_R": np.diff(np.interp(whole, t, along)).tolist()}


def settled_sag(x, mass, total_mass: float, rest_height: float, radius: float) -> float:
    """How far the settled centre of mass (positions `x`, vertex masses `mass`) lies below the rigid shell's in the
    same contact, in R (the scenes' sag_R)."""
    return float((rest_height - mass @ x[:, 2] / total_mass) / radius)


def sag_refusal(scene: str, regime: str, sag: float, young: float) -> ValueError | None:
    """The error that refuses a paper-literal shell whose settled sag lies outside SAG_RANGE; None where it passes."""
    if regime != "paper-literal" or SAG_RANGE[0] <= sag <= SAG_RANGE[1]:
        return None
    return ValueError(f"paper-literal {scene} sags {100 * sag:.2f}% of R at Y = {young:g}, outside "
                      f"{100 * SAG_RANGE[0]:g}–{100 * SAG_RANGE[1]:g}%: choose another Y with "
                      f"--paper-young {scene}=Y (softer sags more)")


def walked(run, measured: dict, trace, forward, sag: float, resolved: dict) -> dict:
    """A finished run's record (`run` a WalkerRun, or the batch of the world whose `measured`, `trace`, `forward`,
    `resolved` these are): its period, its displacement on the paper's footing and how it ran."""
    if measured["period"] is None:
        raise ValueError(f"c at the origin crossed ½ upwards fewer than twice by t = {measured['time']:.4g}: no "
                         "period T; run more periods")
    times = np.arange(run.frames + 1) * run.steps_per_frame * run.wave.dt
    return {"period": measured["period"], **paper_footing(trace, forward, run.radius, measured["period"], times),
            "sag_R": sag, "chemistry_dt": run.wave.dt, "mechanics_dt": resolved["mechanics_dt"],
            "substeps": resolved["substeps"], "mechanics_steps": measured["mechanics_steps"],
            "rolling_angle_deg": measured["rolling_angle_deg"], "lateral_R": measured["lateral_R"],
            "device": str(run.shell.device)}


def walk(point: Point, overrides: list, device: str, h5_path: str | None) -> dict:
    """Build and run one walker to its end; its period, its displacement on the paper's footing and how it ran."""
    import warp as wp

    from wavewarp.driver import simulate
    from wavewarp.parameters import load_scene, resolve
    from wavewarp.trajectory import TrajectoryWriter, read_frames

    wp.config.log_level = wp.LOG_WARNING
    module = load_scene(point.scene)
    p = resolve(module.Parameters, None, overrides)
    run = module.build(p, device=device, seed=point.seed, report=lambda message: None)
    dynamics = run.dynamics
    sag = settled_sag(dynamics.positions(), dynamics.mass, dynamics.total_mass, run.rest_height, run.radius)
    refusal = sag_refusal(point.scene, point.regime, sag, p.young)
    if refusal:
        raise refusal
    writers, frames = [], stored_frames(h5_path) if h5_path else 0
    if h5_path:
        writers.append(TrajectoryWriter(h5_path, triangles=run.mesh.triangles, rest_positions=run.mesh.vertices,
                                        series=run.series, scene=module.NAME, parameters=run.resolved,
                                        device=str(run.shell.device), provenance={"seed": point.seed},
                                        resume=frames > 0, resume_frames=frames or None))
    outcome = simulate(run, writers, replay=read_frames(h5_path)[:frames] if frames else ())
    if outcome.interrupted:
        raise KeyboardInterrupt
    if outcome.failure:
        raise RuntimeError(f"the run stopped at t = {run.time:.4g}: {outcome.failure}")
    return {**walked(run, outcome.measurements, run.trace, run.forward, sag, run.resolved),
            "settle_dt": run.settle_dt, "batch_seeds": [point.seed], "resumed_after_frames": frames,
            "parameters": run.resolved}


def walk_batch(job: Job, overrides: list, device: str) -> list:
    """Build and run the job's seeds as one batch (wavewarp/batch.py): per seed, its record as `walk`'s or the
    error that failed it. A paper-literal world whose sag is out of range is refused and the others go on (it still
    steps with them: the worlds share the settling's steps, so dropping it would change theirs); where every
    world's is, the batch does not run. A world that stops or gives no period fails alone."""
    import warp as wp

    from wavewarp.parameters import load_scene, resolve

    wp.config.log_level = wp.LOG_WARNING
    module = load_scene(job.scene)
    p = resolve(module.Parameters, None, overrides)
    batch = module.build_batch([p] * len(job.seeds), seeds=job.seeds, device=device, report=lambda message: None)
    x, mass, n = batch.dynamics.positions(), batch.dynamics.mass, batch.vertices
    sags = [settled_sag(x[w * n:(w + 1) * n], mass[w * n:(w + 1) * n], batch.dynamics.world_masses[w],
                        batch.rest_heights[w], batch.radius) for w in range(batch.worlds)]
    outcomes = [sag_refusal(job.scene, job.regime, sag, p.young) for sag in sags]
    if all(outcomes):
        return outcomes
    results = batch.run()
    for w, result in enumerate(results):
        if outcomes[w] is not None:
            continue
        try:  # this world's failure is its own: the others keep their results
            if result["status"] == "stopped":
                raise RuntimeError(f"the run stopped at t = {result['measurements']['time']:.4g}: {result['stopped']}")
            outcomes[w] = {**walked(batch, result["measurements"], batch.traces[w], batch.placed[w].forward, sags[w],
                                    batch.resolved[w]),
                           "settle_dt": batch.settle_dt, "batch_seeds": list(job.seeds), "resumed_after_frames": 0,
                           "parameters": batch.resolved[w]}
        except (RuntimeError, ValueError) as error:
            outcomes[w] = error
    return outcomes


def stored_frames(path: str) -> int:
    """The whole frames of a killed run's trajectory at `path` to continue from (0: none, or another version's)."""
    import h5py

    from wavewarp import __version__
    from wavewarp.trajectory import complete_frames

    try:
        with h5py.File(path, "r") as f:
            return complete_frames(f) if f.attrs.get("wavewarp_version") == __version__ else 0
    except (OSError, KeyError, ValueError):
        return 0


def write_record(folder: str, point: Point, overrides: list, outcome, wall_time: float) -> dict:
    """The point's record written to FOLDER/NAME.json: its result, or an error (`outcome` an exception) as failed."""
    from wavewarp.io import write_json

    record = {"scene": point.scene, "regime": point.regime, "sensitive": point.sensitive, "seed": point.seed,
              "overrides": overrides, "status": "done", "error": None}
    if isinstance(outcome, Exception):
        record.update(status="failed", error=f"{type(outcome).__name__}: {outcome}")
    else:
        record.update(outcome)
    record["wall_time_s"] = wall_time
    write_json(os.path.join(folder, point.name + ".json"), record)
    return record


def run_point(point: Point, overrides: list, device: str, folder: str, h5: bool, deadline: float | None) -> dict:
    """One run, its result written to FOLDER/NAME.json (a failure too, with its error); None when `deadline` (a
    time.time()) has passed before it started."""
    if deadline is not None and time.time() > deadline:
        return None
    start = time.perf_counter()
    try:
        outcome = walk(point, overrides, device, os.path.join(folder, point.name + ".h5") if h5 else None)
    except Exception as error:  # a failed run is a result: recorded, and run again by a re-run
        outcome = error
    return write_record(folder, point, overrides, outcome, time.perf_counter() - start)


def run_job(job: Job, overrides: list, device: str, folder: str, h5: bool, deadline: float | None) -> list | None:
    """A worker's job: its seeds as one batched run (one seed: a single run, `run_point`), each seed's record written
    to FOLDER/NAME.json (`wall_time_s` the whole job's); None when `deadline` has passed before it started."""
    if len(job.seeds) == 1:
        record = run_point(job.points[0], overrides, device, folder, h5, deadline)
        return None if record is None else [record]
    if deadline is not None and time.time() > deadline:
        return None
    start = time.perf_counter()
    try:
        outcomes = walk_batch(job, overrides, device)
    except Exception as error:  # the batch failed as a whole (building, settling): every seed's result
        outcomes = [error] * len(job.seeds)
    wall_time = time.perf_counter() - start
    return [write_record(folder, point, overrides, outcome, wall_time) for point, outcome in zip(job.points, outcomes)]


def stored(folder: str, point: Point, overrides: list) -> dict | None:
    """The point's stored result, or None; ValueError if it was run with other settings."""
    path = os.path.join(folder, point.name + ".json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        record = json.load(f)
    if record["overrides"] != overrides:
        raise ValueError(f"{path} was run with {record['overrides']}, not {overrides}: use another --out, or remove "
                         "the folder's points to run them again")
    return record


def front_speed_ratio(device: str, level: int, extra: list) -> float:
    """The sphere walker's FHN front at `level` and the runs' chemistry dt (the `front` accuracy case) over the
    continuum front (0 where the front pins)."""
    from wavewarp.benchmarks.accuracy_cases import front_point
    from wavewarp.parameters import load_scene, resolve

    p = resolve(load_scene("sphere-walker").Parameters, None, extra)
    if not p.dt:
        raise ValueError("fig3a measures the front at the runs' chemistry dt: give a fixed dt, not --set dt=auto")
    point = front_point(device, level, p.mass_corrections, p.dtype, scheme=p.fhn_scheme, dt=p.dt)
    return point["speed"] / point["reference"]


RUN_FIELDS = ("scene", "regime", "sensitive", "seed", "period", "t_over_T", "displacement_R", "pulse_displacements_R",
              "time", "sag_R", "chemistry_dt", "mechanics_dt", "substeps", "overrides", "status", "error",
              "wall_time_s")


def named_values(items: list, option: str, kind=float) -> dict:
    """SCENE=VALUE items as a dict (ValueError naming the option and the valid scenes)."""
    out = {}
    for item in items:
        scene, sep, value = item.partition("=")
        if not sep or scene not in SCENES:
            raise ValueError(f"{option} takes SCENE=VALUE with SCENE one of {', '.join(SCENES)}, got {item!r}")
        out[scene] = kind(value)
    return out


def parse(argv):
    parser = argparse.ArgumentParser(prog="wavewarp bench fig3a", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--seeds", type=int, default=None, help="rest shapes per twin (default 8; --quick 2)")
    parser.add_argument("--level", type=int, default=None, help="the sphere's icosphere level (default 4; --quick 2)")
    parser.add_argument("--regimes", nargs="+", choices=tuple(REGIMES), default=list(REGIMES), help="default all")
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES), help="default both walkers")
    parser.add_argument("--periods", type=float, default=None, help="t/T to reach, in periods (default 12; --quick 2)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes running the runs (default 1)")
    parser.add_argument("--out", default=os.path.join("benchmarks", "results", "fig3a"), help="output folder")
    parser.add_argument("--quick", action="store_true", help="level 2, 2 periods, 2 seeds, 4 frames (a CPU smoke run)")
    parser.add_argument("--max-seconds", type=float, default=None, help="start no run after this many seconds")
    parser.add_argument("--batch", type=int, default=None,
                        help="seeds of a twin stepped together in one batched run (default: all --seeds; 1: each "
                             "seed its own run)")
    parser.add_argument("--h5", action="store_true",
                        help="write each run's trajectory as OUT/points/NAME.h5 (each seed its own run: --batch 1)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override for every run")
    parser.add_argument("--paper-young", action="append", default=[], metavar="SCENE=Y",
                        help=f"paper-literal Young's modulus (default {PAPER_YOUNG})")
    args = parser.parse_args(argv)
    for name in ("seeds", "level", "workers", "batch"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    if args.periods is not None and args.periods <= 0:
        parser.error(f"--periods must be positive, got {args.periods}")
    try:
        args.paper_young = {**PAPER_YOUNG, **named_values(args.paper_young, "--paper-young")}
    except ValueError as error:
        parser.error(str(error))
    args.seeds = args.seeds or (2 if args.quick else 8)
    args.level = args.level or (2 if args.quick else 4)
    args.periods = args.periods or (2.0 if args.quick else 12.0)
    if args.h5 and (args.batch or 1) > 1:
        parser.error(f"--h5 continues a killed run from its own trajectory, so each seed runs alone: give --batch 1 "
                     f"or leave --batch out, not --batch {args.batch}")
    args.batch = 1 if args.h5 else min(args.batch or args.seeds, args.seeds)
    args.set = (QUICK if args.quick else []) + args.set
    return args


def run_all(todo: list, args, devices: list, folder: str) -> tuple:
    """Run `todo` [(job, overrides)] on the worker processes, costliest regime first (the smallest drag), the jobs
    dealt over `devices` in turn; returns (done, failed, left) counts of runs."""
    from wavewarp.io import write_json

    order = list(REGIMES)
    todo = sorted(todo, key=lambda item: (-order.index(item[0].regime), item[0].scene != "prism-walker"))
    deadline = None if args.max_seconds is None else time.time() + args.max_seconds
    counts = {"done": 0, "failed": 0, "left": 0}
    context = multiprocessing.get_context("spawn")  # Warp's runtime is not fork-safe
    with concurrent.futures.ProcessPoolExecutor(args.workers, mp_context=context) as pool:
        futures = {pool.submit(run_job, job, overrides, devices[k % len(devices)], folder, args.h5, deadline):
                   (job, overrides) for k, (job, overrides) in enumerate(todo)}
        for future in concurrent.futures.as_completed(futures):
            job, overrides = futures[future]
            try:
                records = future.result()
            except Exception as error:  # the worker died (a crash, a kill): recorded, run again by a re-run
                records = []
                for point in job.points:
                    records.append({"scene": point.scene, "regime": point.regime, "sensitive": point.sensitive,
                                    "seed": point.seed, "overrides": overrides, "status": "failed",
                                    "error": f"the worker process failed: {type(error).__name__}: {error}"})
                    write_json(os.path.join(folder, point.name + ".json"), records[-1])
            if records is None:
                counts["left"] += len(job.seeds)
                continue
            for point, record in zip(job.points, records):
                counts[record["status"]] += 1
                shown = (f"T = {record['period']:.2f}, {record['t_over_T'][-1]:.2f} T: "
                         f"{record['displacement_R'][-1]:+.3e} R" if record["status"] == "done" else record["error"])
                print(f"{point.name}: {record['status']} ({record.get('wall_time_s', 0):.1f} s) {shown}", flush=True)
    return counts["done"], counts["failed"], counts["left"]


def main(argv=None) -> int:
    import warp as wp

    from wavewarp.device import resolve_device
    from wavewarp.io import write_json

    args = parse(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    folder = os.path.join(args.out, "points")
    os.makedirs(folder, exist_ok=True)
    jobs = [Job(scene, regime, sensitive, tuple(range(first, min(first + args.batch, args.seeds))))
            for regime in args.regimes for scene in args.scenes for sensitive in (True, False)
            for first in range(0, args.seeds, args.batch)]
    points = [point for job in jobs for point in job.points]
    todo, skipped = [], 0
    for job in jobs:
        overrides = job.points[0].overrides(args.level, args.periods, args.set, args.paper_young)
        records = [stored(folder, point, overrides) for point in job.points]
        if all(record is not None and record["status"] == "done" for record in records):
            skipped += len(job.seeds)
        else:  # a seed failed or missing: the whole job again
            todo.append((job, overrides))
    print(f"fig3a: {len(points)} runs, {skipped} finished before, {len(points) - skipped} to run in {len(todo)} "
          f"job(s) of up to {args.batch} seed(s) on {args.workers} worker(s)")
    ratio = front_speed_ratio(device.alias, args.level, args.set)
    devices = [device.alias]
    if args.device == "cuda":  # every GPU of the host, the jobs dealt in turn
        devices = [d.alias for d in wp.get_cuda_devices()]
    done, failed, left = run_all(todo, args, devices, folder)
    print(f"fig3a: {done} done, {failed} failed, {left} left for a re-run (--max-seconds), {skipped} skipped")
    runs = []
    for point in points:
        path = os.path.join(folder, point.name + ".json")
        if os.path.exists(path):
            with open(path) as f:
                record = json.load(f)
            runs.append({name: record.get(name) for name in RUN_FIELDS})
    result = {"level": args.level, "front_speed_ratio": ratio, "device": f"{device.alias} ({device.name})",
              "date": date.today().isoformat(), "runs": runs,
              "claims": claims(runs, args.regimes, sorted({*CHECKPOINTS, max(1, math.floor(args.periods))}))}
    write_json(os.path.join(args.out, "fig3a.json"), result)
    title = f"Fig. 3a, level {args.level}, {device.name}, front speed {ratio:.3f} of the continuum's"
    fig3a_png(runs, args.regimes, args.scenes, os.path.join(args.out, "fig3a.png"), title=title)
    print(f"wrote {os.path.join(args.out, 'fig3a.json')} and fig3a.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
