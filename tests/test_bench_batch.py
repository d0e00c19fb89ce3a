"""`wavewarp bench batch --quick` (issue 28): writes its table and chart; the figures are consistent."""

import json

import pytest

from wavewarp.cli import main as cli


@pytest.mark.slow
def test_bench_batch_quick_writes_json_and_chart(tmp_path):
    assert cli(["bench", "batch", "--quick", "--device", "cpu", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "batch_cpu.json").read_text())
    assert (tmp_path / "batch_cpu.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = [r for r in result["rows"] if r["kind"] == "walker"]
    assert [r["worlds"] for r in rows] == [1, 3] and len({r["substeps"] for r in rows}) == 1  # one mechanics step
    relaxations = [r for r in result["rows"] if r["kind"] == "relaxation"]
    assert [r["worlds"] for r in relaxations] == [1, 3]
    for row in relaxations:  # the batch runs until its slowest world converges
        assert row["iterations_max"] >= row["iterations_mean"] > 0
        assert row["speedup_vs_sequential"] == pytest.approx(row["world_relaxations_per_second"]
                                                             / row["sequential_world_relaxations_per_second"])  # fmt: skip
    scenes = [r for r in result["rows"] if r["kind"] == "scene"]
    assert [(r["worlds"], r["level"], r["scene"]) for r in scenes] == [(1, 2, "buckling-modes"), (3, 2, "buckling-modes")]
    for row in scenes:
        assert row["wave_steps"] > 0 and row["speedup_vs_sequential"] == pytest.approx(
            row["world_runs_per_second"] / row["sequential_world_runs_per_second"])  # fmt: skip
    for row in rows:
        assert row["triangles"] == row["worlds"] * row["triangles_per_world"] == row["worlds"] * 80
        assert row["world_steps_per_second"] == pytest.approx(row["worlds"] * row["steps_per_second"])
        assert row["speedup_vs_sequential"] == pytest.approx(row["world_steps_per_second"]
                                                             / row["sequential_world_steps_per_second"])  # fmt: skip
        assert row["shell_forces_seconds"] > 0 and row["shell_forces_times_floor"] > 0
