"""`wavewarp bench walker_regimes --tables`: the twins' statistics and the paper's three claims from sweep
tables, against NumPy on tables made up here (one regime meets every claim, one meets none)."""

import csv
import json
import math

import numpy as np
import pytest

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


def test_walker_regimes_needs_tables_and_names_their_device(tmp_path):
    with pytest.raises(SystemExit):
        cli(["bench", "walker_regimes", "--tables", str(tmp_path)])
    with pytest.raises(SystemExit):
        cli(["bench", "walker_regimes", "--tables", str(tmp_path), "--device-name", "x"])


@pytest.mark.slow
def test_walker_regimes_runs_its_sweeps_and_keeps_their_tables(tmp_path):
    """Two regimes' sweeps side by side on one local cluster: each keeps its own table, and the summary
    counts each table's seeds."""
    assert cli(["bench", "walker_regimes", "--quick", "--device", "cpu", "--seeds", "1", "--regimes",
                "overdamped-implicit-coulomb", "inertial-implicit-coulomb", "--scenes", "prism-walker", "--periods",
                "0.05", "--set", "settle=1", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "walker_regimes.json").read_text())
    for regime in ("inertial-implicit-coulomb", "overdamped-implicit-coulomb"):
        with open(tmp_path / f"{regime}_prism-walker.csv") as f:
            rows = list(csv.DictReader(f))
        assert sorted(r["sensitive"] for r in rows) == ["false", "true"] and all(r["status"] == "done" for r in rows)
        cell = result["regimes"][regime]["scenes"]["prism-walker"]
        for key, sensitive in (("sensitive", "true"), ("insensitive", "false")):  # too short for a period: n = 0
            assert cell[key]["n"] == sum(1 for r in rows if r["sensitive"] == sensitive and r.get("speed_R_per_T"))
