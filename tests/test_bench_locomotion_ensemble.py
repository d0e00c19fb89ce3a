"""`wavewarp bench locomotion_ensemble` (issue 28): the summary of a sweep table and its chart."""

import csv
import json

import numpy as np
import pytest

from wavewarp.cli import main as cli


def write_table(path, rows):
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_tables_are_summarised_per_ac_and_twin(tmp_path):
    """Mean and sample standard deviation over the seeds with a speed (a stopped point without one is left out)."""
    rng = np.random.default_rng(5)
    rows, speeds = [], {}
    for ac in ("0", "0.2"):
        for sensitive in ("true", "false"):
            values = rng.normal(float(ac), 0.1, 3)
            speeds[(float(ac), sensitive == "true")] = values
            rows += [{"AC": ac, "sensitive": sensitive, "seed": s, "device": "cuda:0", "speed_R_per_T": v}
                     for s, v in enumerate(values)]  # fmt: skip
    rows.append({"AC": "0.2", "sensitive": "true", "seed": 3, "device": "cuda:0", "speed_R_per_T": ""})
    write_table(tmp_path / "sphere.csv", rows)
    assert cli(["bench", "locomotion_ensemble", "--scenes", "sphere-walker", "--tables", str(tmp_path / "sphere.csv"),
                "--device-name", "test GPU", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "locomotion_ensemble_cuda0.json").read_text())
    assert result["device_name"] == "test GPU" and (tmp_path / "locomotion_ensemble_cuda0.png").stat().st_size > 0
    cells = result["scenes"]["sphere-walker"]
    assert len(cells) == 4
    for cell in cells:
        values = speeds[(cell["AC"], cell["sensitive"])]
        assert cell["n"] == 3
        assert cell["mean"] == pytest.approx(values.mean(), rel=1e-12)
        assert cell["std"] == pytest.approx(np.sqrt(np.sum((values - values.mean()) ** 2) / 2), rel=1e-12)
