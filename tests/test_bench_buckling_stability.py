"""`wavewarp bench buckling_stability` (issue 5): the softest modes along the perfect buckling path,
with their azimuthal orders, and finite bumps that decay on a stable path."""

import json
import math

import pytest

from wavewarp.cli import main


def test_buckling_stability_runs_and_writes_its_rows(tmp_path, capsys):
    assert main(["bench", "buckling_stability", "--device", "cpu", "--level", "2", "--t-end", "2", "--frames", "2",
                 "--modes", "3", "--bump-frames", "0", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "buckling_stability.json").read_text())
    rows = result["rows"]
    assert [round(row[0], 6) for row in rows] == [0.0, 1.0, 2.0]
    for t, front, values, orders, polar, asymmetry, _ in rows:
        assert len(values) == len(orders) == len(polar) == 3
        assert values == sorted(values) and all(0 <= m <= 16 for m in orders)
        assert front == pytest.approx(math.degrees(t / 10))  # γ t / R
    assert min(rows[0][2]) > 0  # a sphere dimpled by the first pulse is a stable minimum
    bumps = result["bumps"]
    assert [row[1] for row in bumps] == [3, 4, 5, 6, 8]
    # on that stable state every 2 h bump relaxes back to it: same energy, within a tenth of h
    assert all(abs(row[2]) < 1e-8 and row[3] < 0.1 for row in bumps)
    assert (tmp_path / "buckling_stability.png").stat().st_size > 0
    assert "the path stays stable" in capsys.readouterr().out


@pytest.mark.slow  # a benchmark's smoke run
def test_buckling_stability_analyses_a_stored_trajectory_and_refuses_one_with_self_contact(tmp_path, capsys):
    """--h5: the frames of `wavewarp run` (here a coarse quick run), analysed on its stored rest mesh;
    frames relaxed with self-contact are refused (the Hessian has no contact term)."""
    h5 = str(tmp_path / "path.h5")
    assert main(["run", "buckling", "--quick", "--device", "cpu", "--set", "self_contact=false", "--set", "level=2",
                 "--set", "frames=2", "--set", "t_end=2", "--h5", h5, "--out", str(tmp_path / "path.usda")]) == 0  # fmt: skip
    assert main(["bench", "buckling_stability", "--device", "cpu", "--h5", h5, "--modes", "2", "--bump-frames",
                 "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "buckling_stability.json").read_text())
    assert result["source"] == h5 and result["parameters"]["level"] == 2
    assert [round(row[0], 6) for row in result["rows"]] == [0.0, 1.0, 2.0] and result["bumps"] == []
    assert all(min(row[2]) > 0 for row in result["rows"])  # the seeded sphere under the first pulse is stable
    contact = str(tmp_path / "contact.h5")
    assert main(["run", "buckling", "--quick", "--device", "cpu", "--set", "frames=1", "--set", "t_end=0.5",
                 "--h5", contact, "--out", str(tmp_path / "contact.usda")]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["bench", "buckling_stability", "--device", "cpu", "--h5", contact, "--out", str(tmp_path)]) == 2
    assert "self_contact=false" in capsys.readouterr().err
