"""Reverse mode through a walker's walk (wavewarp/adjoint.py): the adjoint against central differences of whole
walks from the same start, the checkpointed pass against the fully stored one, the start state's gradient, and the
refusals."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
import warp as wp

from wavewarp.adjoint import WalkAdjoint, check_adjoint_walk, checkpoint_spacing, walker_adjoint_gradient
from wavewarp.benchmarks.adjoint_cost import main as adjoint_cost
from wavewarp.benchmarks.adjoint_horizon import main as adjoint_horizon
from wavewarp.benchmarks.inverse_design import log_step, main as inverse_design
from wavewarp.benchmarks.tape_adjoints import LAWS, LawCase
from wavewarp.cli import main
from wavewarp.initial import gaussian_pulse
from wavewarp.kernels.adjoint import ShellRates
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.parameters import load_scene, resolve
from wavewarp.shell import Shell
from wavewarp.walker import WalkerRun
from wavewarp.walker_gradients import WalkerGradientError

# the paper's walker model (overdamped, explicit point contact, k_f = 0.1) with the insensitive wave, on the
# level-1 sphere briefly settled, in float64; AC = 0.3 for a walk large against the differences' round-off;
# COULOMB: the scenes' contact instead (implicit, Coulomb's law)
PAPER_WALK = ["level=1", "settle=2", "frames=1", "dtype=float64", "mechanics=overdamped", "contact_solve=explicit",
              "sharpness=0.1", "sensitive=false", "drag=60", "AC=0.3"]  # fmt: skip
COULOMB = ["contact_solve=implicit", "sharpness=inf"]
SPHERE = load_scene("sphere-walker")
BILAYER = load_scene("bilayer-walker")


def parameters(*overrides):
    return resolve(SPHERE.Parameters, {}, [*PAPER_WALK, *overrides])


def settled(p, scene=SPHERE) -> WalkerRun:
    mesh, options = scene.recipe(p, device="cpu", report=lambda message: None)
    return WalkerRun("walker", mesh, p, device="cpu", report=lambda message: None, **options)


def walk_state(run) -> list:
    return run.wave.state.arrays() + [run.dynamics.state.x, run.dynamics.state.v]


def put(run, state) -> None:
    """Set `run` to a copy of the state `state` (its wave's and mechanics' arrays) and the reference to its c."""
    for live, saved in zip(walk_state(run), state):
        wp.copy(live, saved)
    run.shell.update_reference(run.wave.c)


@pytest.fixture(scope="module")
def half_period():
    """The settled walker, its start state and its number of chemistry steps over half a period."""
    run = settled(parameters("periods=0.5"))
    return run, [wp.clone(a) for a in walk_state(run)], run.frames * run.steps_per_frame


def difference_from_start(p, start, steps, name, relative) -> float:
    """(J(θ + δ) - J(θ - δ)) / 2δ of whole walks built at θ ± δ, each set to the same start."""
    theta = float(getattr(p, name))
    delta = relative * (abs(theta) or 1.0)
    ends = []
    for sign in (1.0, -1.0):
        run = settled(replace(p, **{name: theta + sign * delta}))
        put(run, start)
        ends.append(WalkAdjoint(run).walk(steps))
    return (ends[0] - ends[1]) / (2.0 * delta)


def direction_dot_forces(mesh, x, c, direction, **moduli) -> float:
    """d · F(x) of a float64 shell built with `moduli` (thickness, young, AC, AI, volume_penalty)."""
    shell = Shell(mesh, moduli.pop("thickness"), moduli.pop("young"), dtype="float64", device="cpu", **moduli)
    return float(np.sum(shell.forces(x, c) * direction))


@pytest.mark.parametrize("model", ["koiter", "bilayer"])
def test_the_shells_rates_match_the_forces_and_their_differences_in_each_parameter(model):
    """Ė = -d·F, and each term's share through its parameter: -d·∂F/∂θ by central differences of shells built at
    θ ± δ (Y, h scale the elastic terms as Y h, Y h³; the shell's penalty is a number of its own here; AC and AI move
    the reference: Koiter's, or the bilayer's through Λ and A as well)."""
    mesh, rng = icosphere(1.0, level=1), np.random.default_rng(5)
    moduli = {"thickness": 0.05, "young": 3.0, "AC": 0.3, "AI": 0.7, "volume_penalty": 5.0, "model": model}
    x = mesh.vertices + 0.02 * rng.standard_normal(mesh.vertices.shape)
    c, direction = rng.uniform(0.0, 1.0, len(x)), rng.standard_normal(x.shape)
    shell = Shell(mesh, dtype="float64", device="cpu", **moduli)
    rates = wp.zeros(1, dtype=ShellRates, device="cpu")
    shell.rates_device(shell._set(x, c), wp.array(direction, dtype=wp.vec3d, device="cpu"), rates)
    stretching, bending, volume, metric, curvature, per_excess = rates.numpy()[0]
    forces = direction_dot_forces(mesh, x, c, direction, **moduli)
    assert stretching + bending + volume == pytest.approx(-forces, rel=1e-12)
    expected = {"thickness": (stretching + 3 * bending) / moduli["thickness"], "AC": metric, "AI": curvature,
                "young": (stretching + bending) / moduli["young"], "volume_penalty": volume / moduli["volume_penalty"]}
    for name, rate in expected.items():
        delta = 1e-5 * float(moduli[name])
        ends = [direction_dot_forces(mesh, x, c, direction, **{**moduli, name: moduli[name] + sign * delta})
                for sign in (1.0, -1.0)]  # fmt: skip
        assert -rate == pytest.approx((ends[0] - ends[1]) / (2 * delta), rel=1e-6), name
    at_x = shell._volume_of(wp.array(x, dtype=wp.vec3d, device="cpu"))
    for target in (shell.rest_volume, at_x):  # V̄, and V̄ = V(x) exactly
        ends = []
        for sign in (1.0, -1.0):
            shell.rest_volume = target + sign * 1e-6 * target
            ends.append(np.sum(shell.forces(x, c) * direction))
        shell.rest_volume = target
        shell.rates_device(shell._set(x, c), wp.array(direction, dtype=wp.vec3d, device="cpu"), rates)
        assert rates.numpy()[0][5] == pytest.approx((ends[0] - ends[1]) / (2e-6 * target), rel=1e-6)


@pytest.mark.parametrize("law", LAWS)
def test_the_ground_laws_adjoints_match_a_directional_difference_and_warps_tape(law):
    """The hand-written adjoints of the ground laws at points in and out of contact against a central difference of
    f̂ · f along a random direction and, where its adjoint is right (not through the tanh law's Newton loop for the
    slip speed: benchmarks/tape_adjoints.py), against Warp's tape of the forward kernels."""
    case = LawCase(law, 500, device="cpu")
    hand = case.hand()
    assert case.along_direction(hand) == pytest.approx(case.directional_difference(), rel=1e-7)
    if law != "explicit":  # the implicit law's r̂ (the masses' share through the responses)
        along = float(np.sum(case.response_hat.numpy() * case.response_move))
        assert along == pytest.approx(case.response_difference(), rel=1e-7)
    if law != "implicit-tanh":
        taped = case.tape_backward(case.record())
        for mine, warps in zip(hand, taped):
            np.testing.assert_allclose(mine, warps, rtol=0, atol=1e-13 * np.abs(mine).max())


def test_the_forward_walk_replays_the_runs_coupled_steps_bitwise(half_period):
    run, start, steps = half_period
    put(run, start)
    WalkAdjoint(run).walk(7)
    walked = run.dynamics.state.x.numpy().copy()
    put(run, start)
    run.coupled.advance(7)
    assert np.array_equal(run.dynamics.state.x.numpy(), walked)


@pytest.mark.parametrize("name", ["AC", "friction"])
def test_the_adjoint_matches_central_differences_of_walks_from_the_same_start(half_period, name):
    run, start, steps = half_period
    put(run, start)
    adjoint = WalkAdjoint(run, [name]).gradient(steps)["gradient"][name]
    difference = difference_from_start(run.p, start, steps, name, 1e-3)
    assert adjoint == pytest.approx(difference, rel=1e-5)


def test_the_start_states_gradient_matches_central_differences_along_a_random_direction(half_period):
    run, start, steps = half_period
    put(run, start)
    result = WalkAdjoint(run).gradient(steps)
    direction = np.random.default_rng(3).standard_normal((run.mesh.n_vertices, 3))
    step = 1e-5 * run.radius
    ends = []
    for sign in (1.0, -1.0):
        put(run, start)
        run.dynamics.state.x.assign(start[-2].numpy() + sign * step * direction)
        ends.append(WalkAdjoint(run).walk(steps))
    assert np.sum(result["start"]["x"] * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5)


def test_the_checkpointed_gradient_equals_the_fully_stored_one_bitwise(half_period):
    run, start, steps = half_period
    results = []
    for every in (steps, 4):
        put(run, start)
        results.append(WalkAdjoint(run, ["AC", "young", "friction", "drag"], checkpoint_every=every).gradient(steps))
    stored, checkpointed = results
    assert stored["checkpoints"] == 1 and checkpointed["checkpoints"] == math.ceil(steps / 4)
    assert stored["gradient"] == checkpointed["gradient"]
    for name in ("x", "v"):
        assert np.array_equal(stored["start"][name], checkpointed["start"][name])
    assert stored["objective"] == checkpointed["objective"]


def test_the_default_checkpoints_hold_the_fewest_bytes_and_leave_the_run_at_the_walks_end(half_period):
    run, start, steps = half_period
    put(run, start)
    result = WalkAdjoint(run, ["AC"]).gradient(steps)
    every, substeps = result["checkpoint_every"], run.coupled.substeps
    assert result["checkpoints"] == math.ceil(steps / every) and result["stored_substeps"] == every * substeps + 1
    state = sum(a.capacity for a in walk_state(run))
    row, c_row = 2 * run.dynamics.state.x.capacity, 2 * run.wave.c.capacity  # (x, v) a substep, (c, w) a step
    held = [math.ceil(steps / k) * state + (k * substeps + 1) * row + (k + 1) * c_row for k in range(1, steps + 1)]
    assert result["state_bytes"] == min(held)
    left = run.dynamics.state.x.numpy().copy()
    put(run, start)
    WalkAdjoint(run).walk(steps)
    assert np.array_equal(left, run.dynamics.state.x.numpy())  # the gradient leaves the run at the walk's end


@pytest.mark.parametrize("substeps", [1, 4, 200])
def test_the_checkpoints_bytes_grow_as_the_square_root_of_the_steps(substeps):
    held = []
    for steps in (100, 10000):
        every = checkpoint_spacing(steps, substeps, 80, 48, 8)
        held.append(math.ceil(steps / every) * 80 + (every * substeps + 1) * 48 + (every + 1) * 8)
    assert held[1] / held[0] == pytest.approx(10.0, rel=0.15)  # 100× the steps, 10× the bytes


@pytest.mark.parametrize("overrides, wrt, message", [
    (["sensitive=true", "dt=0"], ["AC"], "dt=0.5"), (["mechanics=inertial"], ["AC"], "mechanics=overdamped"),
    (["contact_solve=implicit", "sharpness=inf"], ["sharpness"], "no derivative in k_f"),
    ([], ["density"], "density"),
    (["drag=0"], ["contact_damping"], "--set drag="), (["mu_v=0"], ["mu_v"], "mu_v > 0")])  # fmt: skip
def test_walks_the_reverse_mode_does_not_cover_are_refused_with_the_fix(overrides, wrt, message):
    with pytest.raises(WalkerGradientError, match=message):
        check_adjoint_walk(parameters(*overrides), wrt)


def test_the_settlings_replay_from_the_placement_ends_at_the_walks_start_bitwise(half_period):
    run, start, steps = half_period
    x, v = WalkAdjoint(run).replay_settling()
    assert np.array_equal(x, start[-2].numpy()) and np.array_equal(v, start[-1].numpy())


def whole_run_difference(p, base, name, relative, scene=SPHERE) -> float:
    """(J(θ + δ) - J(θ - δ)) / 2δ of whole runs (placed, settled with `base`'s mechanics steps, walked) at θ ± δ."""
    theta = float(getattr(p, name))
    delta = relative * (abs(theta) or 1.0)
    ends = []
    for sign in (1.0, -1.0):
        mesh, options = scene.recipe(p, device="cpu", report=lambda message: None)
        run = WalkerRun("walker", mesh, replace(p, **{name: theta + sign * delta}), mechanics_dt=base.settle_dt,
                        device="cpu", report=lambda message: None, **options)  # fmt: skip
        ends.append(WalkAdjoint(run).walk(run.frames * run.steps_per_frame))
    return (ends[0] - ends[1]) / (2.0 * delta)


@pytest.fixture(scope="module")
def coulomb_half_period():
    """The settled walker on the implicit contact with Coulomb's law, its start state and its chemistry steps."""
    run = settled(parameters("periods=0.5", *COULOMB))
    return run, [wp.clone(a) for a in walk_state(run)], run.frames * run.steps_per_frame


@pytest.mark.parametrize("walker, name, relative", [("half_period", "stiffness", 1e-3), ("half_period", "thickness", 1e-3),
                                                   ("coulomb_half_period", "friction", 1e-4),
                                                   pytest.param("coulomb_half_period", "drag", 1e-4,
                                                                marks=pytest.mark.slow)])  # fmt: skip
def test_the_adjoint_through_the_settling_matches_central_differences_of_whole_runs(walker, name, relative, request):
    """On the explicit contact and the implicit one with Coulomb's law, whose stick and slip make J piecewise smooth:
    a step of 1e-3 θ crosses their switches, 1e-4 does not."""
    run, start, steps = request.getfixturevalue(walker)
    put(run, start)
    adjoint = WalkAdjoint(run, [name]).gradient(steps, settle=True)["gradient"][name]
    assert adjoint == pytest.approx(whole_run_difference(run.p, run, name, relative), rel=1e-5)


@pytest.mark.parametrize("contact", [pytest.param([], id="explicit"),
                                     pytest.param(COULOMB, id="implicit", marks=pytest.mark.slow)])  # fmt: skip
def test_the_adjoint_on_the_area_contact_matches_central_differences_of_whole_runs(contact):
    """The contact as a pressure on the limit surface's quadrature points: k and β per unit area (per the scene's
    contact_area), the points' areas in the spread and its transpose."""
    p = parameters("periods=0.25", "contact=area", *contact)
    run = settled(p)
    adjoint = WalkAdjoint(run, ["stiffness", "friction"]).gradient(run.frames * run.steps_per_frame, settle=True)
    for name in ("stiffness", "friction"):
        assert adjoint["gradient"][name] == pytest.approx(whole_run_difference(p, run, name, 1e-4), rel=1e-5), name


@pytest.mark.parametrize("law, names, relative", [
    pytest.param(["sharpness=10"], ["sharpness", "drag"], 1e-4, id="tanh", marks=pytest.mark.slow),
    pytest.param([], ["friction"], 1e-5, id="coulomb-friction", marks=pytest.mark.slow),
    pytest.param([], ["drag"], 1e-5, id="coulomb-drag")])  # fmt: skip
def test_the_adjoint_in_the_body_frame_matches_central_differences_of_whole_runs(law, names, relative):
    """The drag on the velocity relative to the body velocity U, which Weiszfeld steps set in every contact pass so that
    the net friction vanishes: U's steps taken back. The area contact, whose many points in contact share the friction
    (on the level-1 sphere's one limit point in contact U would cancel its slip and the friction would do nothing)."""
    p = parameters("periods=0.25", "contact=area", *COULOMB, "drag_frame=body", *law)
    run = settled(p)
    adjoint = WalkAdjoint(run, names).gradient(run.frames * run.steps_per_frame, settle=True)
    for name in names:
        assert adjoint["gradient"][name] == pytest.approx(whole_run_difference(p, run, name, relative), rel=1e-5), name


def test_the_adjoint_on_the_bilayer_walker_matches_central_differences_of_whole_runs():
    """The bilayer reference (b̄ = Λb̄⁰ - A c ā⁰): AC and AI move the curvature through Λ and A = (AC/2 - AI)/R."""
    p = resolve(BILAYER.Parameters, {}, [*PAPER_WALK, "periods=0.25"])
    run = settled(p, BILAYER)
    adjoint = WalkAdjoint(run, ["AC", "AI"]).gradient(run.frames * run.steps_per_frame, settle=True)
    for name in ("AC", "AI"):
        difference = whole_run_difference(p, run, name, 1e-3, BILAYER)
        assert adjoint["gradient"][name] == pytest.approx(difference, rel=1e-5), name


@pytest.mark.slow
def test_the_implicit_contacts_checkpointed_gradient_equals_the_fully_stored_one_bitwise(coulomb_half_period):
    run, start, steps = coulomb_half_period
    results = []
    for every in (steps, 5):
        put(run, start)
        results.append(WalkAdjoint(run, ["AC", "friction", "drag"], checkpoint_every=every).gradient(steps, settle=True))
    assert results[0]["gradient"] == results[1]["gradient"]
    assert np.array_equal(results[0]["start"]["x"], results[1]["start"]["x"])


@pytest.mark.slow
def test_the_body_frames_checkpointed_gradient_equals_the_fully_stored_one_bitwise():
    """The body velocity's iterates are made again in every recomputed stretch: checkpoints change nothing."""
    run = settled(parameters("periods=0.25", "contact=area", *COULOMB, "drag_frame=body"))
    start, steps = [wp.clone(a) for a in walk_state(run)], run.frames * run.steps_per_frame
    results = []
    for every in (steps, 7):
        put(run, start)
        results.append(WalkAdjoint(run, ["AC", "friction", "drag"], checkpoint_every=every).gradient(steps, settle=True))
    assert results[0]["gradient"] == results[1]["gradient"]
    assert np.array_equal(results[0]["start"]["x"], results[1]["start"]["x"])


@pytest.fixture(scope="module")
def sensitive_quarter():
    """The paper's walker model with the sensitive wave, settled: its start state and a quarter period's steps."""
    run = settled(parameters("periods=0.25", "sensitive=true"))
    return run, [wp.clone(a) for a in walk_state(run)], run.frames * run.steps_per_frame


def test_the_sensitive_waves_adjoint_matches_central_differences_of_walks_from_the_same_start(sensitive_quarter):
    """The wave on the deforming shell: J depends on AC through the mechanics and through the chemistry the shape
    steers (docs/theory/gradients.md, "The sensitive wave")."""
    run, start, steps = sensitive_quarter
    put(run, start)
    adjoint = WalkAdjoint(run, ["AC"]).gradient(steps)["gradient"]["AC"]
    assert adjoint == pytest.approx(difference_from_start(run.p, start, steps, "AC", 1e-3), rel=1e-5)


def test_the_sensitive_waves_start_gradient_in_c_and_x_matches_central_differences(sensitive_quarter):
    """dJ/dc₀ (through the mechanics' reference and the wave's steps) and dJ/dx₀ (the mechanics and the operator's
    surface) along random directions."""
    run, start, steps = sensitive_quarter
    put(run, start)
    result = WalkAdjoint(run).gradient(steps)["start"]
    rng = np.random.default_rng(7)
    for name, live, index, step in (("c", run.wave.state.c, 0, 1e-4), ("x", run.dynamics.state.x, -2, 1e-4 * run.radius)):
        direction = rng.standard_normal(result[name].shape)
        ends = []
        for sign in (1.0, -1.0):
            put(run, start)
            live.assign(start[index].numpy() + sign * step * direction)
            run.shell.update_reference(run.wave.c)
            ends.append(WalkAdjoint(run).walk(steps))
        assert np.sum(result[name] * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5), name


def test_the_sensitive_waves_checkpointed_gradient_equals_the_fully_stored_one_bitwise(sensitive_quarter):
    run, start, steps = sensitive_quarter
    results = []
    for every in (steps, 5):
        put(run, start)
        results.append(WalkAdjoint(run, ["AC", "thickness"], checkpoint_every=every).gradient(steps))
    assert results[0]["gradient"] == results[1]["gradient"] and results[0]["objective"] == results[1]["objective"]
    for name in ("x", "c", "w"):
        assert np.array_equal(results[0]["start"][name], results[1]["start"][name])


@pytest.mark.parametrize("names", [["thickness"], pytest.param(["friction", "AC", "drag"], marks=pytest.mark.slow)])
def test_the_scenes_default_walker_adjoint_matches_central_differences_of_whole_runs(names):
    """The scenes' walker as it is (the sensitive wave, the implicit contact with Coulomb's law, two mass corrections)
    through the settling and the pulse placed on the settled surface."""
    p = resolve(SPHERE.Parameters, {}, ["level=1", "settle=2", "frames=1", "dtype=float64", "periods=0.25", "AC=0.3"])
    assert p.sensitive and p.contact_solve == "implicit" and math.isinf(p.sharpness) and p.mass_corrections == 2
    run = settled(p)
    gradient = WalkAdjoint(run, names).gradient(run.frames * run.steps_per_frame, settle=True)["gradient"]
    for name in names:
        assert gradient[name] == pytest.approx(whole_run_difference(p, run, name, 1e-4), rel=1e-5), name


def test_the_cli_prints_the_adjoints_json_and_refuses_shape_points_in_the_body_frame_on_a_slope(capsys):
    sets = [arg for item in [*PAPER_WALK, "periods=0.2"] for arg in ("--set", item)]
    assert main(["grad", "sphere-walker", "--method", "adjoint", "--wrt", "AC,AI", "--json", "--device", "cpu", *sets]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result["gradient"]) == {"AC", "AI"} and result["method"] == "adjoint" and not result["start_held"]
    assert all(math.isfinite(value) for value in result["gradient"].values())
    slope = [*sets, *[arg for item in [*COULOMB, "drag_frame=body", "slope=5"] for arg in ("--set", item)]]
    assert main(["grad", "sphere-walker", "--method", "adjoint", "--wrt", "AC", "--points", "1", "--device", "cpu",
                 *slope]) != 0
    assert "slope=0 or drag_frame=lab" in capsys.readouterr().err


@pytest.mark.slow
def test_every_parameters_adjoint_matches_central_differences_of_whole_walks():
    """One period, every parameter the reverse mode takes, against walks built at θ ± δ from the same start."""
    p = parameters("periods=1")
    run = settled(p)
    start, steps = [wp.clone(a) for a in walk_state(run)], run.frames * run.steps_per_frame
    names = ["AC", "AI", "thickness", "young", "mu_v", "friction", "sharpness", "stiffness", "contact_damping", "drag"]
    adjoint = WalkAdjoint(run, names).gradient(steps)["gradient"]
    for name in names:
        assert adjoint[name] == pytest.approx(difference_from_start(p, start, steps, name, 1e-3), rel=1e-5), name


@pytest.mark.slow
@pytest.mark.parametrize("contact, relative", [
    (COULOMB, 1e-4), (["contact_solve=implicit", "sharpness=10"], 1e-4),
    ([*COULOMB, "drag_frame=body", "contact=area", "periods=0.25"], 1e-5),
    (["contact_solve=implicit", "sharpness=10", "drag_frame=body", "contact=area", "periods=0.25"], 1e-4)],
    ids=["coulomb", "tanh", "body-coulomb", "body-tanh"])  # fmt: skip
def test_every_parameters_adjoint_through_the_implicit_contact_matches_differences_of_whole_runs(contact, relative):
    p = parameters("periods=0.5", *contact)
    names = ["AC", "AI", "thickness", "young", "mu_v", "friction", "stiffness", "contact_damping", "drag"]
    names += [] if "sharpness=inf" in contact else ["sharpness"]
    adjoint = walker_adjoint_gradient(SPHERE, p, names, device="cpu", report=lambda message: None)
    base = settled(p)
    for name in names:
        assert adjoint["gradient"][name] == pytest.approx(whole_run_difference(p, base, name, relative), rel=1e-5), name


@pytest.mark.slow
def test_every_parameters_adjoint_through_the_whole_run_matches_differences_of_whole_runs():
    """`walker_adjoint_gradient` (back through the walk and the settling) against central differences of whole runs
    (each placed and settled anew with the unperturbed run's mechanics steps), and its J against the plain run's."""
    p = parameters("periods=0.5")
    names = ["AC", "AI", "thickness", "young", "mu_v", "friction", "sharpness", "stiffness", "contact_damping", "drag"]
    adjoint = walker_adjoint_gradient(SPHERE, p, names, device="cpu", report=lambda message: None)
    base = settled(p)
    plain = base.dynamics.center_of_mass() @ base.forward
    base.coupled.advance(base.frames * base.steps_per_frame)
    assert adjoint["objective"] == pytest.approx((base.dynamics.center_of_mass() @ base.forward - plain) / base.radius,
                                                 rel=1e-12)  # fmt: skip
    for name in names:
        assert adjoint["gradient"][name] == pytest.approx(whole_run_difference(p, base, name, 1e-3), rel=1e-5), name


def test_one_adjoint_taken_twice_gives_the_same_gradient_through_its_captured_graphs(half_period):
    run, start, steps = half_period
    adjoint = WalkAdjoint(run, ["thickness", "friction"])
    results = []
    for horizon, settle in ((steps, True), (steps // 2, False), (steps, True)):
        put(run, start)
        results.append(adjoint.gradient(horizon, settle=settle))
    assert results[0]["gradient"] == results[2]["gradient"] != results[1]["gradient"]
    assert np.array_equal(results[0]["start"]["x"], results[2]["start"]["x"])


def test_inverse_design_by_the_reverse_mode_raises_the_walk_and_a_plain_run_confirms_it(tmp_path):
    sets = [arg for item in [*PAPER_WALK, "periods=0.3"] for arg in ("--set", item)]
    design = ["--scene", "sphere-walker", "--method", "adjoint", "--wrt", "AC", "friction", "--device", "cpu", "--out",
              str(tmp_path), *sets]  # fmt: skip
    assert inverse_design([*design, "--iterations", "2"]) == 0
    first = json.loads((tmp_path / "inverse_design.json").read_text())["history"]
    assert inverse_design([*design, "--iterations", "3", "--resume"]) == 0  # a third step, gone on from the file
    result = json.loads((tmp_path / "inverse_design.json").read_text())
    assert result["history"][:2] == first and [row["iteration"] for row in result["history"]] == [0, 1, 2]
    best = max((row for row in first if row["accepted"]), key=lambda row: row["J"])
    assert result["history"][2]["theta"] == log_step(best["theta"], best["gradient"], first[-1]["rate"])
    assert result["method"] == "adjoint" and result["best"]["J"] > result["history"][0]["J"]
    with pytest.raises(SystemExit, match="wrt"):  # other settings: not gone on from
        inverse_design([*design, "--wrt", "AC", "--iterations", "4", "--resume"])
    assert result["verified_J"] == pytest.approx(result["best"]["J"], rel=1e-12)  # the same plain run
    body = ["--set", "slope=5", "--set", "contact_solve=implicit", "--set", "sharpness=inf", "--set",
            "drag_frame=body"]  # the rest shape's reverse mode refuses the body frame on a slope, before any run
    with pytest.raises(WalkerGradientError, match="drag_frame=lab"):
        inverse_design(["--method", "adjoint", "--wrt", "AC", "--points", "0", "--device", "cpu", "--out",
                        str(tmp_path), *body])


@pytest.mark.parametrize("fixture", ["half_period", "coulomb_half_period"])
def test_the_start_gradient_knows_a_horizontal_shift_changes_nothing(fixture, request):
    """On the flat ground the walk from a start moved sideways is the same walk: Σᵢ ∂J/∂x₀ᵢ has no horizontal part
    (the vertical one is the ground's); the implicit overdamped step does not read v₀."""
    run, start, steps = request.getfixturevalue(fixture)
    put(run, start)
    gradient = WalkAdjoint(run).gradient(steps)["start"]
    x = gradient["x"]
    # round-off of the adjoint's sums over the walk's steps: 1.8e-9 of Σ|x| on one 2-core CPU, below 1e-9 on another
    assert np.abs(x.sum(axis=0)[:2]).max() < 1e-8 * np.abs(x).sum()
    assert abs(x.sum(axis=0)[2]) > 1e-3 * np.abs(x).sum()
    if fixture == "coulomb_half_period":
        assert not gradient["v"].any()


@pytest.mark.slow
def test_the_adjoint_cost_benchmark_writes_its_figures_and_holds_fewer_states_checkpointed(tmp_path):
    """A smoke run of `wavewarp bench adjoint_cost`: its JSON and chart, the gradients of its two passes equal, and
    the checkpointed pass holding fewer bytes than the stored one, growing more slowly."""
    assert adjoint_cost(["--device", "cpu", "--set", "level=1", "--set", "settle=2", "--periods", "0.1", "0.4",
                         "--wrt", "AC", "friction", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "adjoint_cost_cpu.json").read_text())
    assert (tmp_path / "adjoint_cost_cpu.png").stat().st_size > 0
    for row in result["rows"]:
        assert row["checkpointed"]["gradient"] == row["stored"]["gradient"]
        assert row["checkpointed"]["state_bytes"] < row["stored"]["state_bytes"]
    assert result["memory_exponents"]["checkpointed"] < result["memory_exponents"]["stored"]


@pytest.mark.slow
def test_the_adjoint_horizon_benchmark_writes_its_figures_with_a_finite_growth(tmp_path):
    """A smoke run of `wavewarp bench adjoint_horizon` (level-1 sphere, three short horizons)."""
    assert adjoint_horizon(["--device", "cpu", "--set", "level=1", "--set", "settle=2", "--periods", "0.2", "1", "1.2",
                            "--wrt", "AC", "--out", str(tmp_path)]) == 0  # fmt: skip
    result = json.loads((tmp_path / "adjoint_horizon_sphere-walker_cpu.json").read_text())
    assert (tmp_path / "adjoint_horizon_sphere-walker_cpu.png").stat().st_size > 0
    assert [row["periods"] for row in result["rows"]] == [0.2, 1.0, 1.2]
    assert all(row["start_sensitivity"] > 0 for row in result["rows"])
    assert math.isfinite(result["growth"]["rate"]) and math.isfinite(result["growth"]["power"])


@pytest.mark.parametrize("walker, form", [("half_period", "metric"), ("sensitive_quarter", "curvature")])
def test_the_rest_forms_gradient_matches_central_differences_of_walks_with_moved_rest_forms(walker, form, request):
    """dJ/dā⁰ and dJ/db̄⁰ at every quadrature point along a random symmetric move of the shell's rest forms (its mass,
    volume and placement held), against walks from the same start with the forms moved by ± δ."""
    run, start, steps = request.getfixturevalue(walker)
    put(run, start)
    gradient = WalkAdjoint(run, rest_forms=True).gradient(steps)["rest_forms"][form]
    rest = {"metric": run.shell.rest_metric, "curvature": run.shell.rest_curvature}[form]
    base, rng = rest.numpy().copy(), np.random.default_rng(4)
    move = rng.standard_normal(base.shape)
    move, step = 0.5 * (move + move.transpose(0, 2, 1)), 1e-4 * float(np.abs(base).max())
    ends = []
    for sign in (1.0, -1.0):
        rest.assign(base + sign * step * move)
        put(run, start)
        ends.append(WalkAdjoint(run).walk(steps))
    rest.assign(base)
    run.shell.update_reference(run.wave.c)
    assert np.sum(gradient * move) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5)


def test_the_rest_forms_gradient_through_the_settling_matches_central_differences_of_whole_runs(half_period):
    """The same through the settling: each side's walk starts from the settling replayed from the placement with the
    rest forms moved (the insensitive wave's pulse lies on the rest surface, which they do not move)."""
    run, start, steps = half_period
    put(run, start)
    gradient = WalkAdjoint(run, rest_forms=True).gradient(steps, settle=True)["rest_forms"]["metric"]
    base, rng = run.shell.rest_metric.numpy().copy(), np.random.default_rng(6)
    move = rng.standard_normal(base.shape)
    move, step = 0.5 * (move + move.transpose(0, 2, 1)), 1e-4 * float(np.abs(base).max())
    ends = []
    for sign in (1.0, -1.0):
        run.shell.rest_metric.assign(base + sign * step * move)
        put(run, start)
        x, v = WalkAdjoint(run).replay_settling()
        run.dynamics.state.x.assign(x)
        run.dynamics.state.v.assign(v)
        ends.append(WalkAdjoint(run).walk(steps))
    run.shell.rest_metric.assign(base)
    run.shell.update_reference(run.wave.c)
    assert np.sum(gradient * move) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5)


def test_the_insensitive_waves_start_gradient_in_c_and_its_rest_surfaces_share_match_central_differences(half_period):
    """The wave on the rest surface: dJ/dc₀ along a random direction, and the rest operator's share of dJ/dX̄ (its
    stiffness and masses moved with the rest shape, nothing else) against walks on an operator moved by ± δ."""
    run, start, steps = half_period
    put(run, start)
    result = WalkAdjoint(run, rest_forms=True).gradient(steps)
    rng = np.random.default_rng(9)
    rest = run.mesh.vertices
    for name, step in (("c", 1e-4), ("rest_operator", 1e-5 * run.radius)):
        gradient = result["start"]["c"] if name == "c" else result["rest_operator"]
        direction = rng.standard_normal(gradient.shape)
        ends = []
        for sign in (1.0, -1.0):
            put(run, start)
            if name == "c":
                run.wave.state.c.assign(start[0].numpy() + sign * step * direction)
                run.shell.update_reference(run.wave.c)
            else:
                run.operator.update(rest + sign * step * direction)
            ends.append(WalkAdjoint(run).walk(steps))
        run.operator.update(rest)
        assert np.sum(gradient * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5), name


def test_the_rest_volumes_gradient_matches_central_differences_of_walks_with_a_moved_target(sensitive_quarter):
    """dJ/dV̄ (the volume term's target, the rest shape's volume) against walks from the same start with V̄ ± δ."""
    run, start, steps = sensitive_quarter
    put(run, start)
    gradient = WalkAdjoint(run, rest_forms=True).gradient(steps)["rest_volume"]
    base = run.shell.rest_volume
    step, ends = 1e-4 * base, []
    for sign in (1.0, -1.0):
        run.shell.rest_volume = base + sign * step
        put(run, start)
        ends.append(WalkAdjoint(run).walk(steps))
    run.shell.rest_volume = base
    assert gradient == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5)


def test_the_pulses_width_and_rest_surface_shares_match_central_differences_of_walks_from_moved_pulses(half_period):
    """dJ/dσ of the initial pulse's width and (the insensitive wave) its rest surface's share of dJ/dX̄: walks from the
    start with c₀ = the pulse of width σ ± δ, or placed on the rest surface moved by ± δ along a random direction."""
    run, start, steps = half_period
    put(run, start)
    result = WalkAdjoint(run, rest_forms=True).gradient(steps)
    sigma, rest = run.resolved["width"] / run.radius, run.mesh.vertices
    surface = LaplaceBeltrami(run.mesh, rest, device="cpu", dtype="float64")

    def walk_from_pulse(x, width):
        surface.update(x)
        put(run, start)
        run.wave.state.c.assign(gaussian_pulse(surface, run.origin_vertex, width, gamma=run.p.gamma,
                                               radius=run.radius)[0])  # fmt: skip
        run.shell.update_reference(run.wave.c)
        return WalkAdjoint(run).walk(steps)

    assert np.array_equal(gaussian_pulse(surface, run.origin_vertex, sigma, gamma=run.p.gamma, radius=run.radius)[0],
                          start[0].numpy())  # fmt: skip
    step = 1e-5 * sigma
    ends = [walk_from_pulse(rest, sigma + sign * step) for sign in (1.0, -1.0)]
    assert result["pulse_sigma"] == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5)
    direction, step = np.random.default_rng(8).standard_normal(rest.shape), 1e-5 * run.radius
    ends = [walk_from_pulse(rest + sign * step * direction, sigma) for sign in (1.0, -1.0)]
    assert np.sum(result["rest_pulse"] * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-5)
