"""`wavewarp bench numbering --quick` (issue 7, docs/theory/geometry.md#numbering-for-memory-locality): one row per level and
numbering, the same forces in every numbering, the ratios against the old numbering."""

import json

import numpy as np
import pytest

from wavewarp.benchmarks import numbering
from wavewarp.cli import main as cli


@pytest.mark.slow  # a benchmark's smoke run
def test_bench_numbering_quick_writes_a_row_per_level_and_variant(tmp_path):
    assert cli(["bench", "numbering", "--quick", "--device", "cpu", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "numbering_cpu.json").read_text())
    assert result["benchmark"] == "numbering" and result["device"] == "cpu" and result["quick"]
    assert result["dtype"] == "float32" and result["variants"][0] == "old"
    rows = {(r["level"], r["variant"]): r for r in result["rows"]}
    assert len(rows) == len(result["rows"])
    assert set(rows) == {(level, variant) for level in (3, 4) for variant in numbering.VARIANTS}
    for (level, variant), row in rows.items():
        old = rows[level, "old"]
        assert row["triangles"] == 20 * 4**level and row["vertices"] == 10 * 4**level + 2
        for kernel in ("forces", "forces_energy"):
            assert row[f"{kernel}_ms"] > 0
            assert row[f"{kernel}_triangles_per_s"] * row[f"{kernel}_ms"] * 1e-3 == pytest.approx(row["triangles"])
        assert row["speedup_vs_old"] == pytest.approx(old["forces_ms"] / row["forces_ms"], rel=1e-12)
        assert row["speedup_vs_old_with_energy"] == pytest.approx(old["forces_energy_ms"] / row["forces_energy_ms"],
                                                                  rel=1e-12)  # fmt: skip
        assert row["force_deviation"] < 1e-5, (level, variant, row["force_deviation"])  # float32 round-off
    for level in (3, 4):
        assert rows[level, "old"]["speedup_vs_old"] == 1.0 and rows[level, "old"]["speedup_vs_old_with_energy"] == 1.0
        assert rows[level, "old"]["force_deviation"] == 0.0
        # the locality the renumbering is for: patches span fewer indices than in Loop's numbering
        assert rows[level, "new"]["span"] < 0.5 * rows[level, "old"]["span"] < rows[level, "shuffled"]["span"]


def test_numberings_are_permutations_of_the_old_mesh():
    """The force difference compares vertex i of a variant with vertex order[i] of old."""
    meshes = numbering.numberings(2, numbering.VARIANTS)
    old = meshes["old"][0]
    for name, (mesh, order) in meshes.items():
        assert np.array_equal(np.sort(order), np.arange(old.n_vertices)), name
        assert np.array_equal(mesh.vertices, old.vertices[order]), name
        corners = {tuple(sorted(t)) for t in order[mesh.triangles].tolist()}
        assert corners == {tuple(sorted(t)) for t in old.triangles.tolist()}, name
