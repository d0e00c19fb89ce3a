"""Implicit overdamped mechanics (wavewarp/implicit_dynamics.py; docs/theory/dynamics.md, "Implicit overdamped
mechanics"; issue 58): backward Euler of ζ M ẋ = F − M g + Lᵀ f, against the explicit mobility model it replaces."""

from dataclasses import replace

import numpy as np
import pytest

from wavewarp import Ground, ImplicitOverdampedDynamics, OverdampedDynamics, Shell, icosphere
from wavewarp.device import set_deterministic
from wavewarp.driver import simulate
from wavewarp.geometry import limit_positions
from wavewarp.parameters import resolve
from wavewarp.runs import imperfect
from wavewarp.scenes import sphere_walker as scene
from wavewarp.walker import WalkerRun, place_walker, sphere_walker_recipe, walker_model

QUIET = lambda message: None  # noqa: E731


@pytest.fixture
def deterministic():
    set_deterministic(True)
    yield
    set_deterministic(False)


def capped_walker(device):
    """(dynamics(dt, implicit, **options), run(dt, implicit, **options) to t = 2, the rest positions) of a level-2
    sphere walker (the scene's shell, ground, Coulomb friction and drag ζ = 60, float64) under a fixed active cap
    around its origin vertex, from its placement: it sags and contracts (0.8 of R = 25)."""
    p = resolve(scene.Parameters, None, ["level=2", "dtype=float64"])
    mesh, options = sphere_walker_recipe(p, device=device)
    placed = place_walker(mesh, p, options["origin"])
    x0 = placed.mesh.vertices
    c = np.exp(-np.sum((x0 - x0[placed.origin_vertex]) ** 2, axis=1) / (2 * (0.5 * p.radius) ** 2))

    def dynamics(dt, implicit, **options_):
        model = walker_model(placed.mesh, [p], placed.ground, size=options["size"], bilayer=False, rule="3",
                             device=device)
        return model.dynamics(overdamped=True, implicit=implicit, drag=p.drag, dt=dt, c=c, **options_)

    def run(dt, implicit, **options_):
        stepper = dynamics(dt, implicit, **options_)
        stepper.run_until(2.0)
        return stepper

    return dynamics, run, x0


def test_implicit_step_equals_the_explicit_one_as_dt_goes_to_zero_at_first_order(device):
    """The capped walker for 2 time units. At each of dt = the explicit step (0.9 × its bound), dt/2, dt/4 the two
    schemes, both first order, differ by C dt: the differences halve (observed order 1 ± 0.1) and end below 1% of
    the motion."""
    dynamics, run, x0 = capped_walker(device)
    probe = dynamics(None, False)
    omega, bound = probe.omega_max, probe.stable_dt
    differences, moved = [], None
    for k in (1, 2, 4):
        dt = 2.0 / round(2.0 / (0.9 * bound / k))
        reference = run(dt, False, omega=omega).positions()
        implicit = run(dt, True)
        assert implicit.solver.bound(omega) == np.inf and implicit.mean_iterations()[0] > 1
        differences.append(np.abs(implicit.positions() - reference).max())
        moved = np.abs(reference - x0).max()
    orders = np.log2(np.array(differences[:-1]) / differences[1:])
    assert moved > 0.5
    np.testing.assert_allclose(orders, 1.0, atol=0.1)
    assert differences[-1] < 0.01 * moved


def test_the_ground_passes_converge_to_a_fixed_point(device):
    """The capped walker at a step 8× the explicit bound's: the ground's solve taken from the explicit predictor and
    held (one pass) is the split; passes from the last solution's own velocity iterate it: each pass moves the
    answer less than half as far as the one before (a contraction to the step's fixed point, where the ground's
    velocity is the solution's own). (On a walk this removes the split's error: BENCHMARKS.md.)"""
    dynamics, run, _ = capped_walker(device)
    dt = 2.0 / round(2.0 / (8 * dynamics(None, False).stable_dt))
    passes = [run(dt, True, ground_passes=n).positions() for n in (1, 2, 3, 4)]
    moves = [np.abs(b - a).max() for a, b in zip(passes, passes[1:])]
    assert moves[0] > 1e-6 and moves[1] < 0.5 * moves[0] and moves[2] < 0.5 * moves[1], moves


def test_a_stiff_shell_settles_on_the_ground_to_the_explicit_rest_state(device):
    """A stiff ball (Y = 1e4, h = 0.1 R: it sags 0.1 R) put down on a vertex on frictionless ground. The explicit
    model settles at its bound (about 30,000 steps); the implicit one with a step about 500× longer (32 steps). A
    rest state of either is an exact equilibrium F − M g + Lᵀ f = 0 with the ground's law at x: the two agree to
    1e-6 R, and the ground carries the weight (Σ F_n = M g)."""
    mesh = icosphere(1.0, 2)
    z = limit_positions(mesh, device="cpu", dtype="float64")[:, 2]
    x0 = mesh.vertices + [0.0, 0.0, -z.min()]
    ground = Ground(stiffness=1e3, damping=1.0, friction=0.0, solve="implicit", sweeps=32)

    def settled(kind, **options):
        shell = Shell(mesh, thickness=0.1, young=1e4, device=device, dtype="float64")
        dynamics = kind(shell, density=1.0, gravity=1.0, ground=ground, drag=5.0, x0=x0, **options)
        dynamics.run_until(16.0)
        return dynamics

    explicit = settled(OverdampedDynamics)
    implicit = settled(ImplicitOverdampedDynamics, dt=0.5)
    assert implicit.steps == 32 and explicit.steps > 500 * implicit.steps
    sag = x0[:, 2].mean() - explicit.positions()[:, 2].mean()
    assert sag > 0.05
    assert np.abs(implicit.positions() - explicit.positions()).max() < 1e-6
    weight = implicit.total_mass * 1.0
    assert implicit.normal_forces().sum() == pytest.approx(weight, rel=1e-5)
    assert explicit.normal_forces().sum() == pytest.approx(weight, rel=1e-9)


def test_each_world_of_an_implicit_walker_batch_equals_its_single_run_bit_for_bit(deterministic, device):
    """Two level-1 sphere walkers, mechanics=overdamped-implicit, apart in AC, Y, h, μV, elongation, the wave's side
    and the noise seed, stepped as one batch (one minimisation, each world its own line search and convergence): each
    world's positions, concentrations and measurements are those of its own WalkerRun, bit for bit on the CPU."""
    base = resolve(scene.Parameters, {"level": 1, "periods": 0.1, "frames": 2, "settle": 1.0, "dtype": "float64",
                                      "noise": 0.01, "contact_sweeps": 2, "mechanics": "overdamped-implicit",
                                      "implicit_substeps": 2})
    ps = [replace(base, AC=0.1), replace(base, AC=0.2, mirror=True, mu_v=0.0, young=250.0, thickness=2.5,
                                         elongation=1.15)]
    seeds = [0, 1]
    batch = scene.build_batch(ps, seeds=seeds, device=device, report=QUIET)
    results = batch.run()
    x, c, n = batch.dynamics.positions(), batch.wave.concentration(), batch.vertices
    assert batch.coupled.substeps == 2
    for w, (p, seed) in enumerate(zip(ps, seeds)):
        mesh, options = sphere_walker_recipe(p, device=device)
        run = WalkerRun(scene.NAME, imperfect(mesh, p.noise * p.radius, seed), p, device=device,
                        mechanics_dt=batch.settle_dt, report=QUIET, **options)
        outcome = simulate(run, [])
        assert outcome.failure is None and results[w]["status"] == "done"
        same = np.testing.assert_array_equal if device == "cpu" else np.testing.assert_allclose
        same(x[w * n:(w + 1) * n], run.dynamics.positions())
        same(c[w * n:(w + 1) * n], run.wave.concentration())
        if device == "cpu":
            assert results[w]["measurements"] == outcome.measurements
    assert not np.array_equal(x[:n], x[n:])


def test_a_step_whose_minimisation_does_not_converge_is_an_error_with_the_state_restored(device):
    """A budget of one CG iteration cannot reach the tolerance: the run raises ImplicitStepError naming the fix, and
    the state is the chunk's start."""
    from wavewarp import ImplicitStepError

    shell = Shell(icosphere(1.0, 1), thickness=0.1, young=1e3, device=device, dtype="float64")
    x0 = shell.mesh.vertices * 1.05
    dynamics = ImplicitOverdampedDynamics(shell, density=1.0, drag=5.0, x0=x0, dt=0.1, max_iterations=1)
    with pytest.raises(ImplicitStepError, match="did not converge.*raise tol or max_iterations"):
        dynamics.run_until(0.5)
    np.testing.assert_array_equal(dynamics.positions(), x0)
    assert dynamics.steps == 0


def test_the_implicit_mechanics_refuse_what_they_cannot_step():
    """No dt (no bound picks one), an explicit ground, a shell that already has terms; in a walker scene the
    explicit contact."""
    from wavewarp.parameters import SceneError

    shell = Shell(icosphere(1.0, 1), thickness=0.1, young=1e3, device="cpu", dtype="float64")
    with pytest.raises(ValueError, match="give dt"):
        ImplicitOverdampedDynamics(shell, density=1.0, drag=5.0, dt=None)
    with pytest.raises(ValueError, match="solve='implicit'"):
        ImplicitOverdampedDynamics(shell, density=1.0, drag=5.0, dt=0.1, ground=Ground(solve="explicit"))
    ImplicitOverdampedDynamics(shell, density=1.0, drag=5.0, dt=0.1)
    with pytest.raises(ValueError, match="without terms"):
        ImplicitOverdampedDynamics(shell, density=1.0, drag=5.0, dt=0.1)
    p = resolve(scene.Parameters, None, ["level=1", "mechanics=overdamped-implicit", "contact_solve=explicit",
                                         "sharpness=0.1"])
    with pytest.raises(SceneError, match="contact_solve=implicit"):
        scene.build(p, device="cpu", report=QUIET)
