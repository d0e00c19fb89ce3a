"""`wavewarp bench accuracy` (issue 7): the quick sweep through the CLI, its JSON and charts, and
properties whose answers are known in advance: convergence with the level, float32 within stated
bounds of float64, the Pareto fronts and the recommendations re-derived by brute force, the exact
answers' own equations (docs/theory/scenes.md)."""

import json
import math

import numpy as np
import pytest

from wavewarp.benchmarks.accuracy_cases import FAMILIES, closed_form_stretch, front_reference, telegraph_modes
from wavewarp.cli import main as cli
from wavewarp.parameters import scene_descriptions

CONFIGURATIONS = {"spectrum": {"sphere"}, "telegraph": {"modes", "pulse", "wide pulse"}, "radius": set(FAMILIES),
                  "arrival": {"sphere", "cube"}, "front": {"sphere"}}  # fmt: skip
SETTING = ("level", "divisions", "rule", "discretization", "mass_corrections", "dt_fraction", "tol_factor")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    assert cli(["bench", "accuracy", "--quick", "--device", "cpu", "--out", str(out)]) == 0
    with open(out / "accuracy_cpu.json") as f:
        return out, json.load(f)


def usable(point):
    return point.get("converged", True) and math.isfinite(point["error"])


def points_of(result, case):
    return [(name, block["points"]) for name, block in result["cases"][case]["configurations"].items()]


def pairs_by_dtype(points):
    """float32 and float64 points with the same setting otherwise."""
    by = {}
    for p in points:
        by.setdefault(tuple(p.get(k) for k in SETTING), {})[p["dtype"]] = p
    return [(d["float32"], d["float64"]) for d in by.values() if len(d) == 2]


@pytest.mark.slow  # runs the quick benchmark
def test_writes_the_json_and_one_chart_per_case(bench):
    out, result = bench
    assert result["benchmark"] == "accuracy" and result["device"] == "cpu" and result["quick"]
    assert {case: set(block["configurations"]) for case, block in result["cases"].items()} == CONFIGURATIONS
    for case in CONFIGURATIONS:
        with open(out / f"accuracy_{case}_cpu.png", "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
        for _, points in points_of(result, case):
            assert points and all(p["seconds"] > 0 and p["error"] >= 0 and isinstance(p["pareto"], bool) for p in points)
            assert {p["dtype"] for p in points} == {"float32", "float64"}


@pytest.mark.slow  # runs the quick benchmark
def test_the_pareto_front_holds_exactly_the_undominated_points(bench):
    _, result = bench
    for case in CONFIGURATIONS:
        for _, points in points_of(result, case):
            candidates = [p for p in points if usable(p)]
            for p in points:
                dominated = any(q["seconds"] <= p["seconds"] and q["error"] <= p["error"]
                                and (q["seconds"] < p["seconds"] or q["error"] < p["error"]) for q in candidates)  # fmt: skip
                assert p["pareto"] == (usable(p) and not dominated), (case, p)


@pytest.mark.slow  # runs the quick benchmark
def test_errors_fall_as_the_level_rises(bench):
    """The sphere spectrum (every operator, rule and dtype) and the uniform-c radius (float64, rule 3,
    every family) converge: level 3 beats level 2."""
    _, result = bench
    (_, spectrum), = points_of(result, "spectrum")
    series = {}
    for p in spectrum:
        series.setdefault((p["discretization"], p["mass_corrections"], p["rule"], p["dtype"]), {})[p["level"]] = p["error"]
    assert len(series) >= 8 and all(errors[3] < errors[2] for errors in series.values()), series
    for family, points in points_of(result, "radius"):
        errors = {p["level"]: p["error"] for p in points if p["dtype"] == "float64" and p["rule"] == "3"}
        assert errors[3] < errors[2], (family, errors)


@pytest.mark.slow  # runs the quick benchmark
def test_float32_errors_stay_within_stated_bounds_of_float64(bench):
    """float32 round-off is far below the discretisation errors: the float32-built operator has the
    same spectrum to 1e-3 of its error, the waves' errors agree to 1e-3 (of the scale, of γ, of the
    FHN front's v_ref), and the float32 radius lies within 1e-4 R of the float64 one (ten times the
    float32 relax tolerance, a residual strain of 1e-5)."""
    _, result = bench
    for case in ("spectrum", "telegraph", "arrival", "radius", "front"):
        for name, points in points_of(result, case):
            pairs = pairs_by_dtype(points)
            assert pairs, (case, name)
            for single, double in pairs:
                if case == "spectrum":
                    assert single["error"] == pytest.approx(double["error"], rel=1e-3)
                elif case == "radius":
                    assert abs(single["error"] - double["error"]) * abs(1 - double["stretch"]) <= 1e-4
                else:
                    assert abs(single["error"] - double["error"]) <= 1e-3, (case, name, single, double)


def test_the_1d_front_reference_is_the_bistable_speed_without_w():
    """docs/theory/scenes.md: with w ≡ 0 the converged 1-D lattice front runs at the Nagumo front's
    √(2γ²)(½ − ν) (measured 2e-5); the reference checks its own second-order convergence in h."""
    bare = front_reference(0.0)
    assert bare["speed"] == pytest.approx(bare["bistable"], rel=1e-3)
    assert 3.5 < bare["ratio"] < 4.5 and abs(bare["richardson"]) < 5e-3 * bare["speed"]


@pytest.mark.slow  # runs the quick benchmark
def test_the_front_case_reports_stalls_and_a_travelling_front(bench):
    """Quick sweep (levels 3 and 5, lumped): every point is measured against the bench's 1-D
    reference; a stalled front is speed 0 and error 1 (no crash); level 5, where the lattice no
    longer pins the front (docs/theory/dynamics.md), travels: 0 < error < 1."""
    _, result = bench
    block = result["cases"]["front"]
    assert block["reference"]["speed"] == pytest.approx(front_reference()["speed"], rel=1e-12)
    (_, points), = points_of(result, "front")
    for p in points:
        assert p["reference"] == block["reference"]["speed"]
        assert p["stalled"] == (p["speed"] == 0.0 and p["error"] == 1.0), p
    fine = [p for p in points if p["level"] == 5]
    assert fine and all(not p["stalled"] and 0 < p["error"] < 1 for p in fine)


def test_the_closed_form_radius_solves_the_cubic_without_volume_term():
    """Without μV, E'(λ) = 0 is λ³ − (s − ε)λ − εk = 0, ε = h²/6, s = e^{−AC}: k = 1 − AI (Koiter),
    k = e^{−AC/2} + (AC/2 − AI) (bilayer: the same energy with its preferred curvature)."""
    for AC, AI, h, model in [(0.2, 0.0, 0.1, "koiter"), (0.3, 0.5, 0.05, "koiter"), (0.1, 0.4, 0.084, "bilayer")]:
        lam = closed_form_stretch(AC, AI, h, 0.0, model)
        s, eps = math.exp(-AC), h**2 / 6
        k = 1 - AI if model == "koiter" else math.exp(-AC / 2) + AC / 2 - AI
        assert lam**3 - (s - eps) * lam - eps * k == pytest.approx(0.0, abs=1e-10)
    assert closed_form_stretch(0.5, 0.0, 0.05, 1e6, "koiter") == pytest.approx(1.0, abs=1e-5)  # a stiff volume holds R


def test_the_exact_telegraph_modes_solve_their_equations():
    """c_l'' + α c_l' + γ² l(l+1)/R² c_l = 0 (central differences) with c_l(0) = a_l, c_l'(0) = b_l."""
    a, b = np.array([0.3, 1.0, -0.5, 0.2]), np.array([0.2, 0.5, 0.1, -0.7])
    gamma, alpha, radius, t, h = 1.3, 0.2, 2.0, 1.7, 1e-4

    def c(time):
        return telegraph_modes(a, b, gamma, alpha, radius, time)

    l = np.arange(len(a))
    second = (c(t + h) - 2 * c(t) + c(t - h)) / h**2
    first = (c(t + h) - c(t - h)) / (2 * h)
    np.testing.assert_allclose(second + alpha * first + gamma**2 * l * (l + 1) / radius**2 * c(t), 0.0, atol=1e-6)
    np.testing.assert_allclose(c(0.0), a, atol=1e-14)
    np.testing.assert_allclose((c(h) - c(-h)) / (2 * h), b, atol=1e-7)


@pytest.mark.slow  # runs the quick benchmark
def test_recommendations_are_the_cheapest_selectable_points_below_tolerance(bench):
    """Re-derived from the points: every scene is covered; a recommended setting meets its tolerance,
    is float32 whenever a float32 point the scene can select meets it, and no such point is cheaper."""
    _, result = bench
    recommendations = result["recommendations"]
    assert {r["scene"] for r in recommendations} == set(scene_descriptions())
    for r in recommendations:
        assert r["why"] and r["tolerance"] > 0 and {"setting", "error", "current"} <= set(r)
        points = result["cases"][r["case"]]["configurations"][r["configuration"]]["points"]
        selectable = [p for p in points if usable(p) and all(p.get(k, v) == v for k, v in r["fixed"].items())]
        meeting = [p for p in selectable if p["error"] <= r["tolerance"]]
        if not meeting:
            assert r["setting"] is None
            continue
        assert r["error"] <= r["tolerance"]
        single = [p for p in meeting if p["dtype"] == "float32"]
        assert r["setting"]["dtype"] == ("float32" if single else "float64")
        assert r["seconds"] == min(p["seconds"] for p in single or meeting)
        if r["current"]["error"] is not None:
            assert r["current"]["meets"] == (r["current"]["error"] <= r["tolerance"])
