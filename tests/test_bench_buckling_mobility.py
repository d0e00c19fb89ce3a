"""`wavewarp bench buckling_mobility` (issue 5 probe): the drag follows from the requested substeps,
and the mobility-stepped buckling shell records its rows and JSON."""

import json

import pytest

from wavewarp.cli import main


def test_buckling_mobility_runs_and_writes_its_rows(tmp_path, capsys):
    assert main(["bench", "buckling_mobility", "--device", "cpu", "--level", "2", "--dtype", "float32",
                 "--substeps", "5", "--t-end", "2", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "buckling_mobility.json").read_text())
    run = result["runs"][0]
    assert run["substeps"] == 5 and run["status"] == "done"
    assert run["drag"] == pytest.approx(run["omega_max"] ** 2 * run["dt_c"] / (2 * 0.9 * 5))  # 0.9 of the bound
    times = [row[0] for row in run["rows"]]
    assert times[-1] >= 2.0 and all(b > a for a, b in zip(times, times[1:]))
    assert all(0 < row[3] <= 2.2 for row in run["rows"])  # pole-to-pole height in R: a sphere is 2
    assert "substeps" in capsys.readouterr().out
