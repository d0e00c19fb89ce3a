"""`wavewarp bench soak` (issue 57): its CPU smoke run writes the samples and the chart; the invariant holds to
float32 round-off and the memory is sampled (the 10⁵-step soak on a GPU is BENCHMARKS.md's)."""

import json

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
