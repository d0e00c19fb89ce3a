"""`wavewarp bench sweep_scaling --quick` on CPU workers: a row per worker count, the efficiency
against the first, the same table from every worker count (a CPU run is deterministic), also on a
kept cluster. (How much the kept cluster saves is a timing: BENCHMARKS.md, not a test.)"""

import json

import pytest

from wavewarp.cli import main as cli


@pytest.mark.slow
def test_bench_sweep_scaling_quick_writes_a_row_per_worker_count(tmp_path):
    assert cli(["bench", "sweep_scaling", "--quick", "--device", "cpu", "--workers", "1,2", "--kept-cluster", "--out",
                str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "sweep_scaling_cpu.json").read_text())
    rows = result["rows"]
    assert [r["workers"] for r in rows] == [1, 2] and all(r["points"] == 4 for r in rows)
    assert all(r["differing_values"] == 0 and r["kept_cluster_differing_values"] == 0 for r in rows)
    for row in rows:
        assert row["efficiency"] == pytest.approx(rows[0]["wall_s"] / (row["wall_s"] * row["workers"]), rel=1e-12)
        assert row["kept_cluster_wall_s"] > 0
    assert (tmp_path / "sweep_scaling_cpu.png").stat().st_size > 0


@pytest.mark.slow
def test_bench_sweep_scaling_without_warm_up_has_no_baseline(tmp_path):
    assert cli(["bench", "sweep_scaling", "--quick", "--device", "cpu", "--workers", "1", "--no-warm-up", "--out",
                str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "sweep_scaling_cpu.json").read_text())
    assert "warm_up_s" not in result and "warm_up_differing_values" not in result
    assert [r["workers"] for r in result["rows"]] == [1] and result["rows"][0]["points"] == 4
