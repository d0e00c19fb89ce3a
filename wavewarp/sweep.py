"""Parameter sweeps (docs/theory/sweeps.md): a scene run at every point of a grid of parameter
values and seeds, in batches on any `concurrent.futures.Executor`; by default an embedded Dask
cluster with one worker per GPU, or per CPU core.

    spec = SweepSpec("cube-waves", grid={"gamma": ["0.8", "1.0"]}, seeds=2, quick=True)
    table = sweep(spec, "out/", executor=None, batch=1)      # None: a local Dask cluster

Every point's result is written atomically to DIR/points/POINT.json as soon as it is computed,
so a killed sweep loses only the points being computed; running the same sweep into the same
DIR again computes only the points without a result, and those whose result is a failure. A point
is locked while it is computed (DIR/points/.POINT.json.lock): two sweeps into one DIR compute each
point once. A batch whose worker died (Dask retries it on another first) or whose task raised
fails its points alone: the sweep goes on, and reports them. With `h5` each point's trajectory
(DIR/points/POINT.h5) is durable frame by frame and records the batch it ran in: the batches a
killed sweep left part-way are run again as they were and go on from their worlds' last common
frame. At the end the sweep writes DIR/table.csv (a row per point) and DIR/chart.png (a
measurement against the grid).

Scenes with batched worlds (`build_batch`: the walkers, wavewarp/batch.py; buckling and
buckling-modes, wavewarp/quasistatic_batch.py) run a batch of points
as one batched run: its points differ only in the per-world parameters (batch.PER_WORLD and the
seed); points that differ in another are dealt to other batches.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import itertools
import json
import logging
import os
import re
import shutil
import tempfile
import time
import uuid
from dataclasses import dataclass, field, replace

import h5py
import warp as wp
from distributed import Client, KilledWorker, Nanny, Scheduler, SpecCluster
from distributed.system import MEMORY_LIMIT
from tqdm import tqdm

from .batch import PER_WORLD
from .device import init_warp, set_deterministic
from .driver import FAILURES, simulate
from .figures import sweep_chart_png
from .io import atomic_path, write_json
from .locks import OutputBusy, output_lock
from .parameters import SceneError, fields, load_scene, resolve
from .trajectory import TrajectoryWriter, complete_frames, read_frames
from .version import __version__

BATCH_ATTRIBUTE = "sweep_batch"  # a point's trajectory: the names of the points of the batch it ran in (JSON)


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep runs: the scene, `grid` (parameter name -> the values' text, in order), `seeds`
    (first_seed … first_seed + seeds - 1 at every grid point: a later sweep with another first_seed adds
    seeds to an ensemble), `fixed` NAME=VALUE settings for every point, `quick` (the
    scene's reduced run), `device` ("cpu", "cuda" or None: the worker's choice), `h5` (a trajectory
    per point), `measure`, the measurement the chart shows (None: the first that differs between
    points), `deterministic` (bit-exact repeated runs on a GPU: wavewarp.device.set_deterministic), and
    `invocation`, the id `sweep` gives one sweep's run (each result it writes records it)."""

    scene: str
    grid: dict = field(default_factory=dict)
    seeds: int = 1
    first_seed: int = 0
    fixed: tuple = ()
    quick: bool = False
    device: str | None = None
    h5: bool = False
    measure: str | None = None
    deterministic: bool = False
    invocation: str = ""

    def definition(self) -> dict:
        """What identifies the sweep's points and results (not where they run); first_seed only where it
        is not 0, so that folders written before it existed continue."""
        seeds = {"first_seed": self.first_seed} if self.first_seed else {}
        return {"scene": self.scene, "grid": self.grid, "seeds": self.seeds, **seeds, "fixed": list(self.fixed),
                "quick": self.quick, "deterministic": self.deterministic}  # fmt: skip


@dataclass(frozen=True)
class Point:
    """One run of a sweep: the grid values (NAME, text) and the seed."""

    values: tuple
    seed: int

    @property
    def name(self) -> str:
        """A file name: NAME=VALUE parts and the seed, characters outside [A-Za-z0-9.=+-] replaced."""
        parts = [f"{name}={value}" for name, value in self.values] + [f"seed={self.seed}"]
        return re.sub(r"[^A-Za-z0-9.=+-]", "_", "_".join(parts))

    def overrides(self) -> list:
        return [f"{name}={value}" for name, value in self.values]


def parse_grid(items) -> dict:
    """`--grid NAME=v1,v2,...` items as {NAME: [v1, v2, ...]} (ValueError naming the bad item)."""
    grid = {}
    for item in items:
        name, sep, text = str(item).partition("=")
        name, values = name.strip(), [v.strip() for v in text.split(",")]
        if not sep or not name or not all(values):
            raise ValueError(f"--grid needs NAME=v1,v2,... with no empty value, got {item!r}")
        if name in grid:
            raise ValueError(f"--grid {name} is given twice: list all its values in one --grid {name}=v1,v2,...")
        grid[name] = values
    return grid


def grid_points(spec: SweepSpec) -> list:
    """Every (grid values, seed) of the sweep, the first grid parameter varying slowest, seeds fastest."""
    if int(spec.seeds) < 1:
        raise ValueError(f"--seeds must be an integer >= 1, got {spec.seeds!r}")
    if int(spec.first_seed) < 0:
        raise ValueError(f"--first-seed must be an integer >= 0, got {spec.first_seed!r}")
    names, seeds = list(spec.grid), range(int(spec.first_seed), int(spec.first_seed) + int(spec.seeds))
    return [Point(tuple(zip(names, values)), seed)
            for values in itertools.product(*(spec.grid[n] for n in names)) for seed in seeds]  # fmt: skip


def check_points(spec: SweepSpec, points) -> None:
    """Every point's parameters resolved before anything runs: a bad name or value is a SceneError
    naming it, and a grid parameter also set with --set is refused."""
    module = load_scene(spec.scene)
    clash = set(spec.grid) & {str(item).partition("=")[0].strip() for item in spec.fixed}
    if clash:
        raise SceneError(f"{', '.join(sorted(clash))} is both swept (--grid) and fixed (--set): keep one")
    unknown = set(spec.grid) - set(fields(module.Parameters))
    if unknown:
        raise SceneError(f"unknown parameter {sorted(unknown)[0]!r} in --grid; valid: {', '.join(sorted(fields(module.Parameters)))}")
    for point in points:
        point_parameters(module, spec, point)


def point_parameters(module, spec: SweepSpec, point: Point):
    """The scene's parameters at `point`: its defaults (or QUICK), the --set values, the grid values."""
    return resolve(module.Parameters, getattr(module, "QUICK", {}) if spec.quick else None, [*spec.fixed, *point.overrides()])


def result_path(out: str, point: Point) -> str:
    return os.path.join(out, "points", f"{point.name}.json")


def trajectory_path(out: str, point: Point) -> str:
    return os.path.join(out, "points", f"{point.name}.h5")


def stored_batch(path: str) -> tuple:
    """The batch a point's trajectory ran in (its points' names) and the frames it holds; ([], 0) where
    there is no trajectory to continue (also one another wavewarp version wrote: a resume would refuse it)."""
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("wavewarp_version") != __version__:
                return [], 0
            return json.loads(f.attrs.get(BATCH_ATTRIBUTE, "[]")), complete_frames(f)
    except (OSError, KeyError, ValueError):
        return [], 0


def resumable_frames(out: str, points) -> int:
    """The frames every point's trajectory holds, where each records this very batch (a killed sweep's
    batch, to continue); 0 where any does not."""
    names = [point.name for point in points]
    stored = [stored_batch(trajectory_path(out, point)) for point in points]
    return min(frames for _, frames in stored) if all(batch == names for batch, _ in stored) else 0


def started_batches(out: str, missing) -> tuple:
    """The batches a killed sweep left part-way (recorded in their points' trajectories, every point of
    them still without a result), and the other points of `missing`."""
    by_name, started, taken = {point.name: point for point in missing}, [], set()
    for point in missing:
        names, frames = stored_batch(trajectory_path(out, point))
        free = all(name in by_name and name not in taken for name in names)
        if frames and names and point.name not in taken and free:
            started.append([by_name[name] for name in names])
            taken.update(names)
    return started, [point for point in missing if point.name not in taken]


def point_writer(out: str, points, w: int, *, mesh, series, scene: str, parameters, device: str,
                 resume_frames: int) -> TrajectoryWriter:  # fmt: skip
    """World w's trajectory writer: a new file, or with `resume_frames` the file continued after them."""
    return TrajectoryWriter(trajectory_path(out, points[w]), triangles=mesh.triangles, rest_positions=mesh.vertices,
                            series=series, scene=scene, parameters=parameters, device=device,
                            resume=resume_frames > 0, resume_frames=resume_frames or None,
                            attributes={BATCH_ATTRIBUTE: json.dumps([point.name for point in points])},
                            provenance={"seed": points[w].seed})  # fmt: skip


def run_point(spec: SweepSpec, point: Point, out: str) -> dict:
    """Run one point to its end and write its result (parameters, outcome, measurements) atomically.
    A solver failure is a result ("stopped", with the frames before it measured); an error while
    building the run is a result too ("failed", with the message)."""
    module = load_scene(spec.scene)
    p = point_parameters(module, spec, point)
    result = {"point": point.name, "values": dict(point.values), "seed": point.seed, "sweep": spec.definition(),
              "invocation": spec.invocation}
    reports, start = [], time.perf_counter()
    try:
        run = module.build(p, device=spec.device, seed=point.seed, report=reports.append)
    except (ValueError, *FAILURES) as error:
        result.update(status="failed", error=str(error), wall_time_s=time.perf_counter() - start)
        write_json(result_path(out, point), result)
        return result
    writers = []
    frames = resumable_frames(out, [point]) if spec.h5 and hasattr(run, "restore") else 0
    if spec.h5:
        writers.append(point_writer(out, [point], 0, mesh=run.mesh, series=run.series, scene=module.NAME,
                                    parameters=run.resolved, device=str(run.shell.device), resume_frames=frames))  # fmt: skip
    if frames:
        result["resumed_after_frames"] = frames
    replay = read_frames(trajectory_path(out, point))[:frames] if frames else ()
    outcome = simulate(run, writers, replay=replay, on_measured=writers[0].set_measurements if writers else None)
    if outcome.interrupted:
        raise KeyboardInterrupt
    result.update(status="stopped" if outcome.failure else "done", stopped=outcome.failure, frames=outcome.frames,
                  steps=run.steps, device=str(run.shell.device), wall_time_s=time.perf_counter() - start,
                  reports=reports, parameters=run.resolved, measurements=outcome.measurements)  # fmt: skip
    write_json(result_path(out, point), result)
    return result


def run_worlds(spec: SweepSpec, module, points, out: str) -> list:
    """The points of one batch as the worlds of one batched run (`module.build_batch`); each point's
    result written as run_point writes it (with `--h5` its trajectory too), its wall time the batch's,
    with `batch` {worlds, world}. A batch whose trajectories hold its frames so far (a killed sweep's)
    goes on from the last frame they share (`batch` then also says after how many frames)."""
    results = [{"point": point.name, "values": dict(point.values), "seed": point.seed, "sweep": spec.definition(),
                "invocation": spec.invocation, "batch": {"worlds": len(points), "world": w}}
               for w, point in enumerate(points)]
    reports, start = [], time.perf_counter()
    try:
        run = module.build_batch([point_parameters(module, spec, point) for point in points],
                                 seeds=[point.seed for point in points], device=spec.device, report=reports.append)  # fmt: skip
        frames = resumable_frames(out, points) if spec.h5 and run.resumable else 0
        replay = [read_frames(trajectory_path(out, point))[:frames] for point in points] if frames else None
        writers = [point_writer(out, points, w, mesh=mesh, series=run.series, scene=module.NAME,
                                parameters=parameters, device=str(run.shell.device), resume_frames=frames)
                   for w, (mesh, parameters) in enumerate(zip(run.world_meshes, run.resolved))] if spec.h5 else None  # fmt: skip
        if frames:
            for result in results:
                result["batch"]["resumed_after_frames"] = frames
        worlds = run.run(writers=writers, replay=replay)
    except (ValueError, *FAILURES) as error:
        worlds = [{"status": "failed", "error": str(error)}] * len(points)
    else:
        device = str(run.shell.device)
        worlds = [{**world, "device": device, "reports": reports} for world in worlds]
    for point, result, world in zip(points, results, worlds):
        result.update(world, wall_time_s=time.perf_counter() - start)
        write_json(result_path(out, point), result)
    return results


def has_result(out: str, point: Point) -> bool:
    """Whether `point` has a result that is no failure (a failed point is run again)."""
    result = stored_result(out, point)
    return result is not None and result.get("status") != "failed"


def skipped(point: Point, reason: str) -> dict:
    """What a batch reports of a point it left to another sweep (nothing is written)."""
    return {"point": point.name, "values": dict(point.values), "seed": point.seed, "status": "skipped",
            "reason": reason}


def run_batch(spec: SweepSpec, points, out: str) -> list:
    """The points of one batch in this worker (each result written as it comes): one batched run where
    the scene has batched worlds, else one point after another. Each point is locked while it runs; a
    point another sweep holds, or has computed meanwhile, is skipped (reported, "skipped")."""
    wp.config.log_level = wp.LOG_WARNING
    set_deterministic(spec.deterministic)
    module = load_scene(spec.scene)
    with contextlib.ExitStack() as stack:
        mine, left = [], []
        for point in points:
            try:
                stack.enter_context(output_lock(result_path(out, point), "point"))
            except OutputBusy:
                left.append(skipped(point, "another sweep into this folder is computing it"))
                continue
            if has_result(out, point):
                left.append(skipped(point, "another sweep into this folder computed it"))
            else:
                mine.append(point)
        if len(mine) > 1 and hasattr(module, "build_batch"):
            return run_worlds(spec, module, mine, out) + left
        return [run_point(spec, point, out) for point in mine] + left


def world_group(spec: SweepSpec):
    """point -> what a batch's worlds must share (their parameters but PER_WORLD), for a scene with
    batched worlds; None for the others (any points may share a batch)."""
    module = load_scene(spec.scene)
    if not hasattr(module, "build_batch"):
        return None
    def shared(point):
        p = point_parameters(module, spec, point)
        return replace(p, **{name: None for name in PER_WORLD if hasattr(p, name)})

    return shared


def batches(points, size: int, group=None) -> list:
    """The points dealt round-robin into ceil(n / size) batches of at most `size`: neighbours in the
    grid (which often cost alike: one twin, one coupling) go to different batches, so that batches cost
    about the same. With `group` (point -> key) only points of one key share a batch."""
    if int(size) < 1:
        raise ValueError(f"--batch must be an integer >= 1, got {size!r}")
    groups = {}
    for point in points:
        groups.setdefault(None if group is None else group(point), []).append(point)
    dealt = []
    for members in groups.values():
        count = -(-len(members) // int(size))
        dealt += [members[k::count] for k in range(count)]
    return dealt


def prepare_folder(spec: SweepSpec, out: str) -> None:
    """DIR/sweep.json holds the sweep's definition; a folder holding another sweep is refused."""
    os.makedirs(os.path.join(out, "points"), exist_ok=True)
    stored = os.path.join(out, "sweep.json")
    if os.path.isfile(stored):
        with open(stored) as f:
            before = json.load(f)
        if before != json.loads(json.dumps(spec.definition())):
            raise ValueError(f"{out} holds another sweep ({before}): choose another --out, or the same scene, "
                             "grid, seeds, --set and --quick to continue it")  # fmt: skip
    else:
        write_json(stored, spec.definition())


@contextlib.contextmanager
def local_cluster(device: str | None = None, workers: int | None = None, port: int = 0):
    """A Dask cluster on this machine: one single-threaded worker per GPU this process sees
    (CUDA_VISIBLE_DEVICES of the worker set to it) when CUDA is present and `device` is not "cpu",
    else `workers` CPU workers (default: one per core), each allowed an equal share of this machine's
    memory (Dask's default, memory / cores, stops a GPU worker of a many-core host long before the
    memory runs out); its scheduler on `port` (0: any free one).
    Each worker has its own WARP_CACHE_PATH, seeded from this process's kernel cache, so that no
    cache is written by two processes; the kernels the workers compiled are copied back into it at
    the end, so the next cluster starts warm."""
    init_warp()
    gpus = 0 if device == "cpu" else wp.get_cuda_device_count()
    visible = [v for v in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",") if v.strip()] or [str(k) for k in range(gpus)]
    count = gpus or int(workers or os.cpu_count() or 1)
    ours = wp.config.kernel_cache_dir  # versioned: CACHE/1.19.0
    base = tempfile.mkdtemp(prefix="wavewarp-sweep-cache-")
    caches = [os.path.join(base, f"worker-{k}") for k in range(count)]
    specification = {}
    for k, cache in enumerate(caches):
        shutil.copytree(ours, os.path.join(cache, os.path.basename(ours)))
        env = {"WARP_CACHE_PATH": cache, "CUDA_VISIBLE_DEVICES": visible[k] if gpus else "", "OMP_NUM_THREADS": "1"}
        options = {"nthreads": 1, "env": env, "memory_limit": MEMORY_LIMIT // count, "silence_logs": logging.ERROR}
        specification[f"worker-{k}"] = {"cls": Nanny, "options": options}
    try:
        scheduler = {"cls": Scheduler, "options": {"dashboard_address": ":0", "port": int(port)}}
        with SpecCluster(workers=specification, scheduler=scheduler, silence_logs=logging.ERROR) as cluster:
            yield cluster
    finally:
        for cache in caches:
            merge_kernel_cache(os.path.join(cache, os.path.basename(ours)), ours)
        shutil.rmtree(base, ignore_errors=True)


def merge_kernel_cache(source: str, target: str) -> None:
    """Copy the compiled modules of `source` that `target` lacks (each entry to a temporary name,
    then renamed: another process reading `target` never sees half an entry)."""
    if not os.path.isdir(source):
        return
    for entry in os.listdir(source):
        made, staging = os.path.join(source, entry), os.path.join(target, f".{entry}.{os.getpid()}.tmp")
        if os.path.exists(os.path.join(target, entry)) or not os.path.isdir(made):
            continue
        try:
            shutil.copytree(made, staging)
            os.replace(staging, os.path.join(target, entry))
        except OSError:  # another process put it there first
            shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def _executor(executor, spec: SweepSpec, workers, scheduler, report):
    """The executor given, or a Dask client's (of `scheduler`, or of a local cluster closed at the end)."""
    if executor is not None:
        yield executor
        return
    with contextlib.ExitStack() as stack:
        cluster = None if scheduler else stack.enter_context(local_cluster(spec.device, workers))
        client = stack.enter_context(Client(scheduler or cluster))
        report(f"Dask: {len(client.scheduler_info()['workers'])} workers; dashboard {client.dashboard_link}")
        yield client.get_executor()


LISTED_COLUMNS = 32  # a measurement that is a list of at most this many numbers gets a column per entry


def measurement_columns(measurements: dict) -> dict:
    """The numeric measurements, each short list of numbers (`pulse_displacements_R`: one per pulse) as
    columns NAME_1, NAME_2, ..."""
    columns = {}
    for name, value in measurements.items():
        if isinstance(value, (int, float)):
            columns[name] = value
        elif isinstance(value, list) and len(value) <= LISTED_COLUMNS and all(isinstance(v, (int, float)) for v in value):
            columns.update({f"{name}_{k}": v for k, v in enumerate(value, 1)})
    return columns


def table_rows(out: str, points) -> list:
    """One row per point with a result: its grid values, seed, status and numeric measurements (short
    lists of numbers a column per entry)."""
    rows = []
    for point in points:
        path = result_path(out, point)
        if not os.path.isfile(path):
            continue
        with open(path) as f:
            result = json.load(f)
        row = {"point": point.name, **result["values"], "seed": result["seed"], "status": result["status"],
               "frames": result.get("frames", 0), "steps": result.get("steps", 0), "wall_time_s": result["wall_time_s"], "device": result.get("device", "")}  # fmt: skip
        row.update(measurement_columns(result.get("measurements", {})))
        rows.append(row)
    return rows


def write_table(rows, path) -> None:
    """The rows as CSV (the union of their columns, in first-seen order), written atomically."""
    columns = list(dict.fromkeys(k for row in rows for k in row))
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)


class SweepTable(list):
    """The table's rows (one dict per point with a result), and what this sweep did: `computed` (points it
    ran to a result, "done" or "stopped"), `skipped` (points with a result before it, or left to another
    sweep into the folder) and `failures` (point -> error: points that failed; a re-run tries them again)."""

    def __init__(self, rows, computed: int = 0, skipped: int = 0, failures: dict | None = None):
        super().__init__(rows)
        self.computed, self.skipped, self.failures = computed, skipped, dict(failures or {})

    def summary(self) -> dict:
        """{"computed", "skipped", "failed"} (counts) and the `failures` by point."""
        return {"computed": self.computed, "skipped": self.skipped, "failed": len(self.failures),
                "failures": self.failures}


def sweep(spec: SweepSpec, out: str, *, executor: concurrent.futures.Executor | None = None, batch: int = 1,
          workers: int | None = None, scheduler: str | None = None, progress: bool = False,
          report=print) -> SweepTable:
    """Run every point of `spec` without a result in `out`, or whose result is a failure (batches of `batch`
    points on `executor`; None: a Dask client of `scheduler`, or of a local cluster), then write
    DIR/table.csv and DIR/chart.png. A batch whose worker died or whose task raised fails its points (their
    results say why) and the others go on. Returns the table's rows with what this sweep did (SweepTable)."""
    spec = replace(spec, invocation=uuid.uuid4().hex)
    points = grid_points(spec)
    check_points(spec, points)
    group = world_group(spec)
    prepare_folder(spec, out)
    missing = [p for p in points if not has_result(out, p)]
    report(f"{len(points) - len(missing)} of {len(points)} points already done; running {len(missing)}")
    if missing:
        with _executor(executor, spec, workers, scheduler, report) as pool:
            started, fresh = started_batches(out, missing) if spec.h5 else ([], missing)
            if started:
                report(f"{len(started)} batch(es) of a killed sweep go on from their trajectories' frames")
            planned = started + batches(fresh, batch, group)
            work = {pool.submit(run_batch, spec, points, out): points for points in planned}
            bar = tqdm(total=len(missing), unit="point", desc=spec.scene, disable=not progress)
            for future in concurrent.futures.as_completed(work):
                try:
                    future.result()
                except Exception as error:  # the batch's worker died (Dask's KilledWorker) or its task raised
                    lost_batch(spec, work[future], out, error)
                bar.update(len(work[future]))
            bar.close()
    rows = table_rows(out, points)
    write_table(rows, os.path.join(out, "table.csv"))
    sweep_chart_png(rows, list(spec.grid), spec.measure, os.path.join(out, "chart.png"), title=spec.scene)
    stored = [stored_result(out, point) for point in points]  # what this sweep wrote (a batch Dask ran twice, once)
    ours = [result for result in stored if result is not None and result.get("invocation") == spec.invocation]
    failures = {result["point"]: result.get("error", "") for result in ours if result["status"] == "failed"}
    computed = len(ours) - len(failures)
    return SweepTable(rows, computed=computed, skipped=len(points) - len(ours), failures=failures)


def stored_result(out: str, point: Point) -> dict | None:
    """The point's result in `out`, None where it has none (or an unreadable one)."""
    try:
        with open(result_path(out, point)) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def lost_batch(spec: SweepSpec, points, out: str, error: Exception) -> None:
    """A batch whose task ended in `error`: each of its points without a result gets a failure that says why
    (a re-run tries it again); those it finished before keep theirs."""
    if isinstance(error, KilledWorker):
        why = ("its worker process died every time the batch was tried: stopped by Dask's memory monitor (at 95% "
               "of the worker's memory limit) or crashed in native code; run the sweep again, with a smaller --batch "
               "(fewer worlds per run) or fewer workers per machine")
    else:
        why = f"its batch raised {type(error).__name__}: {' '.join(str(error).split())}"
    for point in points:
        if not has_result(out, point):
            write_json(result_path(out, point), {"point": point.name, "values": dict(point.values), "seed": point.seed,
                                                 "sweep": spec.definition(), "invocation": spec.invocation,
                                                 "status": "failed", "error": why, "wall_time_s": 0.0})
