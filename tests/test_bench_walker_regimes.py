"""`wavewarp bench walker_regimes --tables`: the twins' statistics and the paper's three claims from sweep
tables, against NumPy on tables made up here (one regime meets every claim, one meets none)."""

import argparse
import csv
import json
import math
import os

import numpy as np
import pytest

from wavewarp.benchmarks import walker_regimes
from wavewarp.cli import main as cli

SPEEDS = {  # (regime, scene, sensitive): speeds of four seeds
    ("inertial-implicit-coulomb", "sphere-walker", True): [0.52, 0.55, 0.50, 0.53],
    ("inertial-implicit-coulomb", "sphere-walker", False): [0.30, 0.31, 0.29, 0.30],
    ("inertial-implicit-coulomb", "prism-walker", True): [0.030, 0.032, 0.031, 0.029],
    ("inertial-implicit-coulomb", "prism-walker", False): [0.010, 0.011, 0.009, 0.010],
    ("overdamped-implicit-coulomb", "sphere-walker", True): [0.30, 0.28, 0.33, 0.29],
    ("overdamped-implicit-coulomb", "sphere-walker", False): [0.31, 0.30, 0.29, 0.32],
    ("overdamped-implicit-coulomb", "prism-walker", True): [-0.002, -0.001, -0.003, -0.002],
    ("overdamped-implicit-coulomb", "prism-walker", False): [0.001, 0.002, 0.001, -0.001],
}


def write_tables(folder):
    for regime, scene in {(r, s) for r, s, _ in SPEEDS}:
        with open(folder / f"{regime}_{scene}.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=["point", "sensitive", "seed", "status", "period", "speed_R_per_T",
                                                       "rolling_angle_deg", "sag_R"])
            writer.writeheader()
            for sensitive in (True, False):
                for seed, speed in enumerate(SPEEDS[(regime, scene, sensitive)]):
                    writer.writerow({"point": f"sensitive={str(sensitive).lower()}_seed={seed}",
                                     "sensitive": str(sensitive).lower(), "seed": seed, "status": "done",
                                     "period": 260.0 if sensitive else 280.0, "speed_R_per_T": speed,
                                     "rolling_angle_deg": 90.0 * speed + seed, "sag_R": 0.01 * (seed + 1)})  # fmt: skip


def test_walker_regimes_summarises_twins_and_checks_the_papers_claims(tmp_path):
    write_tables(tmp_path)
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    result = json.loads((tmp_path / "walker_regimes.json").read_text())
    for (regime, scene, sensitive), speeds in SPEEDS.items():
        cell = result["regimes"][regime]["scenes"][scene]
        twin = cell["sensitive" if sensitive else "insensitive"]
        assert twin["n"] == 4 and twin["mean"] == pytest.approx(np.mean(speeds), rel=1e-12)
        assert twin["sd"] == pytest.approx(np.std(speeds, ddof=1), rel=1e-12)
        assert twin["forward_share"] == np.mean(np.array(speeds) > 0)
        assert twin["rolling_angle_deg"] == pytest.approx(np.mean(90.0 * np.array(speeds) + np.arange(4)), rel=1e-12)
        assert twin["sag_R"] == pytest.approx(0.025, rel=1e-12)
    cell = result["regimes"]["inertial-implicit-coulomb"]["scenes"]["prism-walker"]
    s, i = np.array(SPEEDS[("inertial-implicit-coulomb", "prism-walker", True)]), np.array(SPEEDS[("inertial-implicit-coulomb", "prism-walker", False)])  # fmt: skip
    ratio = s.mean() / i.mean()
    spread = ratio * math.hypot(s.std(ddof=1) / 2 / s.mean(), i.std(ddof=1) / 2 / i.mean())
    assert cell["speed_ratio"] == pytest.approx(ratio, rel=1e-12)
    assert cell["speed_ratio_spread"] == pytest.approx(spread, rel=1e-12)
    assert cell["period_ratio"] == pytest.approx(260 / 280, rel=1e-12)
    assert result["regimes"]["inertial-implicit-coulomb"]["claims"] == {
        "forward": True, "sensitive_sphere_faster": True, "prism_ratio_above_2": True}
    assert result["regimes"]["overdamped-implicit-coulomb"]["claims"] == {
        "forward": False, "sensitive_sphere_faster": False, "prism_ratio_above_2": False}
    assert (tmp_path / "walker_regimes.png").stat().st_size > 0


def test_one_seed_a_twin_leaves_the_sphere_claim_undecided(tmp_path):
    with open(tmp_path / "overdamped-implicit-coulomb-drag6_sphere-walker.csv", "w", newline="") as f:
        f.write("point,sensitive,seed,status,period,speed_R_per_T\n"
                "sensitive=true_seed=0,true,0,done,268,0.003\nsensitive=false_seed=0,false,0,done,278,0.002\n")
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    claims = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb-drag6"]["claims"]
    assert claims == {"forward": True, "sensitive_sphere_faster": None, "prism_ratio_above_2": None}


def test_twins_are_compared_per_unit_time_over_the_pulses_every_seed_has(tmp_path):
    """The sensitive twin's shorter period gives it a third pulse, here a large one: over whole runs it
    looks faster per pulse, over the two pulses both twins have and per unit time it is slower."""
    sensitive = {0: [1.0e-3, 4.0e-4, 1.5e-3], 1: [1.1e-3, 4.4e-4, 1.6e-3], 2: [0.9e-3, 4.2e-4, 1.4e-3]}
    insensitive = {0: [1.1e-3, 5.0e-4], 1: [1.2e-3, 5.2e-4], 2: [1.0e-3, 4.8e-4]}
    periods = {True: 268.0, False: 278.0}
    with open(tmp_path / "overdamped-implicit-kf100_sphere-walker.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["point", "sensitive", "seed", "status", "period", "speed_R_per_T",
                                               *(f"pulse_displacements_R_{k}" for k in (1, 2, 3))])  # fmt: skip
        writer.writeheader()
        for flag, twin in ((True, sensitive), (False, insensitive)):
            for seed, pulses in twin.items():
                writer.writerow({"point": f"s{flag}{seed}", "sensitive": str(flag).lower(), "seed": seed,
                                 "status": "done", "period": periods[flag] + seed, "speed_R_per_T": np.mean(pulses),
                                 **{f"pulse_displacements_R_{k}": v for k, v in enumerate(pulses, 1)}})  # fmt: skip
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    result = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-kf100"]
    cell = result["scenes"]["sphere-walker"]
    s = np.array([np.mean(p[:2]) / (periods[True] + seed) for seed, p in sensitive.items()])
    i = np.array([np.mean(p[:2]) / (periods[False] + seed) for seed, p in insensitive.items()])
    assert cell["compared"] == "first 2 pulse(s) of every seed, per unit time"
    assert cell["speed_ratio"] == pytest.approx(s.mean() / i.mean(), rel=1e-12)
    error = math.hypot(s.std(ddof=1), i.std(ddof=1)) / math.sqrt(3)
    assert cell["separation"] == pytest.approx((s.mean() - i.mean()) / error, rel=1e-12)
    assert cell["sensitive"]["mean"] > cell["insensitive"]["mean"]  # whole runs, per pulse
    assert result["claims"]["sensitive_sphere_faster"] is False
    assert cell["sensitive"]["pulse_forward_share"] == 1.0 and result["claims"]["forward"] is True
    for twin, flag in ((sensitive, "sensitive"), (insensitive, "insensitive")):  # Fig. 3a's curve over the pulses
        walks = np.array([np.cumsum(p) for p in twin.values()])  # each twin's seeds have equally many
        assert cell[flag]["distance_by_pulse_R"]["mean"] == pytest.approx(walks.mean(axis=0), rel=1e-12)
        assert cell[flag]["distance_by_pulse_R"]["sd"] == pytest.approx(walks.std(axis=0, ddof=1), rel=1e-12)
    assert (tmp_path / "walker_regimes_gaits.png").read_bytes()[:4] == b"\x89PNG"


def test_one_backward_pulse_fails_the_forward_claim(tmp_path):
    """Claim 1 is about every pulse: a run whose mean is forward but whose first pulse went back fails it."""
    with open(tmp_path / "overdamped-implicit-coulomb_prism-walker.csv", "w", newline="") as f:
        f.write("point,sensitive,seed,status,period,speed_R_per_T,pulse_displacements_R_1,pulse_displacements_R_2\n"
                "a,true,0,done,268,0.0002,-0.0001,0.0005\na,true,1,done,268,0.0003,0.0001,0.0005\n"
                "b,false,0,done,278,0.0002,0.0002,0.0002\nb,false,1,done,278,0.0001,0.0001,0.0001\n")
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    result = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb"]
    assert result["scenes"]["prism-walker"]["sensitive"]["pulse_forward_share"] == 0.75
    assert result["scenes"]["prism-walker"]["sensitive"]["forward_share"] == 1.0
    assert result["claims"]["forward"] is False


def test_two_backward_twins_fail_the_prism_claim_whatever_their_ratio(tmp_path):
    """Both twins crawl back over the pulses they share, the sensitive one 3× as far: the ratio is 3, the
    claim (the sensitive prism more than twice as fast along the wave) fails. The sensitive twin's extra
    third pulse makes its whole-run mean forward."""
    with open(tmp_path / "overdamped-implicit-coulomb-body_prism-walker.csv", "w", newline="") as f:
        f.write("point,sensitive,seed,status,period,speed_R_per_T,pulse_displacements_R_1,pulse_displacements_R_2,"
                "pulse_displacements_R_3\n"
                "a,true,0,done,260,0.001,0.001,-0.007,0.009\na,true,1,done,260,0.001,0.0012,-0.0072,0.009\n"
                "b,false,0,done,280,-0.001,0.001,-0.003,\nb,false,1,done,280,-0.001,0.0011,-0.0031,\n")
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    result = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb-body"]
    cell = result["scenes"]["prism-walker"]
    s = np.mean([(0.001 - 0.007) / 2 / 260, (0.0012 - 0.0072) / 2 / 260])
    i = np.mean([(0.001 - 0.003) / 2 / 280, (0.0011 - 0.0031) / 2 / 280])
    assert cell["compared_speeds"] == pytest.approx([s, i], rel=1e-12) and cell["speed_ratio"] > 2
    assert cell["sensitive"]["mean"] > 0 and result["claims"]["prism_ratio_above_2"] is False


def test_footings_that_disagree_leave_the_sphere_claim_undecided(tmp_path):
    """Pulse for pulse the sensitive sphere is slower; in the same time it goes further (its start-up and
    its extra pulse): the gait is still changing over the run, and the claim is left open."""
    rows = {True: [(0.020, 0.004, 0.005), (0.021, 0.0041, 0.0052), (0.019, 0.0039, 0.0049)],
            False: [(0.012, 0.005, 0.006), (0.013, 0.0052, 0.0061), (0.011, 0.0049, 0.0058)]}  # fmt: skip
    with open(tmp_path / "overdamped-implicit-coulomb_sphere-walker.csv", "w", newline="") as f:
        f.write("point,sensitive,seed,status,time,period,speed_R_per_T,distance_R,pulse_displacements_R_1,"
                "pulse_displacements_R_2\n")
        for flag, twin in rows.items():
            for seed, (distance, first, second) in enumerate(twin):
                f.write(f"p,{str(flag).lower()},{seed},done,1104,270,{(first + second) / 2},{distance},{first},{second}\n")
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    result = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb"]
    cell = result["scenes"]["sphere-walker"]
    s, i = np.array([r[0] for r in rows[True]]), np.array([r[0] for r in rows[False]])
    assert cell["distance_ratio"] == pytest.approx(s.mean() / i.mean(), rel=1e-12)
    error = math.hypot(s.std(ddof=1), i.std(ddof=1)) / math.sqrt(3)
    assert cell["distance_separation"] == pytest.approx((s.mean() - i.mean()) / error, rel=1e-12)
    assert cell["separation"] < -2 and result["claims"]["sensitive_sphere_faster"] is None


def write_pulses(path, sensitive: dict, insensitive: dict) -> None:
    """A made-up table of long runs: {seed: per-pulse displacements} a twin, periods 268 and 278."""
    count = len(next(iter(sensitive.values())))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["point", "sensitive", "seed", "status", "time", "period", "distance_R",
                                               "speed_R_per_T", *(f"pulse_displacements_R_{k}" for k in range(1, count + 1))])  # fmt: skip
        writer.writeheader()
        for flag, twin in ((True, sensitive), (False, insensitive)):
            for seed, pulses in twin.items():
                writer.writerow({"point": f"s{flag}{seed}", "sensitive": str(flag).lower(), "seed": seed,
                                 "status": "done", "time": 3300, "period": 268.0 if flag else 278.0,
                                 "distance_R": 0.001, "speed_R_per_T": np.mean(pulses),
                                 **{f"pulse_displacements_R_{k}": v for k, v in enumerate(pulses, 1)}})  # fmt: skip


def test_late_pulses_decide_the_sphere_claim_once_the_start_up_is_left_out(tmp_path):
    """A long run whose first two pulses favour the insensitive twin and whose later ones the sensitive:
    with --skip-pulses 2 the twins are compared over pulses 3 to 5 alone, and too few pulses is an error."""
    sensitive = {0: [4e-4, 4e-4, 9e-4, 9.2e-4, 9.1e-4], 1: [4.1e-4, 4e-4, 9.1e-4, 9e-4, 9.3e-4]}
    insensitive = {0: [6e-4, 6e-4, 7e-4, 7.1e-4, 6.9e-4], 1: [6.1e-4, 5.9e-4, 7.1e-4, 7e-4, 7.2e-4]}
    write_pulses(tmp_path / "overdamped-implicit-coulomb_sphere-walker.csv", sensitive, insensitive)
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up",
                "--skip-pulses", "2"]) == 0  # fmt: skip
    result = json.loads((tmp_path / "walker_regimes.json").read_text())
    cell = result["regimes"]["overdamped-implicit-coulomb"]["scenes"]["sphere-walker"]
    s = np.array([np.mean(p[2:]) / 268.0 for p in sensitive.values()])
    i = np.array([np.mean(p[2:]) / 278.0 for p in insensitive.values()])
    assert result["skip_pulses"] == 2 and cell["compared"] == "pulses 3 to 5 of every seed, per unit time"
    assert cell["speed_ratio"] == pytest.approx(s.mean() / i.mean(), rel=1e-12) and "distances" not in cell
    assert result["regimes"]["overdamped-implicit-coulomb"]["claims"]["sensitive_sphere_faster"] is True
    with pytest.raises(SystemExit):
        cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up", "--skip-pulses", "5"])


def test_halves_of_the_compared_pulses_that_disagree_leave_the_claims_undecided(tmp_path):
    """After the start-up (pulse 1) the sensitive sphere leads over pulses 2-3 and trails over 4-5; the sensitive
    prism is 1.5× as fast over pulses 2-3 and 5× over 4-5, 2.6× over all four: each claim is undecided."""
    write_pulses(tmp_path / "overdamped-implicit-coulomb_sphere-walker.csv",
                 {0: [1e-3, 9e-4, 9.1e-4, 6e-4, 6.1e-4], 1: [1e-3, 9.2e-4, 9e-4, 6.2e-4, 6.1e-4]},
                 {0: [1e-3, 7e-4, 7.1e-4, 8e-4, 8.1e-4], 1: [1e-3, 7.1e-4, 7.2e-4, 8.2e-4, 8.1e-4]})  # fmt: skip
    write_pulses(tmp_path / "overdamped-implicit-coulomb_prism-walker.csv",
                 {0: [1e-4, 3e-4, 3e-4, 5e-4, 5e-4], 1: [1e-4, 3.1e-4, 2.9e-4, 5.1e-4, 4.9e-4]},
                 {0: [1e-4, 2e-4, 2e-4, 1e-4, 1e-4], 1: [1e-4, 2.1e-4, 1.9e-4, 1.1e-4, 0.9e-4]})  # fmt: skip
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up",
                "--skip-pulses", "1"]) == 0  # fmt: skip
    regime = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb"]
    sphere, prism = regime["scenes"]["sphere-walker"], regime["scenes"]["prism-walker"]
    assert [h["compared"] for h in sphere["halves"]] == ["pulses 2 to 3 of every seed, per unit time",
                                                          "pulses 4 to 5 of every seed, per unit time"]  # fmt: skip
    assert sphere["halves"][0]["separation"] > 2 and sphere["halves"][1]["separation"] < -2
    assert sphere["separation"] > 2 and regime["claims"]["sensitive_sphere_faster"] is None
    ratios = [prism["speed_ratio"], *(h["speed_ratio"] for h in prism["halves"])]
    assert ratios == pytest.approx([4.0 / 268 / (1.5 / 278), 3.0 / 268 / (2.0 / 278), 5.0 / 268 / (1.0 / 278)], rel=1e-9)
    assert regime["claims"]["prism_ratio_above_2"] is None


def test_the_centres_height_drift_is_the_slope_at_the_crossings(tmp_path):
    """Heights at the crossings rising 1e-4 R a pulse (sensitive, with a wobble that a straight line
    averages out) and flat (insensitive); tables without the column report none."""
    path = tmp_path / "overdamped-implicit-coulomb_sphere-walker.csv"
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["point", "sensitive", "seed", "status", "period", "speed_R_per_T",
                                               *(f"crossing_heights_R_{k}" for k in range(1, 6))])  # fmt: skip
        writer.writeheader()
        for flag, slope in ((True, 1e-4), (False, 0.0)):
            for seed in (0, 1):
                heights = [slope * k + (2e-5 if k in (1, 3) else 0.0) + 1e-3 * seed for k in range(5)]
                writer.writerow({"point": f"s{flag}{seed}", "sensitive": str(flag).lower(), "seed": seed, "status": "done",
                                 "period": 270.0, "speed_R_per_T": 1e-3,
                                 **{f"crossing_heights_R_{k}": v for k, v in enumerate(heights, 1)}})  # fmt: skip
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    cell = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb"]
    sphere = cell["scenes"]["sphere-walker"]
    assert sphere["sensitive"]["height_drift_R_per_pulse"] == pytest.approx(1e-4, rel=1e-9)
    assert sphere["insensitive"]["height_drift_R_per_pulse"] == pytest.approx(0.0, abs=1e-15)
    write_pulses(path, {0: [1e-3, 1e-3]}, {0: [1e-3, 1e-3]})
    assert cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "made up"]) == 0
    cell = json.loads((tmp_path / "walker_regimes.json").read_text())["regimes"]["overdamped-implicit-coulomb"]
    assert cell["scenes"]["sphere-walker"]["sensitive"]["height_drift_R_per_pulse"] is None


def test_a_regimes_sweep_keeps_trajectories_with_h5(tmp_path, monkeypatch):
    """--h5 reaches the regime's sweep (a batch killed part-way then goes on: tests/test_sweep_resume.py), its
    fixed settings are the regime's, its folder OUT/sweeps/REGIME_SCENE."""
    calls = []

    def fake_sweep(spec, folder, **options):
        calls.append((spec, folder))
        os.makedirs(folder, exist_ok=True)
        open(os.path.join(folder, "table.csv"), "w").close()

    monkeypatch.setattr(walker_regimes, "sweep", fake_sweep)
    for h5 in (False, True):
        args = argparse.Namespace(noise=1e-3, periods=4.0, set=[], seeds=8, quick=False, out=str(tmp_path), h5=h5)
        walker_regimes.run_regime("overdamped-implicit-coulomb-drag20", "prism-walker", args, "cpu", None)
    assert [spec.h5 for spec, _ in calls] == [False, True]
    assert "drag=20" in calls[1][0].fixed
    assert calls[1][1] == str(tmp_path / "sweeps" / "overdamped-implicit-coulomb-drag20_prism-walker")


def test_walker_regimes_needs_tables_and_names_their_device(tmp_path):
    with pytest.raises(SystemExit):
        cli(["bench", "walker_regimes", "--tables", str(tmp_path)])
    with pytest.raises(SystemExit):
        cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "x"])


@pytest.mark.slow
def test_walker_regimes_runs_its_sweeps_and_keeps_their_tables(tmp_path, capsys):
    """Two regimes' sweeps side by side on one local cluster: each keeps its own table, the summary
    counts each table's seeds, and the scan run again (one regime lost its results) computes only those."""
    command = ["bench", "walker_regimes", "--quick", "--device", "cpu", "--seeds", "1", "--pairs",
               "overdamped-implicit-coulomb:prism-walker", "inertial-implicit-coulomb:prism-walker", "--periods",
               "0.05", "--set", "settle=1", "--out", str(tmp_path)]  # fmt: skip
    assert cli(command) == 0
    for result in (tmp_path / "sweeps" / "inertial-implicit-coulomb_prism-walker").glob("**/sensitive=*.json"):
        result.unlink()
    capsys.readouterr()
    assert cli(command) == 0
    printed = capsys.readouterr().out
    assert "overdamped-implicit-coulomb prism-walker: 2 of 2 points already done; running 0" in printed
    assert "inertial-implicit-coulomb prism-walker: 0 of 2 points already done; running 2" in printed
    result = json.loads((tmp_path / "walker_regimes.json").read_text())
    for regime in ("inertial-implicit-coulomb", "overdamped-implicit-coulomb"):
        with open(tmp_path / f"{regime}_prism-walker.csv") as f:
            rows = list(csv.DictReader(f))
        assert sorted(r["sensitive"] for r in rows) == ["false", "true"] and all(r["status"] == "done" for r in rows)
        cell = result["regimes"][regime]["scenes"]["prism-walker"]
        for key, sensitive in (("sensitive", "true"), ("insensitive", "false")):  # too short for a period: n = 0
            assert cell[key]["n"] == sum(1 for r in rows if r["sensitive"] == sensitive and r.get("speed_R_per_T"))
