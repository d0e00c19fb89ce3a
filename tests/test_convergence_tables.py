"""The convergence tables' arithmetic (benchmarks/convergence_tables.py) on sequences whose limits and orders are
known in advance: q(h) = q* + C h^p, and a mesh-and-step error q* + a 4^-L + b dt."""

import pytest
from wavewarp.benchmarks.convergence_tables import (
    converged_value,
    default_errors,
    profile_convergence,
    richardson,
    within,
)


@pytest.mark.parametrize("order", [1.0, 2.0, 3.5])
def test_richardson_recovers_the_order_and_the_limit(order):
    limit, constant = 1.25, -0.3
    values = [limit + constant * (0.4 / 2**k) ** order for k in range(4)]
    result = richardson(values)
    assert result["asymptotic"] and result["order"] == pytest.approx(order, rel=1e-9)
    assert result["estimate"] == pytest.approx(limit, abs=1e-12)
    assert result["error"] == pytest.approx(abs(values[-1] - limit), rel=1e-9)


def test_a_sequence_that_turns_is_not_asymptotic_and_keeps_its_last_difference():
    result = richardson([1.0, 1.1, 1.05, 1.08])
    assert not result["asymptotic"] and result["estimate"] == 1.08 and result["error"] == pytest.approx(0.03)
    assert richardson([None, 2.0, 2.0, 2.0]) == {**richardson([2.0, 2.0, 2.0])}
    assert richardson([3.0])["order"] is None


def test_profile_differences_halve_at_first_order_and_skip_empty_bins():
    profiles = [[1.0 + 0.1 / 2**k, None, 0.9 - 0.2 / 2**k] for k in range(3)]
    result = profile_convergence(profiles)
    assert result["differences"] == pytest.approx([0.1, 0.05])
    assert result["order"] == pytest.approx(1.0) and result["error"] == pytest.approx(0.05)


def test_the_converged_value_combines_the_mesh_and_the_step_and_judges_the_default():
    """q = q* + a 4^-L + b dt (second order in the edge, first in dt): levels 4–6 at k = 2 give the mesh's limit
    at that step, the finest level's steps k = 2, 3, 4 remove the step's error; the default (L4, k0) is judged by
    its distance from q*."""
    limit, a, b, dt0 = 0.5, 20.0, 0.04, 0.25

    def q(level, k):
        return limit + a * 4.0**-level + b * dt0 / 2**k

    members = {(level, k): {"wave_speed": q(level, k)} for level in (4, 5, 6) for k in range(level - 4, 5)}
    best = converged_value(members, "wave_speed")
    assert best["levels"] == [4, 5, 6] and best["k_ref"] == 2
    assert best["estimate"] == pytest.approx(limit, abs=1e-12)
    # the error stated is the finest values' own, in the mesh and in the step: an upper bound of the estimate's
    assert best["error"] == pytest.approx(a * 4.0**-6 + b * dt0 / 2**4, rel=1e-9)
    assert best["mesh_order"] == pytest.approx(2.0) and best["time_order"] == pytest.approx(1.0)
    checked = default_errors(members, 4)["wave_speed"]
    distance = abs(q(4, 0) - limit)
    assert checked["default"] == q(4, 0) and checked["meets"] == (distance <= 0.02 * limit)
    assert converged_value({(4, 0): {"wave_speed": 1.0}, (4, 1): {"wave_speed": 1.0}}, "wave_speed") is None


def test_within_counts_the_estimates_error():
    assert within(1.0, 1.01, 0.005, 0.02, 1.0) and not within(1.0, 1.01, 0.015, 0.02, 1.0)
    assert within(None, 1.0, 0.0, 0.1, 1.0) is None


@pytest.mark.slow
def test_bench_convergence_runs_points_and_writes_its_tables(tmp_path):
    """A smoke run of `wavewarp bench convergence`: two quick starfish points (level 2, dt and dt/2), their JSON,
    the tables and the defaults' check (one level: nothing to judge)."""
    import json

    from wavewarp.cli import main

    out = tmp_path / "conv"
    argv = [
        "bench",
        "convergence",
        "--scenes",
        "starfish",
        "--readings",
        "conservative/overdamped",
        "--levels",
        "2",
        "--halvings",
        "1",
        "--set",
        "t_end=2",
        "--set",
        "frames=2",
        "--device",
        "cpu",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    points = sorted(p.name for p in (out / "points").iterdir())
    assert points == [
        "starfish_conservative_overdamped_L2_k0_t_end2_frames2.json",
        "starfish_conservative_overdamped_L2_k1_t_end2_frames2.json",
    ]
    result = json.loads((out / "convergence.json").read_text())
    sequence = result["tables"]["starfish conservative/overdamped t_end=2 frames=2"]["time_step"]["L2"]
    assert sequence["members"] == ["k0", "k1"] and len(sequence["contraction_depth"]["values"]) == 2
    assert (out / "convergence.md").exists() and (out / "convergence.png").exists()
