"""`wavewarp bench sweep_scaling --quick` on CPU workers: a row per worker count, the efficiency
against the first, and the same table from every worker count (a CPU run is deterministic)."""

import json

import pytest

from wavewarp.cli import main as cli


@pytest.mark.slow
def test_bench_sweep_scaling_quick_writes_a_row_per_worker_count(tmp_path):
    assert cli(["bench", "sweep_scaling", "--quick", "--device", "cpu", "--workers", "1,2", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "sweep_scaling_cpu.json").read_text())
    rows = result["rows"]
    assert [r["workers"] for r in rows] == [1, 2] and all(r["points"] == 4 for r in rows)
    assert all(r["differing_values"] == 0 for r in rows)
    for row in rows:
        assert row["efficiency"] == pytest.approx(rows[0]["wall_s"] / (row["wall_s"] * row["workers"]), rel=1e-12)
    assert (tmp_path / "sweep_scaling_cpu.png").stat().st_size > 0
