"""`wavewarp bench fig3a` at quick settings on the CPU (the sphere twins, 2 seeds, level 2, 2 periods): the JSON's
schema, t/T on each twin's own period, the displacement from t = 0 against the trajectories' own centre of mass, the
pulses' sum, a refused paper-literal shell recorded as a failure, and a re-run that skips the finished runs (each seed
alone: --h5); a batched job's seeds against their single runs, and its refused worlds."""

import json
import os

import h5py
import numpy as np
import pytest

from wavewarp.benchmarks import fig3a
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import Mesh

ARGS = ["--device", "cpu", "--quick", "--scenes", "sphere-walker", "--regimes", "default", "paper-literal",
        "--paper-young", "sphere-walker=2000", "--set", "settle=10", "--h5"]
TOP_LEVEL = {"level", "front_speed_ratio", "device", "date", "runs", "claims"}
RUN_FIELDS = {"scene", "regime", "sensitive", "seed", "period", "t_over_T", "displacement_R", "pulse_displacements_R"}


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """The bench run once, its JSON, and the points' modification times before a second run of the same command."""
    out = tmp_path_factory.mktemp("fig3a")
    assert fig3a.main([*ARGS, "--out", str(out)]) == 0
    with open(out / "fig3a.json") as f:
        result = json.load(f)
    times = {name: os.stat(out / "points" / name).st_mtime_ns for name in os.listdir(out / "points")}
    return out, result, times


def done(result):
    return [run for run in result["runs"] if run["status"] == "done"]


def test_json_schema(bench):
    out, result, _ = bench
    assert set(result) == TOP_LEVEL
    assert result["level"] == 2 and result["device"].startswith("cpu")
    assert result["front_speed_ratio"] == 0.0  # the level-2 front pins (the accuracy case's stalled front)
    assert len(result["runs"]) == 8 and all(RUN_FIELDS <= set(run) for run in result["runs"])
    assert {(run["sensitive"], run["seed"]) for run in done(result)} == {(s, k) for s in (True, False) for k in (0, 1)}
    assert set(result["claims"]) == {"each_pulse_forward", "sensitive_sphere_farther", "insensitive_prism_under_half"}
    for claim in result["claims"].values():
        assert set(claim["regimes"]) == {"default", "paper-literal"}
        for checks in claim["regimes"].values():
            assert [check["t_over_T"] for check in checks] == [2, 4, 6, 12]
            assert all(check["verdict"] in ("holds", "fails", "undecided", "not run") for check in checks)
    default = {check["t_over_T"]: check for check in result["claims"]["sensitive_sphere_farther"]["regimes"]["default"]}
    assert default[2]["verdict"] != "not run" and default[4]["verdict"] == "not run"  # runs of 2.1 T₀
    assert os.path.getsize(out / "fig3a.png") > 0


def test_t_over_T_uses_each_twins_own_period(bench):
    _, result, _ = bench
    periods = {run["sensitive"]: run["period"] for run in done(result)}
    assert periods[True] != pytest.approx(periods[False], rel=1e-3)  # the twins' waves differ in period
    for run in done(result):
        t_over_T = np.array(run["t_over_T"])
        np.testing.assert_allclose(t_over_T * run["period"], run["time"], rtol=1e-12)
        whole = np.arange(np.floor(t_over_T[-1] + 1e-9) + 1)
        assert all(np.isclose(t_over_T, k, atol=1e-9).any() for k in whole) and len(whole) >= 3


def test_displacement_from_t0_equals_the_trajectorys_centre_of_mass(bench):
    out, result, _ = bench
    for run in done(result):
        name = f"default_sphere-walker_{'sensitive' if run['sensitive'] else 'insensitive'}_seed{run['seed']}.h5"
        with h5py.File(out / "points" / name, "r") as f:
            mesh = Mesh(f["mesh/rest_positions"][:], f["mesh/triangles"][:])
            times, positions = f["frames/time"][:], f["frames/positions"][:]
            radius = json.loads(f.attrs["parameters"])["radius"]
        mass = LaplaceBeltrami(mesh, device="cpu", dtype="float64").mass()
        along = np.einsum("v,fv->f", mass, positions[:, :, 0]) / mass.sum()
        expected = (along - along[0]) / radius
        assert run["displacement_R"][0] == 0.0 and run["t_over_T"][0] == 0.0
        measured = np.interp(times / run["period"], run["t_over_T"], run["displacement_R"])
        np.testing.assert_allclose(measured, expected, atol=2e-6)
        assert abs(expected[-1]) > 1e-4  # the comparison sees the walk, not only round-off


def test_pulses_sum_to_the_displacement_at_the_last_whole_period(bench):
    _, result, _ = bench
    for run in done(result):
        pulses = run["pulse_displacements_R"]
        assert len(pulses) == int(np.floor(run["t_over_T"][-1] + 1e-9)) >= 2
        last = np.interp(len(pulses), run["t_over_T"], run["displacement_R"])
        assert sum(pulses) == pytest.approx(last, rel=1e-12, abs=1e-15)


def test_a_refused_shell_is_recorded_not_fatal(bench):
    out, result, _ = bench
    failed = [run for run in result["runs"] if run["status"] != "done"]
    assert {run["regime"] for run in failed} == {"paper-literal"} and len(failed) == 4
    for run in failed:
        assert "sags 0." in run["error"] and "outside 1–10%" in run["error"] and "--paper-young" in run["error"]
        assert run["period"] is None and run["displacement_R"] is None
    assert all(check["verdict"] == "not run" for check in
               result["claims"]["sensitive_sphere_farther"]["regimes"]["paper-literal"])


def test_a_rerun_skips_finished_points_and_retries_failed_ones(bench, capsys):
    out, _, before = bench
    capsys.readouterr()
    assert fig3a.main([*ARGS, "--out", str(out)]) == 0
    assert "8 runs, 4 finished before, 4 to run" in capsys.readouterr().out
    after = {name: os.stat(out / "points" / name).st_mtime_ns for name in before}
    assert {name for name in before if after[name] != before[name]} == {
        name for name in before if name.startswith("paper-literal")}


def test_a_folder_of_other_settings_is_refused(bench):
    out, _, _ = bench
    with pytest.raises(ValueError, match="use another --out"):
        fig3a.main([*ARGS, "--periods", "3", "--out", str(out)])


def test_paper_footing_on_a_made_up_trace():
    t = np.arange(0.0, 10.01, 0.5)
    trace = np.zeros((len(t), 8))
    trace[:, 0], trace[:, 2], trace[:, 3] = t, 3.0 + 0.1 * t**2, 5.0 * t  # forward x; sideways y ignored
    footing = fig3a.paper_footing(trace, [1.0, 0.0, 0.0], 2.0, period=4.0, frame_times=[0.0, 5.0, 10.0])
    assert footing["t_over_T"] == [0.0, 1.0, 1.25, 2.0, 2.5]
    np.testing.assert_allclose(footing["displacement_R"], [0.0, 0.8, 1.25, 3.2, 5.0], atol=0.02)
    np.testing.assert_allclose(footing["pulse_displacements_R"], [0.8, 2.4], atol=0.02)
    assert fig3a.prism_divisions(4) == 34 and fig3a.prism_divisions(2) == 8


def test_a_run_killed_part_way_continues_from_its_trajectory(bench, tmp_path):
    from wavewarp.trajectory import COMPLETE

    out, _, _ = bench
    sensitive, insensitive = (f"default_sphere-walker_{twin}_seed0" for twin in ("sensitive", "insensitive"))
    os.makedirs(tmp_path / "points")
    for name in (f"{sensitive}.h5", f"{insensitive}.json"):
        with open(out / "points" / name, "rb") as source, open(tmp_path / "points" / name, "wb") as target:
            target.write(source.read())
    with h5py.File(tmp_path / "points" / f"{sensitive}.h5", "r+") as f:
        f["frames"].attrs[COMPLETE] = 2  # killed after its second frame
    assert fig3a.main([*ARGS[:5], "--regimes", "default", "--seeds", "1", *ARGS[8:], "--out", str(tmp_path)]) == 0
    with open(tmp_path / "points" / f"{sensitive}.json") as f:
        resumed = json.load(f)
    with open(out / "points" / f"{sensitive}.json") as f:
        whole = json.load(f)
    assert resumed["status"] == "done" and resumed["resumed_after_frames"] == 2
    assert resumed["period"] == whole["period"]
    np.testing.assert_allclose(resumed["displacement_R"], whole["displacement_R"], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_a_batched_job_gives_each_seed_its_own_run(tmp_path, monkeypatch):
    """One twin's three seeds as one batched job (float64), the third world refused by its sag check (stubbed): it is
    recorded failed with its error, and each of the others' JSON holds the displacement series, period and sag of
    that seed run alone (a WalkerRun settled with the batch's steps, which the worlds share), bit for bit (batch.py:
    every reduction per world, in a fixed order on the CPU)."""
    from wavewarp.driver import simulate
    from wavewarp.parameters import load_scene, resolve
    from wavewarp.runs import imperfect
    from wavewarp.walker import WalkerRun

    worlds = iter(range(3))
    monkeypatch.setattr(fig3a, "sag_refusal", lambda *args: ValueError("refused") if next(worlds) == 2 else None)
    job = fig3a.Job("sphere-walker", "default", True, (0, 1, 2))
    overrides = job.points[0].overrides(2, 2.0, [*fig3a.QUICK, "settle=10", "dtype=float64"])
    fig3a.run_job(job, overrides, "cpu", str(tmp_path), False, None)
    records = []
    for point in job.points:
        with open(tmp_path / f"{point.name}.json") as f:
            records.append(json.load(f))
    assert records[2]["status"] == "failed" and records[2]["error"] == "ValueError: refused"
    assert "period" not in records[2]
    module = load_scene(job.scene)
    p = resolve(module.Parameters, None, overrides)
    mesh, options = module.recipe(p, device="cpu", report=lambda message: None)
    for point, batched in zip(job.points[:2], records):
        assert batched["status"] == "done" and batched["batch_seeds"] == [0, 1, 2]
        run = WalkerRun(module.NAME, imperfect(mesh, p.noise * options["radius"], point.seed), p, device="cpu",
                        mechanics_dt=tuple(batched["settle_dt"]), report=lambda message: None, **options)
        dynamics = run.dynamics
        sag = fig3a.settled_sag(dynamics.positions(), dynamics.mass, dynamics.total_mass, run.rest_height, run.radius)
        outcome = simulate(run, [])
        alone = fig3a.walked(run, outcome.measurements, run.trace, run.forward, sag, run.resolved)
        for name in ("period", "time", "t_over_T", "displacement_R", "pulse_displacements_R", "sag_R", "mechanics_dt",
                     "substeps", "mechanics_steps"):
            assert batched[name] == alone[name], name
    assert records[0]["displacement_R"] != records[1]["displacement_R"]  # the seeds' walks differ


def test_a_batch_whose_every_shell_is_refused_does_not_run(tmp_path, monkeypatch):
    """Paper-literal shells too stiff to sag 1 %: every seed of the batched job recorded failed with the sag check's
    error, the batch never stepped."""
    from wavewarp.batch import WalkerBatch

    def never(*args, **kwargs):
        raise AssertionError("the refused batch ran")

    monkeypatch.setattr(WalkerBatch, "run", never)
    job = fig3a.Job("sphere-walker", "paper-literal", False, (0, 1))
    overrides = job.points[0].overrides(2, 2.0, [*fig3a.QUICK, "settle=10"], {"sphere-walker": 2000.0})
    records = fig3a.run_job(job, overrides, "cpu", str(tmp_path), False, None)
    assert [record["status"] for record in records] == ["failed", "failed"]
    assert all("sags 0." in record["error"] and "outside 1–10%" in record["error"] for record in records)


def test_h5_runs_each_seed_alone():
    assert fig3a.parse(["--seeds", "4"]).batch == 4 and fig3a.parse(["--seeds", "4", "--batch", "3"]).batch == 3
    assert fig3a.parse(["--seeds", "4", "--h5"]).batch == 1
    with pytest.raises(SystemExit):
        fig3a.parse(["--h5", "--batch", "2"])
