"""Sweeps (docs/theory/sweeps.md): grid points, each point's result equal to the single run with its
settings, re-runs that compute only what is missing, failures that stop one point alone, and a
Dask cluster killed midway."""

import concurrent.futures
import csv
import importlib
import json
import os
import pkgutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
import warp as wp

from wavewarp import cli, kernels, walker
from wavewarp.device import deterministic_default, set_deterministic
from wavewarp.mesh import icosphere
from wavewarp.parameters import SceneError, load_scene, resolve
from distributed import Client, KilledWorker
from distributed.system import MEMORY_LIMIT

from wavewarp.sweep import (LISTED_COLUMNS, Point, SweepSpec, batches, grid_points, local_cluster, measurement_columns,
                            merge_kernel_cache, parse_grid, prepare_folder, sweep)

QUICK_CUBE = SweepSpec("cube-waves", grid={"gamma": ["0.8", "1.0"]}, seeds=2, quick=True, device="cpu")


class CountingExecutor(concurrent.futures.ThreadPoolExecutor):
    """One worker thread, counting the points it was given."""

    def __init__(self):
        super().__init__(max_workers=1)
        self.points = 0

    def submit(self, function, spec, points, out):
        self.points += len(points)
        return super().submit(function, spec, points, out)


def test_grid_points_vary_the_first_parameter_slowest_and_the_seed_fastest():
    grid = parse_grid(["AC=0,0.1", "sensitive=true,false"])
    assert grid == {"AC": ["0", "0.1"], "sensitive": ["true", "false"]}
    points = grid_points(SweepSpec("starfish", grid=grid, seeds=2))
    assert len(points) == 8 and points[0] == Point((("AC", "0"), ("sensitive", "true")), 0)
    assert [p.seed for p in points[:2]] == [0, 1] and points[2].values == (("AC", "0"), ("sensitive", "false"))
    assert points[-1].name == "AC=0.1_sensitive=false_seed=1"


def test_first_seed_starts_the_seeds_and_names_another_sweep(tmp_path):
    """Seeds N … N+K-1 at every grid point; a folder holding seeds from 0 refuses a sweep from N (and the
    definition without first_seed is unchanged, so that older folders continue)."""
    grid = parse_grid(["AC=0,0.1"])
    points = grid_points(SweepSpec("starfish", grid=grid, seeds=3, first_seed=4))
    assert [p.seed for p in points] == [4, 5, 6, 4, 5, 6] and points[0].name == "AC=0_seed=4"
    assert "first_seed" not in SweepSpec("starfish", grid=grid, seeds=3).definition()
    prepare_folder(SweepSpec("starfish", grid=grid, seeds=3), str(tmp_path))
    with pytest.raises(ValueError, match="holds another sweep"):
        prepare_folder(SweepSpec("starfish", grid=grid, seeds=3, first_seed=4), str(tmp_path))
    with pytest.raises(ValueError, match="--first-seed must be an integer >= 0"):
        grid_points(SweepSpec("starfish", grid=grid, first_seed=-1))


@pytest.mark.parametrize("items, message", [(["AC"], "--grid needs NAME=v1,v2"), (["AC=0,,1"], "no empty value"),
                                            (["AC=0", "AC=1"], "--grid AC is given twice")])  # fmt: skip
def test_bad_grids_are_named(items, message):
    with pytest.raises(ValueError, match=message):
        parse_grid(items)


def test_batches_deal_the_grid_round_robin():
    """Every point in exactly one batch, batches of at most B differing by at most one point, and a
    block of neighbouring (alike) points spread over the batches."""
    points = list(range(10))
    dealt = batches(points, 4)
    assert sorted(p for batch in dealt for p in batch) == points
    assert [len(b) for b in dealt] == [4, 3, 3]
    assert all(len({p // 3 for p in batch}) == len(batch) for batch in dealt)  # blocks of 3 alike points
    assert batches(points, 1) == [[p] for p in points]
    with pytest.raises(ValueError, match="--batch must be an integer >= 1"):
        batches(points, 0)


def test_batches_keep_points_of_one_group_together():
    """With a group key, a batch holds points of one group only, each group dealt round-robin."""
    dealt = batches(list(range(10)), 3, group=lambda p: p % 2)
    assert sorted(p for batch in dealt for p in batch) == list(range(10))
    assert all(len({p % 2 for p in batch}) == 1 and len(batch) <= 3 for batch in dealt) and len(dealt) == 4


def test_a_walker_sweep_runs_each_batch_as_one_batched_run(tmp_path):
    """sphere-walker over AC (a per-world parameter) and sensitive (shared) in batches of 2: each batch
    is one batched run of the points of one `sensitive` (the two AC values its worlds), each point with
    its own result and parameters (a world equals its single run: tests/test_batch.py)."""
    fixed = ("level=1", "periods=0.1", "frames=1", "settle=1", "dtype=float64", "contact_sweeps=2")
    spec = SweepSpec("sphere-walker", grid={"AC": ["0.1", "0.2"], "sensitive": ["true", "false"]}, fixed=fixed,
                     device="cpu")  # fmt: skip
    pool = CountingExecutor()
    rows = sweep(spec, str(tmp_path), executor=pool, batch=2)
    assert [row["status"] for row in rows] == ["done"] * 4 and pool.points == 4
    results = {}
    for point in grid_points(spec):
        with open(tmp_path / "points" / f"{point.name}.json") as f:
            results[point.name] = json.load(f)
    for name, result in results.items():
        assert result["batch"]["worlds"] == 2
        assert result["parameters"]["AC"] == float(result["values"]["AC"])
    assert {r["values"]["sensitive"] for r in results.values() if r["batch"]["world"] == 0} == {"true", "false"}


def test_a_batched_walker_sweep_keeps_each_points_trajectory(tmp_path):
    """--h5 with --batch: each world's frames in its point's HDF5 file, as many as its result counts, its
    measurements stored with it; the worlds' trajectories differ (their AC does)."""
    fixed = ("level=1", "periods=0.1", "frames=2", "settle=1", "dtype=float64", "contact_sweeps=2")
    spec = SweepSpec("sphere-walker", grid={"AC": ["0.1", "0.3"]}, fixed=fixed, device="cpu", h5=True)
    sweep(spec, str(tmp_path), executor=CountingExecutor(), batch=2)
    last = []
    for point in grid_points(spec):
        with open(tmp_path / "points" / f"{point.name}.json") as f:
            result = json.load(f)
        with h5py.File(tmp_path / "points" / f"{point.name}.h5", "r") as trajectory:
            positions = trajectory["frames"]["positions"][:]
            assert len(positions) == result["frames"] == 3 and np.isfinite(positions).all()
            assert json.loads(trajectory.attrs["parameters"])["AC"] == float(result["values"]["AC"])
            assert trajectory["frames"]["trace"].shape[2] == 8
            assert json.loads(trajectory.attrs["measurements"]) == result["measurements"]
        last.append(positions[-1])
    assert not np.array_equal(last[0], last[1])


def test_a_batched_buckling_sweep_gives_each_point_its_single_runs_result(tmp_path):
    """The Fig. S1b sweep's shape (AI x thickness, per-world parameters) at level 2: the four points as one
    batched run (deterministic float64) have the measurements of the same sweep run point by point, each
    point's trajectory holds its frames, and the chart shows n_mode over the grid."""
    fixed = ("level=2", "frames=2", "t_end=1", "dtype=float64", "adaptive_dt=false", "self_contact=false",
             "relax_iterations=300")  # fmt: skip
    grid = {"AI": ["10.5", "13.5"], "thickness": ["0.25", "0.5"]}
    results = {}
    for batch in (4, 1):
        spec = SweepSpec("buckling-modes", grid=grid, fixed=fixed, device="cpu", deterministic=True, h5=batch > 1,
                         measure="n_mode")  # fmt: skip
        out = tmp_path / f"batch{batch}"
        rows = sweep(spec, str(out), executor=CountingExecutor(), batch=batch)
        assert [row["status"] for row in rows] == ["done"] * 4 and (out / "chart.png").stat().st_size > 0
        for point in grid_points(spec):
            with open(out / "points" / f"{point.name}.json") as f:
                results.setdefault(point.name, []).append(json.load(f))
    for name, (batched, single) in results.items():
        assert batched["batch"]["worlds"] == 4 and "batch" not in single
        assert batched["measurements"] == single["measurements"] and batched["frames"] == single["frames"] == 3
        with h5py.File(tmp_path / "batch4" / "points" / f"{name}.h5", "r") as trajectory:
            assert len(trajectory["frames"]["positions"]) == 3


def test_bad_points_are_refused_before_anything_runs(tmp_path):
    with pytest.raises(SceneError, match="unknown parameter 'bogus' in --grid"):
        sweep(SweepSpec("cube-waves", grid={"bogus": ["1"]}), str(tmp_path), executor=CountingExecutor())
    with pytest.raises(SceneError, match="bad value for gamma: 'fast'"):
        sweep(SweepSpec("cube-waves", grid={"gamma": ["1", "fast"]}), str(tmp_path), executor=CountingExecutor())
    with pytest.raises(SceneError, match="gamma is both swept"):
        sweep(SweepSpec("cube-waves", grid={"gamma": ["1"]}, fixed=("gamma=2",)), str(tmp_path), executor=CountingExecutor())
    assert not os.path.exists(tmp_path / "points")


def test_each_point_equals_its_single_run_and_a_rerun_computes_only_the_missing(tmp_path, capsys):
    out = str(tmp_path / "sweep")
    pool = CountingExecutor()
    rows = sweep(QUICK_CUBE, out, executor=pool, batch=3)
    assert pool.points == 4 and [row["status"] for row in rows] == ["done"] * 4
    with open(os.path.join(out, "table.csv")) as f:
        table = list(csv.DictReader(f))
    assert [row["point"] for row in table] == [p.name for p in grid_points(QUICK_CUBE)]
    assert os.path.getsize(os.path.join(out, "chart.png")) > 0
    # the single run of one point, through the command line: the same measurements, bit for bit
    capsys.readouterr()
    code = cli.main(["run", "cube-waves", "--quick", "--device", "cpu", "--set", "gamma=0.8", "--json",
                     "--out", str(tmp_path / "single.usda")])  # fmt: skip
    single = json.loads(capsys.readouterr().out)
    with open(os.path.join(out, "points", "gamma=0.8_seed=0.json")) as f:
        point = json.load(f)
    assert code == 0 and point["measurements"] == {k: single[k] for k in point["measurements"]}
    assert point["frames"] == single["frames"] and point["steps"] == single["steps"]
    # lose one result (as a kill would): the re-run computes that point alone
    os.remove(os.path.join(out, "points", "gamma=1.0_seed=1.json"))
    before = os.path.getmtime(os.path.join(out, "points", "gamma=0.8_seed=0.json"))
    again = CountingExecutor()
    assert len(sweep(QUICK_CUBE, out, executor=again)) == 4 and again.points == 1
    assert os.path.getmtime(os.path.join(out, "points", "gamma=0.8_seed=0.json")) == before
    with pytest.raises(ValueError, match="holds another sweep"):
        sweep(SweepSpec("cube-waves", grid={"gamma": ["2"]}, quick=True), out, executor=CountingExecutor())


def test_a_failing_point_stops_alone(tmp_path):
    spec = SweepSpec("cube-waves", grid={"dt": ["auto", "50"]}, quick=True, device="cpu")
    rows = sweep(spec, str(tmp_path), executor=CountingExecutor())
    status = {row["point"]: row["status"] for row in rows}
    assert status["dt=auto_seed=0"] == "done" and status["dt=50_seed=0"] in ("stopped", "failed")
    with open(tmp_path / "points" / "dt=50_seed=0.json") as f:
        result = json.load(f)
    assert "stability bound" in (result.get("stopped") or result.get("error"))


@pytest.mark.slow
def test_a_dask_sweep_killed_midway_resumes_with_the_missing_points(tmp_path):
    """A local Dask cluster (one CPU worker) runs 4 starfish points; the sweep's process group is
    killed once the first result exists; the re-run computes only the points without one."""
    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "wavewarp.cli", "sweep", "starfish", "--quick", "--grid", "gamma=0.8,0.9,1.0,1.1",
               "--device", "cpu", "--workers", "1", "--out", str(out)]  # fmt: skip
    first = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def results():  # not the temporary siblings (.NAME.PID.*.tmp.json) a write in progress leaves
        return sorted(n for n in os.listdir(out / "points") if n.endswith(".json") and not n.startswith("."))

    while not (out / "points").is_dir() or not results():
        assert first.poll() is None, first.communicate()
        time.sleep(0.1)
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    kept = results()
    assert 1 <= len(kept) < 4
    times = {name: os.path.getmtime(out / "points" / name) for name in kept}
    again = subprocess.run(command, capture_output=True, text=True, check=True)
    assert f"{len(kept)} of 4 points already done; running {4 - len(kept)}" in again.stderr
    assert "4 points in" in again.stdout and "(4 done" in again.stdout
    assert {name: os.path.getmtime(out / "points" / name) for name in kept} == times


@pytest.mark.slow
def test_sweeps_reuse_a_running_cluster_and_it_stops_on_sigterm(tmp_path):
    """`wavewarp cluster` prints its scheduler's address; two sweeps sent there one after the other
    give the table of a sweep on its own cluster; SIGTERM stops it cleanly."""
    cluster = subprocess.Popen([sys.executable, "-m", "wavewarp.cli", "cluster", "--device", "cpu", "--workers", "2",
                                "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        line = cluster.stdout.readline()
        address = line.split("scheduler ")[1].split(";")[0]
        assert "2 workers" in line and address.startswith("tcp://")
        grid = ["sweep", "cube-waves", "--quick", "--grid", "gamma=0.8,1.1", "--device", "cpu"]
        for name in ("first", "second"):
            assert cli.main([*grid, "--scheduler", address, "--out", str(tmp_path / name)]) == 0
        assert cli.main([*grid, "--workers", "1", "--out", str(tmp_path / "alone")]) == 0
        tables = [(tmp_path / name / "table.csv").read_text().splitlines() for name in ("first", "second", "alone")]
        columns = tables[0][0].split(",")
        kept = [k for k, column in enumerate(columns) if column not in ("wall_time_s", "device")]
        rows = [[[row.split(",")[k] for k in kept] for row in table[1:]] for table in tables]
        assert rows[0] == rows[1] == rows[2] and len(rows[0]) == 2
    finally:
        cluster.send_signal(signal.SIGTERM)
        out, _ = cluster.communicate(timeout=60)
    assert cluster.returncode == 0 and "stopped" in out


def test_short_lists_of_numbers_get_a_column_per_entry():
    columns = measurement_columns({"speed": 0.5, "pulses": [0.1, -0.2], "flag": True, "label": "x",
                                   "long": list(range(LISTED_COLUMNS + 1)), "mixed": [1.0, "a"]})  # fmt: skip
    assert columns == {"speed": 0.5, "pulses_1": 0.1, "pulses_2": -0.2, "flag": True}


def test_walker_seeds_perturb_the_rest_shape(monkeypatch):
    """A walker's seed matters once noise > 0 (an ensemble of gaits); noise 0 keeps the scene's mesh."""
    built = []
    monkeypatch.setattr(walker, "WalkerRun", lambda name, mesh, p, **options: built.append(mesh))
    module = load_scene("sphere-walker")
    noisy = resolve(module.Parameters, module.QUICK, ["noise=1e-3"])
    for seed in (1, 2):
        module.build(noisy, seed=seed, device="cpu")
    module.build(resolve(module.Parameters, module.QUICK), seed=3, device="cpu")
    sphere = icosphere(noisy.radius, noisy.level)
    first, second = (mesh.vertices - sphere.vertices for mesh in built[:2])
    assert 0.5e-3 < np.std(first) / noisy.radius < 2e-3 and not np.allclose(first, second)
    assert np.array_equal(built[2].vertices, sphere.vertices)


class DyingExecutor(CountingExecutor):
    """Runs the first batch; the worker of every later one dies (as Dask reports it)."""

    def submit(self, function, spec, points, out):
        if self.points == 0:
            return super().submit(function, spec, points, out)
        self.points += len(points)
        future = concurrent.futures.Future()
        future.set_exception(KilledWorker("run_batch-1", None, 3))
        return future


def test_a_batch_whose_worker_dies_fails_its_points_alone_and_a_rerun_retries_them(tmp_path):
    rows = sweep(QUICK_CUBE, str(tmp_path), executor=DyingExecutor(), batch=2)
    assert rows.computed == 2 and sorted(rows.failures) == ["gamma=0.8_seed=1", "gamma=1.0_seed=1"]  # the 2nd batch
    assert all("worker process died" in error and "--batch" in error for error in rows.failures.values())
    assert sorted(row["status"] for row in rows) == ["done", "done", "failed", "failed"]  # the table has them all
    again = CountingExecutor()
    rows = sweep(QUICK_CUBE, str(tmp_path), executor=again)
    assert again.points == 2 and (rows.computed, rows.skipped, rows.failures) == (2, 2, {})


def test_a_local_clusters_workers_share_the_machines_memory():
    """One worker gets all of it (Dask's default would give it memory × threads / cores)."""
    with local_cluster("cpu", workers=1) as cluster, Client(cluster) as client:
        limits = [w["memory_limit"] for w in client.scheduler_info()["workers"].values()]
    assert limits == [MEMORY_LIMIT]


def test_workers_kernels_are_merged_back_into_the_cache(tmp_path):
    """Entries the worker compiled are copied into the parent's cache; existing ones are kept as they are."""
    worker, parent = tmp_path / "worker", tmp_path / "parent"
    for folder, entries in ((worker, {"wp_a_1": "new", "wp_b_2": "worker's"}), (parent, {"wp_b_2": "parent's"})):
        for entry, text in entries.items():
            (folder / entry).mkdir(parents=True)
            (folder / entry / "module.o").write_text(text)
    merge_kernel_cache(str(worker), str(parent))
    assert sorted(os.listdir(parent)) == ["wp_a_1", "wp_b_2"]
    assert (parent / "wp_a_1" / "module.o").read_text() == "new"
    assert (parent / "wp_b_2" / "module.o").read_text() == "parent's"


def test_deterministic_mode_reaches_every_kernel_module():
    """With CUDA every kernel module takes Warp's run-to-run mode; without, the modules keep their options
    (the CPU's atomics are ordered already: no second compile) while the gathers and reductions still
    choose their fixed order."""
    modules = [importlib.import_module(f"wavewarp.kernels.{m.name}") for m in pkgutil.iter_modules(kernels.__path__)
               if m.name not in kernels.BUILT_ON_DEMAND]  # fmt: skip
    on = wp.DeterministicMode.RUN_TO_RUN if wp.is_cuda_available() else wp.DeterministicMode.NOT_GUARANTEED
    try:
        set_deterministic(True)
        assert all(wp.get_module_options(m)["deterministic"] == on for m in modules)
        assert deterministic_default() is True
    finally:
        set_deterministic(False)
    assert all(wp.get_module_options(m)["deterministic"] == wp.DeterministicMode.NOT_GUARANTEED for m in modules)
    assert deterministic_default() is False
