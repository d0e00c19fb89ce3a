"""`wavewarp bench soak` (issue 57): its CPU smoke run writes the samples and the chart; the invariant holds to
float32 round-off and the memory is sampled (the 10⁵-step soak on a GPU is BENCHMARKS.md's)."""

import json

import pytest

from wavewarp.cli import main as cli


def test_a_short_soak_writes_its_samples_and_chart(tmp_path):
    assert cli(["bench", "soak", "--device", "cpu", "--quick", "--steps", "40", "--every", "10", "--out",
                str(tmp_path)]) == 0
    result = json.loads((tmp_path / "soak_cpu_quick.json").read_text())
    assert (tmp_path / "soak_cpu_quick.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    samples = result["samples"]
    steps = [s["step"] for s in samples]
    assert steps[0] == 0 and steps == sorted(steps) and steps[-1] == result["steps"] >= 40 and len(samples) >= 4
    assert all(s["step"] % result["steps_per_frame"] == 0 for s in samples)  # whole frames
    # conservative transport: C = C(0) + produced to round-off (float32 sums over 162 vertices)
    assert result["summary"]["invariant_error_max"] < 1e-5
    assert all(s["host_rss_bytes"] > 0 and s["volume"] > 0 for s in samples)
    assert result["machine"]["device"] == "cpu" and result["parameters"]["level"] == 2


def test_a_resumed_soak_continues_the_same_run_and_refuses_another(tmp_path, capsys):
    """A soak cut at 20 steps and resumed to 40 in a new call has the uninterrupted soak's samples (the walker resumes
    bit for bit on the CPU), its second process marked; an existing soak is neither replaced nor continued unasked,
    and one run with other parameters is not continued."""
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    options = ["bench", "soak", "--device", "cpu", "--quick", "--every", "10"]
    assert cli([*options, "--steps", "40", "--out", str(whole)]) == 0
    assert cli([*options, "--steps", "20", "--out", str(parts)]) == 0
    with pytest.raises(SystemExit):  # exists: neither --resume nor --overwrite
        cli([*options, "--steps", "40", "--out", str(parts)])
    assert "soak_cpu_quick.json exists: --resume continues it" in capsys.readouterr().err
    assert cli([*options, "--steps", "40", "--out", str(parts), "--resume", "--set", "AC=0.3"]) == 2
    assert "ran other parameters (AC)" in capsys.readouterr().err
    assert cli([*options, "--steps", "40", "--out", str(parts), "--resume"]) == 0
    uninterrupted = json.loads((whole / "soak_cpu_quick.json").read_text())["samples"]
    resumed = json.loads((parts / "soak_cpu_quick.json").read_text())
    cut = max(s["step"] for s in resumed["samples"] if s.get("segment", 0) == 0)  # the first call's last frame
    steps = {s["step"] for s in uninterrupted}
    assert resumed["finished"] and {s["step"] for s in resumed["samples"]} == steps | {cut} and cut >= 20
    at = {s["step"]: s for s in resumed["samples"]}
    for b in uninterrupted:
        a = at[b["step"]]
        assert (a["invariant_error"], a["volume"], a["time"]) == (b["invariant_error"], b["volume"], b["time"])
    assert {s.get("segment", 0) for s in resumed["samples"] if s["step"] > cut} == {1}
    assert cli([*options, "--steps", "40", "--out", str(parts), "--resume"]) == 2
    assert "finished its 42 steps; ask for more --steps" in capsys.readouterr().err
