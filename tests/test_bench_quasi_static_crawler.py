"""`wavewarp bench quasi_static_crawler`: the walkers in the quasi-static limit, a quick run of both twins."""

import json

import numpy as np
import pytest

from wavewarp.cli import main as cli


@pytest.mark.slow
def test_a_quick_crawl_relaxes_once_a_chemistry_step_and_stays_on_the_waves_axis(tmp_path):
    assert cli(["bench", "quasi_static_crawler", "--quick", "--device", "cpu", "--periods", "0.02", "--smoothing", "1e-4",
                "--tol", "1e-7", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "quasi_static_crawler_sphere-walker_cpu.json").read_text())
    assert (tmp_path / "quasi_static_crawler_sphere-walker_cpu.png").stat().st_size > 0
    assert [twin["sensitive"] for twin in result["twins"]] == [True, False]
    for twin in result["twins"]:
        assert twin["relaxations"] == twin["chemistry_steps"] + 1  # the put-down, then one a step
        assert twin["unconverged_relaxations"] == 0
        assert twin["largest_step_move_R"] > 0 and (twin["snaps"] > 0) == (twin["largest_step_move_R"] > 0.05)
        forward, lateral = twin["displacement"][0], twin["displacement"][1]
        assert np.isfinite(forward) and abs(lateral) <= 1e-3 * abs(forward)  # mirror symmetry in y (to the tolerance)
