"""Walker gradients by central differences over one batch (wavewarp/walker_gradients.py): the worlds'
differences against whole single runs, the steps' convergence, the horizon measures and the errors."""

import json
from dataclasses import replace

import numpy as np
import pytest

from wavewarp.batch import displaced
from wavewarp.benchmarks.gradient_horizon import growth_per_period, horizon, running_magnitude
from wavewarp.benchmarks.inverse_design import ascend, log_step, shape_smoother
from wavewarp.cli import main
from wavewarp.driver import simulate
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.gradients import GradientError, control_scale
from wavewarp.parameters import load_scene, resolve
from wavewarp.walker import WalkerRun, place_walker, sphere_walker_recipe
from wavewarp.walker_gradients import (WalkerGradientError, check_walker_differentiable, check_walker_values,
                                       control_points, forward_distance, objective_value, perturbed_worlds,
                                       walker_gradient)  # fmt: skip

# the quick sphere walker for a third of a period, in float64 (the gradient's dtype)
SHORT = ["periods=0.3", "frames=1", "dtype=float64"]
# shape gradients: the level-1 sphere (42 control points) settled briefly, a tenth of a period
COARSE = ["level=1", "periods=0.1", "settle=2", "frames=1"]


def quick_sphere(*overrides):
    module = load_scene("sphere-walker")
    return module, resolve(module.Parameters, module.QUICK, [*SHORT, *overrides])


def test_perturbed_worlds_put_the_unperturbed_world_first_then_plus_and_minus_each_step():
    _, p = quick_sphere()
    worlds = perturbed_worlds(p, ["AC", "AI"], (1e-2, 1e-3))
    assert [(name, sign) for name, _, sign, _ in worlds] == [(None, 0)] + [(n, s) for n in ("AC", "AI") for _ in range(2)
                                                                        for s in (1, -1)]  # fmt: skip
    assert worlds[0][3] == p
    for name, delta, sign, q in worlds[1:]:
        theta = getattr(p, name)
        assert getattr(q, name) == pytest.approx(theta + sign * delta, rel=0, abs=1e-15)
    assert [delta for name, delta, sign, _ in worlds if name == "AC" and sign == 1] == pytest.approx([1e-2 * p.AC, 1e-3 * p.AC])
    assert [delta for name, delta, sign, _ in worlds if name == "AI" and sign == 1] == pytest.approx([1e-2, 1e-3])  # AI = 0


def test_forward_distance_is_the_centre_of_mass_along_the_wave_in_radii():
    t = np.linspace(0.0, 1.0, 5)
    com = np.column_stack([3.0 * t, 7.0 * t, 1.0 - t]) + [1.0, 2.0, 3.0]
    trace = np.column_stack([t, np.zeros(5), com, np.zeros((5, 3))])
    assert forward_distance(trace, [1.0, 0.0, 0.0], 2.0) == pytest.approx(1.5 * t)
    assert forward_distance(trace, [-1.0, 0.0, 0.0], 2.0) == pytest.approx(-1.5 * t)  # a mirrored walker


@pytest.mark.parametrize("wrt, objective, steps, message", [
    (["young", "density"], "distance", (1e-4,), "density"), ([], "distance", (1e-4,), "(nothing)"),
    (["gravity"], "distance", (1e-4,), "friction, sharpness, stiffness, contact_damping, drag"),
    (["AC"], "height", (1e-4,), "objectives are distance"), (["AC"], "distance", (), "one or more"),
    (["AC"], "distance", (0.5,), "between 0 and 0.5")])  # fmt: skip
def test_gradients_that_cannot_be_taken_are_refused_with_the_fix(wrt, objective, steps, message):
    with pytest.raises(WalkerGradientError, match=message.replace("(", r"\(").replace(")", r"\)")):
        check_walker_differentiable(wrt, objective, steps)


def test_the_cli_refuses_a_walker_parameter_it_cannot_differentiate(capsys):
    assert main(["grad", "sphere-walker", "--quick", "--wrt", "density", "--device", "cpu"]) != 0
    assert "AC, AI, thickness, young, mu_v" in capsys.readouterr().err


@pytest.mark.parametrize("setting, wrt, message", [
    ([], ["sharpness"], "sharpness=1e4"), (["friction=0"], ["friction"], "valid range"),
    (["drag=0"], ["drag"], "automatic"), (["contact_damping=0"], ["contact_damping"], "valid range"),
    (["mu_v=0"], ["mu_v"], "valid range")])  # fmt: skip
def test_values_that_leave_no_central_difference_are_refused_with_the_fix(setting, wrt, message):
    _, p = quick_sphere(*setting)
    with pytest.raises(WalkerGradientError, match=message):
        check_walker_values(p, wrt, (1e-4, 1e-5))
    check_walker_values(quick_sphere("sharpness=1e4")[1], ["AC", "AI", "friction", "sharpness", "drag"], (1e-4,))


def test_the_horizons_and_growth_of_made_up_derivatives():
    t = np.linspace(0.0, 6.0, 6001)
    exact = np.exp(t)
    close = exact + 1e-3 * np.exp(2.0 * t)  # 1e-3 e^2t > 0.1 e^t from t = ln 100 on
    assert horizon(t, exact, close, 0.1) == pytest.approx(np.log(100.0), abs=1e-3)
    assert horizon(t, exact, exact, 1e-3) is None
    early = exact + np.where(t < 0.5, 0.3, 0.0)  # 18-30% off while |g| < 1% of its largest: the first rise, no horizon
    assert horizon(t, exact, early, 0.1) is None
    assert running_magnitude(np.array([0.0, -2.0, 1.0])).tolist() == [2.0, 2.0, 2.0]  # floored at the first non-zero
    wobbling = np.exp(0.5 * t) * (2.0 + np.cos(40.0 * t))  # 0.5 e-folds a period under a wobble
    assert growth_per_period(t, wobbling) == pytest.approx(0.5, abs=0.02)
    assert growth_per_period(t, np.where(t <= 3.0, np.exp(0.5 * t), 1e9), until=3.0) == pytest.approx(0.5, abs=1e-9)
    assert growth_per_period(t, exact, until=0.9) is None  # under a period: the first rise, not a growth


@pytest.mark.slow
@pytest.mark.parametrize("name, steps", [("AC", (1e-4, 1e-5)),
                                         # a ground's parameter (batches of one world); Coulomb's stick and slip put
                                         # kinks within ±1e-4 μ (that step is 1.4e-4 off), not within ±1e-5
                                         ("friction", (1e-5, 1e-6))])  # fmt: skip
def test_the_batched_differences_equal_those_of_whole_single_runs_and_converge(name, steps):
    """The ±δ worlds against two separate single-world runs of the scene (each its own model and wave)
    settled with the main batch's mechanics steps, and the derivative's convergence between the steps."""
    module, p = quick_sphere()
    result = walker_gradient(module, p, [name], steps=steps, device="cpu", report=lambda m: None)
    assert result["agreement"][name] < 1e-5  # measured 5.6e-9 (AC), 1.4e-7 (friction)
    theta, delta = getattr(p, name), result["deltas"][name][0]
    ends = []
    for sign in (1, -1):
        q = resolve(module.Parameters, module.QUICK, [*SHORT, f"{name}={theta + sign * delta!r}"])
        mesh, options = sphere_walker_recipe(q, device="cpu", report=lambda m: None)
        run = WalkerRun("single", mesh, q, device="cpu", mechanics_dt=result["settle_dt"], **options)
        assert simulate(run, []).failure is None
        ends.append(forward_distance(run.trace, run.forward, run.radius)[-1])
    single = (ends[0] - ends[1]) / (2 * delta)
    assert abs(single) > 1e-3 * abs(result["objective"]) / theta  # a derivative that matters
    assert result["derivatives"][name][0][-1] == pytest.approx(single, rel=1e-9)


@pytest.mark.slow
def test_the_cli_prints_a_walkers_gradient_as_json(capsys):
    assert main(["grad", "sphere-walker", "--quick", "--wrt", "AI", "--device", "cpu", "--json",
                 *[f"--set={s}" for s in SHORT]]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"objective", "gradient", "agreement", "steps"} and set(out["gradient"]) == {"AI"}
    assert out["agreement"]["AI"] < 1e-3  # Coulomb friction and contact onsets: piecewise smooth in AI


def test_the_design_ascent_reaches_the_maximum_of_a_known_objective():
    """J = -(ln a - 1)² - (ln b + 0.5)², largest at a = e, b = e^-½, from (1, 1) with its exact gradient."""
    def objective_and_gradient(theta):
        a, b = theta["a"], theta["b"]
        value = -((np.log(a) - 1.0) ** 2) - (np.log(b) + 0.5) ** 2
        return value, {"a": -2.0 * (np.log(a) - 1.0) / a, "b": -2.0 * (np.log(b) + 0.5) / b}

    history = ascend(objective_and_gradient, {"a": 1.0, "b": 1.0}, iterations=60, rate=0.3, report=lambda m: None)
    accepted = [row["J"] for row in history if row["accepted"]]
    assert accepted == sorted(accepted) and any(not row["accepted"] for row in history)  # it overshot and backed off
    best = max(history, key=lambda row: row["J"])["theta"]
    assert best["a"] == pytest.approx(np.e, rel=1e-2) and best["b"] == pytest.approx(np.exp(-0.5), rel=1e-2)
    assert log_step({"a": 2.0, "b": 1.0}, {"a": 1.0, "b": -4.0}, 0.5) == pytest.approx({"a": 2.0 * np.exp(0.25), "b": np.exp(-0.5)})
    # a coordinate (any sign) steps additively by rate × L at most: s = (2 × 1, 10 × -0.4) -> Δx = 0.5 × 10 × (-4/4)
    assert log_step({"a": 2.0, "x": -1.0}, {"a": 1.0, "x": -0.4}, 0.5, {"x": 10.0}) == pytest.approx(
        {"a": 2.0 * np.exp(0.25), "x": -6.0})
    # cut after 7 evaluations (an undone step among them) and gone on from its rows (as read back from JSON):
    # the same steps as the uninterrupted ascent
    cut = json.loads(json.dumps(history[:7], default=float))
    assert not all(row["accepted"] for row in cut)
    resumed = ascend(objective_and_gradient, {"a": 1.0, "b": 1.0}, iterations=60, rate=0.3, report=lambda m: None,
                     history=cut)  # fmt: skip
    assert [(row["theta"], row["J"], row["rate"], row["accepted"]) for row in resumed] == [
        (row["theta"], row["J"], row["rate"], row["accepted"]) for row in history]


def test_the_rest_shapes_design_direction_is_the_steepest_ascent_in_the_smooth_metric():
    """d = (M + ℓ²K)⁻¹ g × (area / points) on the quick prism's control points (its rest limit surface): for every
    direction v, g·v / ‖v‖ ≤ g·d / ‖d‖ in the norm ‖v‖² = vᵀ(M + ℓ²K)v of the displacement field (Cauchy–Schwarz,
    checked on random v); a uniform density of J, g = M f (f constant), gives d = f × area / points; a subset of the
    points gets the steepest ascent within their own displacements."""
    module = load_scene("prism-walker")
    mesh = module.recipe(resolve(module.Parameters, module.QUICK, ["dtype=float64"]), device="cpu",
                         report=lambda m: None)[0]  # fmt: skip
    operator = LaplaceBeltrami(mesh, device="cpu", dtype="float64")
    mass, stiffness = operator.mass_matrix().toarray(), operator.stiffness_matrix().toarray()
    n, length = mesh.n_vertices, 0.3 * control_scale(mesh.vertices)
    carried = mass.sum() / n
    f = np.array([0.2, -1.0, 0.5])
    uniform = shape_smoother(mesh, list(range(n)), length)(mass @ np.tile(f, (n, 1)))
    assert uniform == pytest.approx(np.tile(f * carried, (n, 1)), rel=1e-10, abs=1e-12)
    rng = np.random.default_rng(4)
    for points in (list(range(n)), [5, 6, 30, 41]):
        metric = (mass + length**2 * stiffness)[np.ix_(points, points)]
        g = rng.normal(size=(len(points), 3))
        d = shape_smoother(mesh, points, length)(g)

        def gain(v):  # dJ per unit norm, the axes together
            return np.sum(g * v) / np.sqrt(np.sum(v * (metric @ v)))

        assert np.sum(g * d) > 0 and gain(d) >= max(gain(rng.normal(size=g.shape)) for _ in range(200))
        assert gain(d) == pytest.approx(np.sqrt(np.sum(g * np.linalg.solve(metric, g))), rel=1e-10)
        assert gain(g) < gain(d)  # the raw gradient is not the steepest direction of a smooth displacement


def test_a_design_without_a_smoothing_length_is_refused_with_the_fix(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "inverse_design", "--device", "cpu", "--quick", "--points", "all", "--smoothing", "0"])
    assert "give a length > 0" in capsys.readouterr().err


def test_the_elongation_stretches_the_rest_shape_along_the_wave_and_keeps_the_origin_vertex():
    module, p = quick_sphere()
    mesh, options = sphere_walker_recipe(p, device="cpu", report=lambda m: None)
    plain, stretched = (place_walker(mesh, replace(p, elongation=e), options["origin"]) for e in (1.0, 1.25))
    extent = [np.ptp(placed.mesh.vertices, axis=0) for placed in (plain, stretched)]
    assert extent[1] == pytest.approx(extent[0] * [1.25, 1.0, 1.0], rel=1e-12)
    assert stretched.origin_vertex == plain.origin_vertex
    assert stretched.mesh.vertices[:, 0] == pytest.approx(1.25 * plain.mesh.vertices[:, 0], rel=1e-12, abs=1e-12)


@pytest.mark.slow
def test_bench_gradient_horizon_quick_writes_its_horizons_and_chart(tmp_path):
    assert main(["bench", "gradient_horizon", "--device", "cpu", "--quick", "--periods", "0.3", "--scenes",
                 "sphere-walker", "--mechanics", "default", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "gradient_horizon.json").read_text())
    (run,) = result["runs"]
    assert len(run["derivatives"]) == 3 and len(run["derivatives"][0]) == len(run["t_over_T"])
    assert run["t_over_T"][-1] > 0.25 and (tmp_path / "gradient_horizon.png").stat().st_size > 10_000


@pytest.mark.slow
def test_bench_inverse_design_quick_keeps_the_best_step_and_verifies_it(tmp_path):
    assert main(["bench", "inverse_design", "--device", "cpu", "--quick", "--scene", "sphere-walker", "--periods", "0.3",
                 "--iterations", "2", "--wrt", "AC", "--points", "3", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "inverse_design.json").read_text())
    assert [row["iteration"] for row in result["history"]] == [0, 1]
    assert set(result["history"][0]["gradient"]) == {"AC", "X3x", "X3y", "X3z"} and result["points"] == [3]
    assert result["best"]["J"] == max(row["J"] for row in result["history"] if row["accepted"])
    # the batch's unperturbed world and the plain run differ only in the settling steps each chose
    assert result["verified_J"] == pytest.approx(result["best"]["J"], rel=1e-3)


@pytest.mark.slow
def test_bench_gradient_cost_quick_times_the_gradient_against_its_forward_run(tmp_path):
    assert main(["bench", "gradient_cost", "--device", "cpu", "--quick", "--periods", "0.2", "--wrt", "AC",
                 "--shape-points", "1", "--out", str(tmp_path)]) == 0  # fmt: skip
    rows = json.loads((tmp_path / "gradient_cost.json").read_text())["rows"]
    assert [(r["parameters"], r["worlds"]) for r in rows] == [(0, 1), (1, 3), (3, 7)]
    assert rows[0]["ratio"] == 1.0 and rows[1]["ratio"] == pytest.approx(rows[1]["seconds"] / rows[0]["seconds"])
    assert rows[1]["bytes"] is None  # device memory is a GPU's


def test_the_speed_objective_is_the_walk_per_measured_period():
    """c at the origin pulses with period 40 (upward half-maximum crossings), the centre moves at 0.003 per unit
    time along x: 0.12 per period, 0.06 R per period for R = 2; one pulse is refused."""
    t = np.linspace(0.0, 200.0, 20001)
    c = np.sin(2 * np.pi * t / 40.0)
    com = np.column_stack([0.003 * t, np.zeros_like(t), np.ones_like(t)])
    trace = np.column_stack([t, c, com, com - [1.0, 0.0, 0.0]])  # the origin vertex behind the centre
    distance = forward_distance(trace, [1.0, 0.0, 0.0], 2.0)
    assert objective_value("speed", trace, distance, [1.0, 0.0, 0.0], 2.0, 40.0) == pytest.approx(0.06, rel=1e-9)
    assert objective_value("distance", trace, distance, [1.0, 0.0, 0.0], 2.0, 40.0) == pytest.approx(0.3)
    short = t <= 30.0  # one crossing, at t = 40/12
    with pytest.raises(WalkerGradientError, match="periods=2"):
        objective_value("speed", trace[short], distance[short], [1.0, 0.0, 0.0], 2.0, 40.0)


def test_rest_shapes_displace_each_worlds_control_points_and_are_checked():
    _, p = quick_sphere()
    mesh, _ = sphere_walker_recipe(p, device="cpu", report=lambda m: None)
    moved = np.zeros_like(mesh.vertices)
    moved[5] = [0.5, -0.25, 1.0]
    plain, shifted = displaced(mesh, [np.zeros_like(moved), moved], 2)
    assert np.array_equal(plain.vertices, mesh.vertices) and np.array_equal(shifted.triangles, mesh.triangles)
    assert shifted.vertices - mesh.vertices == pytest.approx(moved, abs=1e-15)
    with pytest.raises(ValueError, match="one .* displacement per world"):
        displaced(mesh, [moved], 2)
    with pytest.raises(ValueError, match=r"\(162, 3\)"):
        displaced(mesh, [moved[:-1]], 1)


def test_control_points_are_checked_against_the_scenes_mesh():
    assert control_points("all", 4) == [0, 1, 2, 3] and control_points(np.array([3, 1]), 4) == [3, 1]
    for wrong in ([4], [-1], [1, 1]):
        with pytest.raises(GradientError, match="between 0 and 3"):
            control_points(wrong, 4)


def test_the_shape_gradient_keeps_the_sphere_walkers_mirror_symmetry():
    """The wave starts on the equator at -x and the icosphere is mirror-symmetric in y: the control point mirrored
    in y pulls the walk the same way along x and z, and opposite along y. Known before the run."""
    module = load_scene("sphere-walker")
    p = resolve(module.Parameters, module.QUICK, COARSE)
    rest = module.recipe(p, device="cpu", report=lambda m: None)[0].vertices
    point = int(np.argmax(rest[:, 1] - 0.1 * rest[:, 0]))  # off every mirror plane but y's partner
    mirror = int(np.argmin(np.linalg.norm(rest - rest[point] * [1.0, -1.0, 1.0], axis=1)))
    assert mirror != point and np.allclose(rest[mirror], rest[point] * [1.0, -1.0, 1.0], atol=1e-12)
    result = walker_gradient(module, p, points=[point, mirror], steps=(1e-4,), device="cpu", report=lambda m: None)
    g = result["shape_gradient"]
    assert g.shape == (2, 3) and np.linalg.norm(g[0]) > 1e-3 * abs(result["objective"]) / p.radius  # it matters
    assert g[1] == pytest.approx(g[0] * [1.0, -1.0, 1.0], rel=1e-6, abs=1e-9 * np.linalg.norm(g[0]))
    assert result["shape_derivatives"].shape == (1, 2, 3, len(result["times"]))
    rms = np.sqrt(np.mean(np.sum((rest - rest.mean(axis=0)) ** 2, axis=1)))  # the control points' (outside the sphere)
    assert result["shape_deltas"] == pytest.approx([1e-4 * rms], rel=1e-12) and rms > p.radius


def test_a_walker_displaced_rigidly_walks_as_before():
    """`rest_shape` moves every world's control points; a rigid horizontal shift (and a vertical one, which the
    walker's placement on the ground undoes) leaves the walk and its shape gradient as they were."""
    module = load_scene("sphere-walker")
    p = resolve(module.Parameters, module.QUICK, COARSE)
    rest = module.recipe(p, device="cpu", report=lambda m: None)[0].vertices
    shift = np.tile([3.0, -2.0, 1.5], (len(rest), 1))
    plain, shifted = (walker_gradient(module, p, points=[5], rest_shape=shape, steps=(1e-4,), device="cpu",
                                      report=lambda m: None) for shape in (None, shift))  # fmt: skip
    assert shifted["rest_vertices"] == pytest.approx(rest + shift, abs=1e-12)
    assert shifted["objective"] == pytest.approx(plain["objective"], rel=1e-8)
    largest = np.abs(plain["shape_gradient"]).max()
    assert shifted["shape_gradient"] == pytest.approx(plain["shape_gradient"], rel=1e-5, abs=1e-5 * largest)
    with pytest.raises(WalkerGradientError, match="rest_shape"):
        walker_gradient(module, p, points=[5], rest_shape=shift[:-1], device="cpu", report=lambda m: None)


def test_worlds_split_into_batches_give_the_one_batchs_gradient():
    """`max_worlds`: 1 + 8 worlds as batches of 5 and 4, the second given the first's steps. The first batch
    chooses its settling step from its own worlds' bounds, not all nine: the runs differ by that choice alone."""
    module = load_scene("sphere-walker")
    p = resolve(module.Parameters, module.QUICK, COARSE)
    whole, split = (walker_gradient(module, p, ["AC"], points=[3], steps=(1e-4,), max_worlds=size, device="cpu",
                                    report=lambda m: None) for size in (None, 5))  # fmt: skip
    assert split["objective"] == pytest.approx(whole["objective"], rel=1e-9)  # the first batch chose its steps
    assert split["gradient"]["AC"] == pytest.approx(whole["gradient"]["AC"], rel=1e-6)  # measured 2e-8
    assert split["shape_gradient"] == pytest.approx(whole["shape_gradient"], rel=1e-6,
                                                    abs=1e-8 * np.abs(whole["shape_gradient"]).max())  # fmt: skip
    with pytest.raises(WalkerGradientError, match="at least 1"):
        walker_gradient(module, p, ["AC"], max_worlds=0, device="cpu", report=lambda m: None)


@pytest.mark.slow
def test_the_shape_gradient_of_every_control_point_knows_translations_and_the_elongation():
    """Two answers known in advance: translating the rest shape rigidly does not change the walk (the ground is
    level and the walker is set down on it), so the shape gradient sums to zero along each axis; stretching it along
    x about x = 0 moves control point i by x_i per unit of elongation, so dJ/d elongation = Σ_i x_i dJ/dX_i."""
    module = load_scene("sphere-walker")
    p = resolve(module.Parameters, module.QUICK, COARSE)
    result = walker_gradient(module, p, ["elongation"], points="all", steps=(1e-4,), device="cpu",
                             report=lambda m: None)  # fmt: skip
    g, x = result["shape_gradient"], result["rest_vertices"][:, 0]
    assert g.shape == (42, 3)
    scale = np.linalg.norm(g, axis=0)
    assert np.all(np.abs(g.sum(axis=0)) < 1e-4 * scale)  # measured 7e-7, 4e-9, 9e-8
    elongation = result["gradient"]["elongation"]
    assert abs(elongation) > 1e-2 * abs(result["objective"])
    assert x @ g[:, 0] == pytest.approx(elongation, rel=1e-5)  # measured 5e-7


@pytest.mark.slow
def test_the_cli_prints_a_walkers_shape_gradient(capsys):
    assert main(["grad", "sphere-walker", "--quick", "--points", "3,7", "--device", "cpu", "--json",
                 *[f"--set={s}" for s in COARSE]]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out["gradient"] == {} and out["shape_gradient"]["points"] == [3, 7]
    assert np.asarray(out["shape_gradient"]["gradient"]).shape == (2, 3)
