"""Walker mechanics (docs/theory/dynamics.md, §4, §8 "Contact"): shell dynamics, gravity, ground
contact and friction, each against an answer known in advance."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from wavewarp.dynamics import Ground, OverdampedDynamics, ShellDynamics
from wavewarp.geometry import limit_positions, limit_surface
from wavewarp.mesh import cube, icosphere
from wavewarp.shell import Shell
from wavewarp.waves import BlowUpError, TimeStepError

F64 = dict(device="cpu", dtype="float64")


def dense_largest_frequency(shell, mass, step=1e-6):
    """√λ_max(M⁻¹H) from a dense finite-difference Hessian (independent of the stepper's Lanczos)."""
    x0 = shell.mesh.vertices
    n = len(x0)
    H = np.empty((3 * n, 3 * n))
    for j in range(3 * n):
        dx = np.zeros(3 * n)
        dx[j] = step
        H[:, j] = (shell.forces(x0 - dx.reshape(n, 3)) - shell.forces(x0 + dx.reshape(n, 3))).ravel() / (2 * step)
    scale = np.repeat(1 / np.sqrt(mass), 3)
    return math.sqrt(np.linalg.eigvalsh(0.5 * (H + H.T) * scale[:, None] * scale[None, :]).max())


def test_stability_bound_is_the_largest_frequency_and_sharp(rng):
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, thickness=0.1, young=1000.0, **F64)
    v0 = 1e-3 * rng.standard_normal((mesh.n_vertices, 3))
    dynamics = ShellDynamics(shell, density=1.0, v0=v0)
    assert dynamics.omega_max == pytest.approx(dense_largest_frequency(shell, dynamics.mass), rel=1e-6)
    assert dynamics.stable_dt == pytest.approx(2 / dynamics.omega_max, rel=1e-12)  # no damping
    assert dynamics.dt == pytest.approx(0.9 * dynamics.stable_dt)
    below = ShellDynamics(shell, density=1.0, v0=v0, dt=0.97 * dynamics.stable_dt)
    energy = below.kinetic_energy()
    below.advance(3000)
    assert below.kinetic_energy() < 3 * energy  # bounded oscillation
    above = ShellDynamics(shell, density=1.0, v0=v0, dt=1.03 * dynamics.stable_dt, check_dt=False)
    with pytest.raises(BlowUpError, match="blew up") as error:
        above.advance(3000)
    assert np.all(np.isfinite(above.positions())) and above.time == error.value.time  # restored, no NaN kept
    with pytest.raises(TimeStepError, match="exceeds the stability bound"):
        ShellDynamics(shell, density=1.0, dt=1.03 * dynamics.stable_dt)


def test_damping_lowers_the_bound_as_predicted(rng):
    """Damped symplectic Euler on the top mode: dt < 2/ω (√(1+ζ²) - ζ) (docs/theory/scenes.md stability)."""
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, thickness=0.1, young=1000.0, **F64)
    free = ShellDynamics(shell, density=1.0)
    eta = 2.0 * free.omega_max  # ζ = 1: the bound falls to 2/ω (√2 - 1)
    damped = ShellDynamics(shell, density=1.0, damping=eta)
    assert damped.stable_dt == pytest.approx(2 / free.omega_max * (math.sqrt(2) - 1), rel=1e-9)
    v0 = 1e-3 * rng.standard_normal((mesh.n_vertices, 3))
    assert not runs_away(ShellDynamics(shell, density=1.0, damping=eta, v0=v0, dt=0.97 * damped.stable_dt))
    assert runs_away(ShellDynamics(shell, density=1.0, damping=eta, v0=v0, dt=1.05 * damped.stable_dt, check_dt=False))


def runs_away(run, steps=2000):
    """True when `steps` steps blow up or multiply the kinetic energy by more than 10⁶."""
    energy = run.kinetic_energy()
    try:
        run.advance(steps)
    except BlowUpError:
        return True
    return run.kinetic_energy() > 1e6 * energy


def test_free_shell_conserves_momentum_and_angular_momentum(device, rng):
    """No ground, no gravity: internal forces (here driven by a random active reference) exert no net
    force or torque; symplectic Euler then keeps P exactly and L = Σ M x × v exactly (the torque
    at x_n vanishes); the damping, relative to the rigid-body motion, keeps both."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, thickness=0.1, young=100.0, AC=0.3, AI=0.5, device=device, dtype="float64")
    c = rng.uniform(0, 1, mesh.n_vertices)
    v0 = 0.1 * rng.standard_normal((mesh.n_vertices, 3))
    for damping in (0.0, 3.0):
        run = ShellDynamics(shell, density=1.0, c=c, v0=v0, damping=damping)
        p0 = run.momentum()
        L0 = np.sum(run.mass[:, None] * np.cross(run.positions(), run.velocities()), axis=0)
        run.advance(500)
        assert np.abs(run.positions() - mesh.vertices).max() > 1e-2  # it deformed
        scale = np.sum(run.mass) * np.abs(run.velocities()).max()
        assert np.abs(run.momentum() - p0).max() <= 1e-12 * scale
        L = np.sum(run.mass[:, None] * np.cross(run.positions(), run.velocities()), axis=0)
        assert np.abs(L - L0).max() <= 1e-11 * scale


def test_a_new_rest_volume_reaches_the_captured_dynamics_steps(device):
    """V̄ is a launch argument of the force step, and the steps run as a captured graph (a CUDA graph,
    or Warp's CPU graph): a V̄ set after the first steps must reach the next ones (the shell's
    revision drops the graph). The reference: a stepper built afresh with the new V̄ from the same
    state."""
    mesh = icosphere(1.0, 2)

    def stepper(rest_volume=None, x0=None, v0=None, dt=None, omega=None):
        shell = Shell(mesh, thickness=0.1, young=100.0, volume_penalty=50.0, deterministic=True, device=device,
                      dtype="float64")  # fmt: skip
        if rest_volume is not None:
            shell.rest_volume = rest_volume
        return shell, ShellDynamics(shell, density=1.0, x0=x0, v0=v0, damping=1.0, dt=dt, omega=omega)

    shell, run = stepper()
    bound = dict(dt=run.dt, omega=run.omega_max)  # one time step for all three
    run.advance(20)
    x, v = run.positions(), run.velocities()
    new_volume = 0.8 * shell.rest_volume
    shell.rest_volume = new_volume
    run.advance(20)
    _, fresh = stepper(new_volume, x, v, **bound)
    fresh.advance(20)
    _, stale = stepper(None, x, v, **bound)
    stale.advance(20)
    assert np.abs(stale.positions() - fresh.positions()).max() > 1e-4  # the new V̄ moves the shell
    np.testing.assert_allclose(run.positions(), fresh.positions(), rtol=0, atol=1e-12)


def test_external_forces_match_the_formulas_on_the_limit_points(device, rng):
    """Gravity -M g ẑ on control points; contact and friction evaluated by NumPy on the limit points
    p = L x, u = L v (limit_positions is linear); Lᵀ keeps their sum (rows of L sum to 1)."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, thickness=0.1, young=100.0, device=device, dtype="float64")
    ground = Ground(stiffness=50.0, damping=0.7, friction=0.3, sharpness=2.0)
    x = mesh.vertices + [0.0, 0.0, 0.9] + 0.02 * rng.standard_normal((mesh.n_vertices, 3))
    v = rng.standard_normal((mesh.n_vertices, 3))
    run = ShellDynamics(shell, density=2.0, gravity=1.5, ground=ground, x0=x, v0=v)
    p, u = limit_positions(mesh, x, **F64), limit_positions(mesh, v, **F64)
    z = p[:, 2]
    fn = np.where(z <= 0, np.maximum(ground.stiffness * z**2 - ground.damping * u[:, 2], 0.0), 0.0)
    speed = np.linalg.norm(u[:, :2], axis=1)
    friction = -ground.friction * fn * np.tanh(ground.sharpness * speed) / speed
    assert (fn > 0).sum() >= 3 and (np.where(z <= 0, 1, 0) > (fn > 0)).any()  # some contacts, some pulled off
    np.testing.assert_allclose(run.normal_forces(), fn, rtol=1e-12, atol=1e-14)
    total = np.array([np.sum(friction * u[:, 0]), np.sum(friction * u[:, 1]), fn.sum() - 1.5 * run.total_mass])
    np.testing.assert_allclose(run.external_forces().sum(axis=0), total, rtol=1e-10, atol=1e-12)
    area = limit_surface(mesh, rule=shell.rule, **F64).total_area
    assert run.total_mass == pytest.approx(2.0 * area, rel=1e-12)  # M_I = ρ ∫ N_I dω̄⁰


def settle_on_ground(mesh, young, *, g=1.0, k=1e4, friction=0.1, until=20.0, dtype="float64"):
    shell = Shell(mesh, thickness=0.1, young=young, device="cpu", dtype=dtype)
    lift = -limit_positions(mesh, **F64)[:, 2].min()
    run = ShellDynamics(shell, density=1.0, gravity=g, ground=Ground(stiffness=k, damping=20.0, friction=friction),
                        damping=5.0, x0=mesh.vertices + [0.0, 0.0, lift])  # fmt: skip
    run.run_until(until)
    return run, lift


def test_nearly_rigid_ball_settles_where_contact_carries_its_weight():
    """docs/theory/scenes.md: at rest Σ k z_i² = total weight; the height matches a rigid ball's (root of
    Σ k min(z_i + s, 0)² = W over the rest limit points), up to the elastic sag ∝ 1/Y."""
    mesh, g, k = icosphere(1.0, 2), 1.0, 1e4
    z = limit_positions(mesh, **F64)[:, 2]
    gaps = []
    for young in (1e5, 1e6):
        run, lift = settle_on_ground(mesh, young, g=g, k=k)
        weight = run.total_mass * g
        assert run.kinetic_energy() < 1e-9 * weight
        assert run.normal_forces().sum() == pytest.approx(weight, rel=1e-4)
        shift = brentq(lambda s: k * np.sum(np.minimum(z + s, 0.0) ** 2) - weight, lift - 0.5, lift)
        rigid = shift + run.mass @ mesh.vertices[:, 2] / run.total_mass
        gaps.append(rigid - run.center_of_mass()[2])
    depth = lift - shift  # the rigid ball's penetration
    assert 0 < gaps[1] < 0.05 * depth
    assert 5 < gaps[0] / gaps[1] < 20  # the sag falls tenfold with a tenfold Y


def test_sliding_block_decelerates_at_mu_g():
    """docs/theory/scenes.md: with k_f |v_t| ≫ 1 friction is Coulomb's, the block slows at μ g."""
    g, mu, speed = 10.0, 0.5, 100.0  # k_f v ≥ 7.5 over the run: tanh = 1 - 6e-7
    run, _ = settle_on_ground(cube(1.0, 4), 1e6, g=g, friction=mu, until=3.0)
    kick = np.zeros((run.shell.mesh.n_vertices, 3))
    kick[:, 0] = speed
    sliding = ShellDynamics(run.shell, density=1.0, gravity=g, ground=run.ground, damping=5.0, x0=run.positions(),
                            v0=run.velocities() + kick, dt=run.dt)  # fmt: skip
    times, velocity = [], []
    for _ in range(20):
        sliding.run_until(sliding.time + 0.25)
        times.append(sliding.time)
        velocity.append(sliding.momentum()[0] / sliding.total_mass)
    slope = np.polyfit(times, velocity, 1)[0]
    assert -slope == pytest.approx(mu * g, rel=2e-3)


@pytest.mark.parametrize("dtype, bound", [("float64", 1e-12), ("float32", 1e-5)])
def test_shell_at_rest_on_the_ground_stays_put(dtype, bound):
    """No wave: a ball resting on a vertex (a 5-fold symmetric contact, an equilibrium) moves less
    than `bound` R along the ground over 10⁴ steps after settling (measured 2e-15 in float64,
    1.2e-7 in float32). Placed on an asymmetric spot it first rocks to an equilibrium, slowly: the
    tanh friction is viscous at low speed, drag μ k_f g per unit mass (docs/theory/dynamics.md)."""
    mesh = icosphere(1.0, 2)
    apex = mesh.vertices[np.flatnonzero(mesh.valence == 5)[0]]  # one of the icosahedron's twelve
    run, _ = settle_on_ground(mesh.turned(apex, [0.0, 0.0, -1.0]), 1e5, until=25.0, dtype=dtype)
    start = run.center_of_mass()
    run.advance(10000)
    drift = run.center_of_mass() - start
    assert np.linalg.norm(drift[:2]) < bound
    assert abs(drift[2]) < max(bound, 1e-6)  # the last of the vertical settling


# ---------------------------------------------------------------- overdamped mobility model


def test_overdamped_free_fall_moves_every_point_at_the_terminal_velocity():
    """ζ M v = -M g ẑ alone: every point falls at g/ζ from the first step, the shape unchanged."""
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, thickness=0.1, young=1000.0, **F64)
    run = OverdampedDynamics(shell, density=0.7, drag=40.0, gravity=2.0)
    run.advance(50)
    expected = mesh.vertices - [0.0, 0.0, 2.0 / 40.0 * run.time]
    np.testing.assert_allclose(run.positions(), expected, rtol=0, atol=1e-13)
    np.testing.assert_allclose(run.velocities(), np.tile([0.0, 0.0, -2.0 / 40.0], (mesh.n_vertices, 1)), atol=1e-13)


def test_overdamped_centre_of_mass_moves_with_the_net_external_force(device, rng):
    """Summed over the points the internal forces drop out: Σ M v = (gravity + contact + friction)/ζ at
    the state the step starts from, every step, while a random active reference deforms the shell."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, thickness=0.1, young=100.0, AC=0.3, AI=0.5, device=device, dtype="float64")
    ground = Ground(stiffness=50.0, damping=0.7, friction=0.3, sharpness=2.0)
    lift = -limit_positions(mesh, **F64)[:, 2].min()
    run = OverdampedDynamics(shell, density=1.0, gravity=1.5, ground=ground, c=rng.uniform(0, 1, mesh.n_vertices),
                             x0=mesh.vertices + [0.0, 0.0, lift - 0.02])  # fmt: skip
    assert run.drag == pytest.approx(2 * run.contact_damping)
    for _ in range(3):
        run.advance(20)  # the shell deforms and slips: contact and friction see a velocity
        external = run.external_forces().sum(axis=0)  # at (x_n, v_(n-1)): what the next step sees
        assert (run.normal_forces() > 0).sum() >= 3 and np.abs(external[:2]).max() > 0
        run.advance(1)
        np.testing.assert_allclose(run.momentum(), external / run.drag, rtol=1e-10, atol=1e-12 * run.total_mass)


def test_overdamped_stability_bound_is_two_drag_over_omega_squared_and_sharp(rng):
    """Explicit Euler on ζ ẋ = -ω² x: |1 - dt ω²/ζ| < 1, i.e. dt < 2ζ/ω²: stable at 0.97, runs away at 1.03."""
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, thickness=0.1, young=1000.0, **F64)
    x0 = mesh.vertices + 1e-4 * rng.standard_normal((mesh.n_vertices, 3))
    run = OverdampedDynamics(shell, density=1.0, drag=30.0)  # ω at the rest state, as the dense Hessian
    omega = dense_largest_frequency(shell, run.mass)
    assert run.stable_dt == pytest.approx(2 * 30.0 / omega**2, rel=1e-6)
    stable = OverdampedDynamics(shell, density=1.0, drag=30.0, x0=x0, dt=0.97 * run.stable_dt)
    stable.advance(3000)
    assert np.abs(stable.velocities()).max() < 1e-3 * 1e-4 / stable.dt  # decayed
    unstable = OverdampedDynamics(shell, density=1.0, drag=30.0, x0=x0, dt=1.03 * run.stable_dt, check_dt=False)
    assert runs_away(unstable, steps=3000)
    with pytest.raises(TimeStepError, match=r"dt < 2ζ/ω²"):
        OverdampedDynamics(shell, density=1.0, drag=30.0, dt=1.03 * run.stable_dt)


def test_overdamped_gradient_flow_reaches_the_closed_form_radius():
    """No ground, no gravity: the mobility model is a gradient flow and comes to rest at the
    quasi-static equilibrium: under uniform c, the closed-form sphere radius (docs/theory/scenes.md)."""
    from wavewarp.benchmarks.accuracy_cases import closed_form_stretch

    R, h, AC, AI = 1.0, 0.05, 0.3, 0.5
    mesh = icosphere(R, 3)
    shell = Shell(mesh, thickness=h, young=1.0, AC=AC, AI=AI, **F64)
    run = OverdampedDynamics(shell, density=1.0, drag=1.0, c=np.ones(mesh.n_vertices))
    run.advance(4000)
    stretch = closed_form_stretch(AC, AI, h, 0.0, "koiter")
    radius = np.linalg.norm(limit_positions(mesh, run.positions(), **F64), axis=1).mean()
    assert abs(radius / R - stretch) <= 1e-3 * abs(1 - stretch)
    assert np.abs(run.velocities()).max() < 1e-6 * R / run.dt  # at rest


def test_overdamped_refuses_a_drag_the_lagged_contact_cannot_follow():
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, thickness=0.1, young=1000.0, **F64)
    ground = Ground(damping=5.0)
    eta = ShellDynamics(shell, density=1.0, ground=ground).contact_damping
    with pytest.raises(ValueError, match="does not exceed the ground's damping per unit mass"):
        OverdampedDynamics(shell, density=1.0, ground=ground, drag=0.9 * eta)
    with pytest.raises(ValueError, match="there is no ground: give the drag"):
        OverdampedDynamics(shell, density=1.0)
    with pytest.raises(ValueError, match="no background damping"):
        OverdampedDynamics(shell, density=1.0, drag=1.0, damping=0.1)


# ---------------------------------------------------------------- per-area contact


def test_area_contact_is_the_pressure_law_on_the_quadrature_points(device, rng):
    """Ground(contact="area"): the docs/theory/dynamics.md law as a pressure at the quadrature points, p_q and u_q
    the limit surface's points at x and v (NumPy through `limit_surface`, linear in x), spread back
    with the basis: the same total force Σ_q f_q dω̄⁰_q and the same virtual work Σ_q f_q·u_q dω̄⁰_q."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, thickness=0.1, young=100.0, device=device, dtype="float64")
    ground = Ground(stiffness=500.0, damping=7.0, friction=0.3, sharpness=2.0, contact="area")
    x = mesh.vertices + [0.0, 0.0, 0.9] + 0.02 * rng.standard_normal((mesh.n_vertices, 3))
    v = rng.standard_normal((mesh.n_vertices, 3))
    run = ShellDynamics(shell, density=2.0, ground=ground, x0=x, v0=v)
    p, u = limit_surface(mesh, x, **F64).points, limit_surface(mesh, v, **F64).points
    area = limit_surface(mesh, **F64).area  # dω̄⁰
    z = p[:, 2]
    pressure = np.where(z <= 0, np.maximum(ground.stiffness * z**2 - ground.damping * u[:, 2], 0.0), 0.0)
    speed = np.linalg.norm(u[:, :2], axis=1)
    traction = np.zeros_like(p)
    traction[:, :2] = -(ground.friction * pressure * np.tanh(ground.sharpness * speed) / speed)[:, None] * u[:, :2]
    traction[:, 2] = pressure
    assert (pressure > 0).sum() >= 3 and ((z <= 0) & (pressure == 0)).any()  # some contacts, some pulled off
    np.testing.assert_allclose(run.normal_forces(), pressure * area, rtol=1e-12, atol=1e-14)
    forces = run.external_forces()
    scale = np.abs(traction * area[:, None]).sum()
    np.testing.assert_allclose(forces.sum(axis=0), (traction * area[:, None]).sum(axis=0), rtol=0, atol=1e-12 * scale)
    work = np.sum(traction * u * area[:, None])
    assert np.sum(forces * v) == pytest.approx(work, rel=1e-11)
    assert run.contact_damping == pytest.approx(ground.damping / 2.0)  # β/ρ: max_J ∫ N_J dω̄⁰ / M_J = 1/ρ


@pytest.mark.slow
def test_area_contact_ball_settles_where_the_pressure_carries_its_weight():
    """At rest Σ_q F_n = W; the height matches the rigid ball's root of Σ_q k min(z_q + s, 0)² dω̄⁰_q = W,
    up to the elastic sag."""
    mesh, g, k = icosphere(1.0, 2), 1.0, 1e5
    surface = limit_surface(mesh, **F64)
    z, area = surface.points[:, 2], surface.area
    shell = Shell(mesh, thickness=0.1, young=1e6, device="cpu", dtype="float64")
    lift = -limit_positions(mesh, **F64)[:, 2].min()
    ground = Ground(stiffness=k, damping=300.0, friction=0.1, contact="area")
    run = ShellDynamics(shell, density=1.0, gravity=g, ground=ground, damping=5.0, x0=mesh.vertices + [0.0, 0.0, lift])
    run.run_until(20.0)
    weight = run.total_mass * g
    assert run.kinetic_energy() < 1e-9 * weight
    assert run.normal_forces().sum() == pytest.approx(weight, rel=1e-4)
    shift = brentq(lambda s: k * np.sum(area * np.minimum(z + s, 0.0) ** 2) - weight, lift - 0.5, lift)
    rigid = shift + run.mass @ mesh.vertices[:, 2] / run.total_mass
    assert 0 < rigid - run.center_of_mass()[2] < 0.05 * (lift - shift)
