"""`wavewarp bench locomotion_ensemble` (issue 28): the summary of a sweep table and its chart."""

import csv
import json
import os

import numpy as np
import pytest

from wavewarp.benchmarks import locomotion_ensemble
from wavewarp.cli import main as cli


def write_table(path, rows):
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def ensemble_rows(rng, seeds):
    """Made-up table rows over AC × twin for `seeds`, and each cell's speeds."""
    rows, speeds = [], {}
    for ac in ("0", "0.2"):
        for sensitive in ("true", "false"):
            values = rng.normal(float(ac), 0.1, len(seeds))
            speeds[(float(ac), sensitive == "true")] = values
            rows += [{"AC": ac, "sensitive": sensitive, "seed": s, "device": "cuda:0", "speed_R_per_T": v}
                     for s, v in zip(seeds, values)]  # fmt: skip
    return rows, speeds


def check_cells(cells, speeds):
    """Mean and sample standard deviation of each cell against numpy's."""
    assert len(cells) == len(speeds)
    for cell in cells:
        values = speeds[(cell["AC"], cell["sensitive"])]
        assert cell["n"] == len(values)
        assert cell["mean"] == pytest.approx(values.mean(), rel=1e-12)
        assert cell["std"] == pytest.approx(np.std(values, ddof=1), rel=1e-12)


def test_tables_are_summarised_per_ac_and_twin(tmp_path):
    """Mean and sample standard deviation over the seeds with a speed (a stopped point without one is left out)."""
    rows, speeds = ensemble_rows(np.random.default_rng(5), seeds=range(3))
    rows.append({"AC": "0.2", "sensitive": "true", "seed": 3, "device": "cuda:0", "speed_R_per_T": ""})
    write_table(tmp_path / "sphere-walker.csv", rows)
    assert cli(["bench", "locomotion_ensemble", "--scenes", "sphere-walker", "--tables", str(tmp_path / "sphere-walker.csv"),
                "--device-name", "test GPU", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "locomotion_ensemble_cuda0.json").read_text())
    assert result["device_name"] == "test GPU" and (tmp_path / "locomotion_ensemble_cuda0.png").stat().st_size > 0
    assert result["seeds"] == 3
    check_cells(result["scenes"]["sphere-walker"], speeds)


def test_a_scenes_tables_are_joined_and_told_apart_by_name(tmp_path):
    """Seeds 0-1 and 2-4 of the sphere in two tables, the prism in a third: the sphere's cells hold all five seeds."""
    rng = np.random.default_rng(7)
    first, first_speeds = ensemble_rows(rng, seeds=range(2))
    later, later_speeds = ensemble_rows(rng, seeds=range(2, 5))
    prism, prism_speeds = ensemble_rows(rng, seeds=range(2))
    paths = [tmp_path / "locomotion_ensemble_sphere-walker_cuda0.csv", tmp_path / "locomotion_ensemble_prism-walker_cuda0.csv",
             tmp_path / "locomotion_ensemble_sphere-walker_cuda0_seeds2-4.csv"]  # fmt: skip
    for path, rows in zip(paths, (first, prism, later)):
        write_table(path, rows)
    assert cli(["bench", "locomotion_ensemble", "--tables", *map(str, paths), "--device-name", "test GPU",
                "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "locomotion_ensemble_cuda0.json").read_text())
    assert result["seeds"] == 5
    check_cells(result["scenes"]["sphere-walker"], {k: np.concatenate([first_speeds[k], later_speeds[k]]) for k in first_speeds})
    check_cells(result["scenes"]["prism-walker"], prism_speeds)


def test_a_table_of_no_scene_is_named(tmp_path, capsys):
    rows, _ = ensemble_rows(np.random.default_rng(1), seeds=range(2))
    write_table(tmp_path / "walker.csv", rows)
    with pytest.raises(SystemExit):
        cli(["bench", "locomotion_ensemble", "--tables", str(tmp_path / "walker.csv"), "--device-name", "x",
             "--out", str(tmp_path)])  # fmt: skip
    assert "must hold exactly one of sphere-walker, prism-walker" in capsys.readouterr().err


def test_the_sweeps_stay_in_the_output_folder_so_a_rerun_resumes(tmp_path, monkeypatch):
    """Each scene's sweep runs in OUT/sweeps/NAME, kept (a killed bench re-run computes only the missing points,
    tests/test_sweep.py), and the later seeds of `--first-seed` in a folder of their own."""
    calls = []

    def fake_sweep(spec, folder, **options):
        calls.append((spec, folder))
        rows, _ = ensemble_rows(np.random.default_rng(len(calls)), seeds=range(spec.first_seed, spec.first_seed + spec.seeds))
        os.makedirs(folder, exist_ok=True)
        write_table(os.path.join(folder, "table.csv"), rows)
        return rows

    monkeypatch.setattr(locomotion_ensemble, "sweep", fake_sweep)
    common = ["bench", "locomotion_ensemble", "--device", "cpu", "--scenes", "sphere-walker", "--ac", "0", "0.2",
              "--seeds", "2", "--out", str(tmp_path)]  # fmt: skip
    assert cli(common) == 0 and cli(common + ["--first-seed", "2", "--h5"]) == 0
    assert [folder for _, folder in calls] == [str(tmp_path / "sweeps" / "locomotion_ensemble_sphere-walker_cpu"),
                                               str(tmp_path / "sweeps" / "locomotion_ensemble_sphere-walker_cpu_seeds2-3")]  # fmt: skip
    assert calls[1][0].first_seed == 2 and calls[1][0].seeds == 2
    assert not calls[0][0].h5 and calls[1][0].h5  # --h5: trajectories kept, a killed batch goes on
    assert (tmp_path / "locomotion_ensemble_sphere-walker_cpu.csv").is_file()
    assert (tmp_path / "locomotion_ensemble_sphere-walker_cpu_seeds2-3.csv").is_file()
