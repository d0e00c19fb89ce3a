"""`wavewarp bench speed --quick` (issue 7): writes its table and chart; the figures are consistent."""

import json

import pytest

from wavewarp.cli import main as cli


@pytest.mark.slow
def test_bench_speed_quick_writes_json_and_chart(tmp_path):
    assert cli(["bench", "speed", "--quick", "--device", "cpu", "--force-blocks", "128", "--regular-patches", "general",
                "held", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "speed_cpu.json").read_text())
    assert (tmp_path / "speed_cpu.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert result["peaks"]["bandwidth_bytes_per_s"] > 0 and result["peaks"]["flops_per_s"] > 0
    kernels = {(r["kernel"], r["dtype"], r["level"]) for r in result["kernels"]}
    for level in (2, 3):
        for dtype in ("float32", "float64"):
            assert ("koiter forces, atomic scatter", dtype, level) in kernels
            assert ("koiter forces, deterministic gather", dtype, level) in kernels
            assert ("koiter forces, atomic, 128 threads a block", dtype, level) in kernels
            for mode in ("general", "held"):
                assert (f"koiter forces, atomic, regular patches {mode}, 128 threads a block", dtype, level) in kernels
        assert ("numpy shell forces (koiter + volume)", "float64", level) in kernels
        for ground in ("explicit ground", "implicit ground (8 sweeps)"):
            assert (f"mechanics step, {ground}", "float32", level) in kernels
    for row in result["kernels"]:
        assert row["triangles"] == 20 * 4 ** row["level"]
        if row["kernel"].startswith("koiter forces, atomic, "):  # the same sums, or the same in another order
            same_kernel = "block" in row["kernel"] and "regular" not in row["kernel"]
            assert row["max_relative_difference"] <= (0.0 if same_kernel else 1e-5 if row["dtype"] == "float32" else 1e-12)
        assert row["triangles_per_second"] * row["seconds"] == pytest.approx(row["triangles"])
        if "floor_seconds" in row:  # the floor is the larger of the two bounds
            assert row["floor_seconds"] == max(row["bytes"] / result["peaks"]["bandwidth_bytes_per_s"],
                                               row["flops"] / result["peaks"]["flops_per_s"])  # fmt: skip
    steps = result["steps"]
    assert {(r["step"], r["substeps"] == 1) for r in steps} == {
        (f"coupled walker step, {kind}", one) for kind in ("insensitive", "sensitive") for one in (True, False)
    }
    for row in steps:  # the clocks agree: dt_c = substeps × the mechanics step
        assert row["chemistry_dt"] == pytest.approx(row["substeps"] * row["mechanics_dt"], rel=1e-12)
