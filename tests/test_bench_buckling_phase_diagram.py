"""wavewarp bench buckling_phase_diagram: the cells of Fig. S1b's diagram from a sweep folder."""

import csv
import json

from wavewarp.benchmarks import buckling_phase_diagram


def fake_sweep(folder, frames: bool):
    """Two points at R = 10: one that buckles into 6 then ovalises (n_mode 2), one that never buckles."""
    (folder / "points").mkdir(parents=True)
    definition = {"scene": "buckling-modes", "grid": {"AI": ["9.5", "13.5"], "thickness": ["0.1"]}, "seeds": 1,
                  "fixed": ["level=4", "radius=10"], "quick": False, "deterministic": False}  # fmt: skip
    (folder / "sweep.json").write_text(json.dumps(definition))
    points = {"a": ("13.5", [0, 6, 4, 2, 2, 2], "done"), "b": ("9.5", [0, 0, 0], "stopped")}
    with open(folder / "table.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, ["point", "AI", "thickness", "status", "n_mode", "amplitude_max_h"])
        writer.writeheader()
        for name, (ai, numbers, status) in points.items():
            writer.writerow({"point": name, "AI": ai, "thickness": "0.1", "status": status,
                             "n_mode": 2 if any(numbers) else 0, "amplitude_max_h": 1.5})  # fmt: skip
            if frames:
                result = {"point": name, "measurements": {"symmetry_numbers": numbers}}
                (folder / "points" / f"{name}.json").write_text(json.dumps(result))


def test_the_diagram_reads_the_onset_mode_from_the_frames_and_falls_back_to_the_table(tmp_path):
    fake_sweep(tmp_path / "frames", frames=True)
    fake_sweep(tmp_path / "table", frames=False)
    assert buckling_phase_diagram.main(["--sweeps", str(tmp_path / "frames"), str(tmp_path / "table"),
                                        "--out", str(tmp_path / "out")]) == 0  # fmt: skip
    result = json.loads((tmp_path / "out" / "buckling_phase_diagram.json").read_text())
    by_panel = [{c["AI"]: c for c in panel["cells"]} for panel in result["panels"]]
    assert (by_panel[0][13.5]["n"], by_panel[0][13.5]["source"]) == (6, "n_onset")
    assert (by_panel[1][13.5]["n"], by_panel[1][13.5]["source"]) == (2, "n_mode")
    assert by_panel[0][9.5]["n"] == 0 and by_panel[0][9.5]["status"] == "stopped"
    assert by_panel[0][13.5]["h_over_R"] == 0.01
    assert (tmp_path / "out" / "buckling_phase_diagram.png").stat().st_size > 0
