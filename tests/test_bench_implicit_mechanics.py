"""`wavewarp bench implicit_mechanics` (issue 58): its CPU smoke run, explicit and implicit side by side; the
ratios it prints are those of the times and displacements it stores, and each run ran the mechanics it names."""

import json

import pytest

from wavewarp.cli import main as cli


def test_the_side_by_side_run_stores_each_mechanics_and_its_ratios(tmp_path):
    assert cli(["bench", "implicit_mechanics", "--device", "cpu", "--quick", "--dtypes", "float64", "--substeps", "1",
                "2", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "implicit_mechanics_cpu_quick.json").read_text())
    explicit, *implicit = result["runs"]
    assert result["level"] == 2 and explicit["mechanics"] == "overdamped" and explicit["cg_iterations"] is None
    # the explicit step sits under the bending bound: several substeps a chemistry step; the implicit takes N
    assert explicit["substeps"] > 2 and [r["substeps"] for r in implicit] == [1, 2]
    chemistry_dt = explicit["mechanics_dt"] * explicit["substeps"]
    for r, n in zip(implicit, (1, 2)):
        assert r["mechanics"] == "overdamped-implicit" and r["implicit_substeps"] == n and r["cg_iterations"] >= 1
        assert r["mechanics_dt"] == pytest.approx(chemistry_dt / n, rel=1e-12)
    for r in result["runs"]:
        assert r["time"] == pytest.approx(explicit["time"]) and r["walk_s"] > 0
        assert r["speed_up"] == pytest.approx(explicit["walk_s"] / r["walk_s"], rel=1e-12)
        assert r["displacement_difference"] == pytest.approx(r["displacement_R"] / explicit["displacement_R"] - 1,
                                                             rel=1e-12, abs=1e-15)
