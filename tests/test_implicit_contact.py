"""The implicit ground (docs/theory/dynamics.md "Implicit contact and friction"): a block on a slope
against the closed forms of sliding friction — Coulomb's stick below tan θ = μ and slide at
g (sin θ - μ cos θ) above it; the regularised law's steady slip speed; the overdamped block's
friction balance at a drag far below what the explicit (lagged) contact allows."""

import math

import numpy as np
import pytest
import warp as wp
from scipy.optimize import brentq

from wavewarp.dynamics import Ground, OverdampedDynamics, ShellDynamics
from wavewarp.geometry import limit_positions
from wavewarp.kernels.contact import ground_motion, limit_transpose_kernel
from wavewarp.geometry import limit_coupling
from wavewarp.kernels.implicit_contact import (
    Coupling,
    contact_indicator_kernel,
    contact_velocity_kernel,
    eval_implicit_ground,
    implicit_contact_kernel,
    limit_coupled_velocity_kernel,
    limit_response_kernel,
)
from wavewarp.mesh import Mesh, cube
from wavewarp.shell import Shell

G, MU = 10.0, 0.5


def block_on_slope(tan_theta, *, sharpness=math.inf, solve="implicit", contact="point", young=1e6, drag=None,
                   sweeps=8, settle=2.0, drag_frame="lab", x0=None, dtype="float64", device="cpu"):  # fmt: skip
    """A 1 × 1 × 0.4 box (wide: it neither tips nor rocks) put down on a slope tan θ (or started at `x0`), run
    for `settle`."""
    box = cube(1.0, 4)
    mesh = Mesh(box.vertices * [1.0, 1.0, 0.4], box.triangles)
    shell = Shell(mesh, thickness=0.1, young=young, device=device, dtype=dtype)
    stiffness, damping = (1e4, 20.0) if contact == "point" else (1e4 * 25 / 2.8, 20.0 * 25 / 2.8)
    ground = Ground(stiffness=stiffness, damping=damping, friction=MU, sharpness=sharpness, solve=solve,
                    contact=contact, sweeps=sweeps, slope=math.atan(tan_theta))  # fmt: skip
    if x0 is None:
        x0 = mesh.vertices + [0.0, 0.0, -limit_positions(mesh, device="cpu", dtype="float64")[:, 2].min()]
    if drag is None:
        run = ShellDynamics(shell, density=1.0, gravity=G, ground=ground, damping=5.0, x0=x0)
    else:
        run = OverdampedDynamics(shell, density=1.0, gravity=G, ground=ground, drag=drag, x0=x0, drag_frame=drag_frame)
    run.run_until(settle)
    return run


def along_slope_velocity(run):
    return run.momentum()[0] / run.total_mass


@pytest.mark.parametrize("contact", ["point", pytest.param("area", marks=pytest.mark.slow)])
def test_coulomb_block_slides_down_a_steep_slope_at_the_closed_form_acceleration(contact):
    """tan θ = 0.7 > μ: a = g (sin θ - μ cos θ) once every contact point slides (measured to 1e-4)."""
    theta = math.atan(0.7)
    run = block_on_slope(0.7, contact=contact)
    start, v0 = run.time, along_slope_velocity(run)
    run.run_until(start + 1.0)
    acceleration = (along_slope_velocity(run) - v0) / (run.time - start)
    assert acceleration == pytest.approx(G * (math.sin(theta) - MU * math.cos(theta)), rel=2e-3)
    assert run.normal_forces().sum() == pytest.approx(run.total_mass * G * math.cos(theta), rel=1e-6)


def test_coulomb_block_kicked_on_flat_ground_slows_at_mu_g_and_stops_at_the_closed_form_distance():
    """v0 = 2 along the ground: Coulomb friction decelerates it at μ g while it slides, it stops after
    v0²/(2 μ g) and then stays (measured: deceleration 4.98, distance 0.396 of 0.4, 6e-6 left after a
    time unit; the slab's slight pitching accounts for the 1%)."""
    run = block_on_slope(0.0, settle=0.5)
    kick = np.zeros((run.shell.mesh.n_vertices, 3))
    kick[:, 0] = 2.0
    block = ShellDynamics(run.shell, density=1.0, gravity=G, ground=run.ground, damping=5.0, x0=run.positions(),
                          v0=run.velocities() + kick, dt=run.dt)  # fmt: skip
    start = block.center_of_mass()[0]
    times, speeds = [], []
    for _ in range(6):
        block.run_until(block.time + 0.05)
        times.append(block.time)
        speeds.append(along_slope_velocity(block))
    assert -np.polyfit(times[1:], speeds[1:], 1)[0] == pytest.approx(MU * G, rel=5e-3)
    block.run_until(block.time + 0.8)
    assert block.center_of_mass()[0] - start == pytest.approx(2.0**2 / (2 * MU * G), rel=0.02)
    assert abs(along_slope_velocity(block)) < 1e-4


@pytest.mark.slow
def test_coulomb_block_sticks_on_a_gentle_slope_and_the_sweeps_make_it_exact():
    """tan θ = 0.3 < μ: Coulomb's law holds the block. Solved point by point (no sweeps) it creeps at a speed of
    order dt g sin θ (each point's response is the contact set's row sum, not the whole body's); the Jacobi
    sweeps couple the points and the creep falls by orders of magnitude (measured 1.4e-3 → 8.7e-7 with 8)."""
    creep = {}
    for sweeps in (0, 8):
        run = block_on_slope(0.3, sweeps=sweeps)
        start = run.center_of_mass()[0]
        run.run_until(run.time + 1.0)
        creep[sweeps] = run.center_of_mass()[0] - start
    dt_pull = run.dt * G * math.sin(math.atan(0.3))
    assert 0 < creep[0] < 2 * dt_pull  # per unit time
    assert abs(creep[8]) < 1e-3 * creep[0]


@pytest.mark.parametrize("solve", ["implicit", "explicit"])
def test_regularised_friction_slides_at_the_closed_form_speed(solve):
    """k_f = 2, tan θ = 0.3: the steady slide balances μ N tanh(k_f v) = M g sin θ, v = atanh(tan θ / μ) / k_f."""
    k_f = 2.0
    run = block_on_slope(0.3, sharpness=k_f, solve=solve, settle=3.0)
    assert along_slope_velocity(run) == pytest.approx(math.atanh(0.3 / MU) / k_f, rel=1e-6)


def test_overdamped_coulomb_block_slides_at_the_friction_balance_far_below_the_explicit_drag_limit():
    """Overdamped, ζ M v = M g + f: on tan θ = 0.7 the block slides at g (sin θ - μ cos θ) / ζ, at a drag
    1/100 of the ground's damping per unit mass, which the explicit contact refuses."""
    drag, theta = 5.0, math.atan(0.7)
    steep = block_on_slope(0.7, young=1e3, drag=drag, settle=1.0, sweeps=32)
    assert drag < 0.01 * steep.contact_damping
    assert along_slope_velocity(steep) == pytest.approx(G * (math.sin(theta) - MU * math.cos(theta)) / drag, rel=1e-3)
    with pytest.raises(ValueError, match="does not exceed the ground's damping"):
        block_on_slope(0.3, young=1e3, drag=drag, solve="explicit", sharpness=2.0, settle=0.0)


@pytest.mark.slow
def test_overdamped_block_follows_the_regularised_friction_balance():
    """The steady slide v + (μ g cos θ / ζ) tanh(k_f v) = g sin θ / ζ (k_f = 2, tan θ = 0.3, ζ = η_ground/287).
    Without inertia the sweeps converge more slowly (slip speed off by 8%, 0.3%, 0.04% after 0, 8, 32
    sweeps)."""
    drag, k_f, theta = 5.0, 2.0, math.atan(0.3)
    run = block_on_slope(0.3, sharpness=k_f, young=1e3, drag=drag, settle=3.0, sweeps=32)
    balance = brentq(lambda v: v + MU * G * math.cos(theta) / drag * math.tanh(k_f * v) - G * math.sin(theta) / drag,
                     0.0, 10.0)  # fmt: skip
    assert along_slope_velocity(run) == pytest.approx(balance, rel=1e-3)


@pytest.fixture(scope="module")
def held():
    """The block's positions settled (inertial, Coulomb: it sticks) on tan θ = 0.3, its normal forces
    balancing g cos θ."""
    return block_on_slope(0.3, young=1e3, settle=3.0, sweeps=32).positions()


@pytest.mark.parametrize("drag", [5.0, pytest.param(61.0, marks=pytest.mark.slow)])
def test_body_frame_drag_leaves_the_slide_to_the_friction_balance_at_any_drag(held, drag):
    """Drag in the body frame brakes no translation: the block slides where μ N tanh(k_f v) = M g sin θ,
    v = atanh(tan θ / μ) / k_f, as with inertia and whatever ζ; in the lab frame the drag takes its share
    (v + (μ g cos θ / ζ) tanh(k_f v) = g sin θ / ζ)."""
    k_f, theta = 2.0, math.atan(0.3)
    body = block_on_slope(0.3, sharpness=k_f, young=1e3, drag=drag, settle=1.0, sweeps=16, drag_frame="body", x0=held)
    assert along_slope_velocity(body) == pytest.approx(math.atanh(0.3 / MU) / k_f, rel=5e-3)
    assert body.solver.body.velocity.numpy()[0, 0] == pytest.approx(along_slope_velocity(body), rel=1e-6)
    lab = brentq(lambda v: v + MU * G * math.cos(theta) / drag * math.tanh(k_f * v) - G * math.sin(theta) / drag, 0.0, 10.0)
    assert lab < 0.7 * along_slope_velocity(body)


def test_body_frame_coulomb_block_sticks_below_the_static_threshold(held):
    """tan θ = 0.3 < μ: nothing but Coulomb friction holds the block, and it holds (below 1e-3 of the k_f = 2 slide)."""
    body = block_on_slope(0.3, young=1e3, drag=5.0, settle=1.0, sweeps=16, drag_frame="body", x0=held)
    assert abs(along_slope_velocity(body)) < 1e-3 * math.atanh(0.3 / MU) / 2.0


def test_body_frame_drag_needs_friction_the_implicit_ground_and_a_slope_friction_can_hold():
    with pytest.raises(ValueError, match="implicit contact"):
        block_on_slope(0.0, young=1e3, drag=5.0, solve="explicit", sharpness=2.0, settle=0.0, drag_frame="body")
    with pytest.raises(ValueError, match="no friction can hold the body"):
        block_on_slope(0.7, young=1e3, drag=5.0, settle=0.0, drag_frame="body")
    with pytest.raises(ValueError, match="drag_frame must be 'lab' or 'body'"):
        block_on_slope(0.0, young=1e3, drag=5.0, settle=0.0, drag_frame="fluid")


def test_ground_refuses_coulomb_without_the_implicit_solve_and_bad_slopes_and_sweeps():
    with pytest.raises(ValueError, match="needs solve='implicit'"):
        Ground(sharpness=math.inf)
    Ground(sharpness=math.inf, solve="implicit")
    with pytest.raises(ValueError, match="between -π/2 and π/2"):
        Ground(slope=2.0)
    with pytest.raises(ValueError, match="sweeps must be an integer >= 0"):
        Ground(sweeps=-1)
    with pytest.raises(ValueError, match="solve must be 'explicit' or 'implicit'"):
        Ground(solve="backward")


def test_implicit_ground_leaves_the_stability_bound_to_the_shell_and_its_damping():
    """The explicit contact damping enters ζ = (η + η_ground)/2ω; the implicit one does not."""
    box = cube(1.0, 4)
    shell = Shell(box, thickness=0.1, young=1e4, device="cpu", dtype="float64")
    explicit = ShellDynamics(shell, density=1.0, ground=Ground(damping=50.0), damping=1.0)
    implicit = ShellDynamics(shell, density=1.0, ground=Ground(damping=50.0, solve="implicit"), damping=1.0,
                             omega=explicit.omega_max)  # fmt: skip
    free = ShellDynamics(shell, density=1.0, damping=1.0, omega=explicit.omega_max)
    assert implicit.stable_dt == pytest.approx(free.stable_dt, rel=1e-12)
    assert explicit.stable_dt < 0.5 * implicit.stable_dt
    assert np.isfinite(implicit.stable_dt)


def separate_launches(solver, x, v, scale, dt):
    """The implicit contact step on the limit points (lab frame) launch by launch: the contact set's indicator, Lᵀ of
    it into a zeroed buffer and the responses, the law alone; per sweep Lᵀ f, the coupled velocity and the law; then
    Lᵀ f and the velocity update. x, v updated; returns the points' forces."""
    n, s, ground = len(x), type(scale), solver.ground
    ring = [solver.mask.ring_start, solver.mask.ring, solver.mask.centre_weight, solver.mask.ring_weight]
    vec = x.dtype
    p, u, f, others, load = (wp.zeros(n, dtype=vec) for _ in range(5))
    response, normal = wp.zeros(n, dtype=s), wp.zeros(n, dtype=s)
    laws = [scale, s(dt), s(ground.stiffness), s(ground.damping), s(ground.friction), s(ground.sharpness)]
    body = wp.zeros(1, dtype=vec)
    ground_motion(ground, x, v, solver.mask, None, p, u)
    wp.launch(contact_indicator_kernel, n, inputs=[p], outputs=[f])
    wp.launch(limit_transpose_kernel, n, inputs=[f, *ring], outputs=[load])
    wp.launch(limit_response_kernel, n, inputs=[load, solver.inverse_mass, *ring], outputs=[response])
    wp.launch(implicit_contact_kernel, n, inputs=[p, u, response, *laws, body], outputs=[normal, f])
    for _ in range(ground.sweeps):
        load.zero_()
        wp.launch(limit_transpose_kernel, n, inputs=[f, *ring], outputs=[load])
        wp.launch(limit_coupled_velocity_kernel, n, inputs=[load, solver.inverse_mass, scale, *ring, u, response, f],
                  outputs=[others])  # fmt: skip
        wp.launch(implicit_contact_kernel, n, inputs=[p, others, response, *laws, body], outputs=[normal, f])
    load.zero_()
    wp.launch(limit_transpose_kernel, n, inputs=[f, *ring], outputs=[load])
    wp.launch(contact_velocity_kernel, n, inputs=[load, solver.inverse_mass, scale, s(dt)], outputs=[x, v])
    return f


def dense_coupling(solver) -> np.ndarray:
    """C = L M⁻¹ Lᵀ, dense, from the limit mask's rings (L_ii = centre weight, L_iJ = ring weight of i)."""
    mask, n = solver.mask, len(solver.mass)
    start, ring = mask.ring_start.numpy(), mask.ring.numpy()
    limit = np.diag(mask.centre_weight.numpy().astype(np.float64))
    for i in range(n):
        limit[i, ring[start[i]:start[i + 1]]] = mask.ring_weight.numpy()[i]
    return limit @ np.diag(1.0 / solver.mass) @ limit.T


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("sweeps", [0, 1, 2])
def test_one_launch_per_pass_equals_the_separate_launches(dtype, sweeps, device="cpu"):
    """On the limit points in the lab frame (the scenes' default) each pass of the implicit contact is one launch
    (kernels/implicit_contact.py `eval_limit_sweeps`) over the rows of C = L M⁻¹ Lᵀ formed once for the mesh
    (`limit_coupling`: checked against the dense product of the mask's rings). A block sliding down a slope
    (contact, Coulomb friction, points off the ground), one step from its predictor: the forces, velocities and
    positions of the separate launches, to round-off, and each contact point's response the row sum of C over the
    contact set (`device`: where a GPU is, the same check there)."""
    run = block_on_slope(0.7, sweeps=sweeps, settle=0.05, dtype=dtype, device=device)
    solver, dt = run.solver, run.dt
    scale = solver.scalar(dt)
    x, v = wp.clone(run.state.x), wp.empty_like(run.state.v)
    solver.predictor(x, run.state.v, dt, v)
    x_ref, v_ref = wp.clone(x), wp.clone(v)
    n = len(x)
    with wp.ScopedDevice(device):
        expected = separate_launches(solver, x_ref, v_ref, scale, dt)
        points, velocities, others, forces, load = (wp.zeros(n, dtype=x.dtype) for _ in range(5))
        response, normal = wp.zeros(n, dtype=solver.scalar), wp.zeros(n, dtype=solver.scalar)
        csr = limit_coupling(solver.shell.mesh, 1.0 / solver.mass)
        coupling = Coupling.of(csr, solver.scalar)
        eval_implicit_ground(solver.ground, x, v, solver.inverse_mass, dt, dt, solver.mask, None, None, points,
                             velocities, response, others, normal, forces, load, solver.body, coupling)  # fmt: skip
    sliding = np.linalg.norm(forces.numpy()[:, :2], axis=1)
    assert (sliding > 0).sum() >= 4 and (normal.numpy() == 0).sum() > n // 2  # friction acts; most points are off
    tolerance = 1e-12 if dtype == "float64" else 2e-5
    for got, want in ((forces, expected), (v, v_ref), (x, x_ref)):
        want = want.numpy()
        np.testing.assert_allclose(got.numpy(), want, rtol=0, atol=tolerance * np.abs(want).max())
    dense = dense_coupling(solver)
    start, point, value = csr
    rebuilt = np.zeros_like(dense)
    rebuilt[np.repeat(np.arange(n), np.diff(start)), point] = value
    exact = 1e-15 if dtype == "float64" else 1e-6  # float32: the mask's weights are rounded
    np.testing.assert_allclose(rebuilt, dense, rtol=0, atol=exact * np.abs(dense).max())
    contact = points.numpy()[:, 2] <= 0
    assert contact.sum() >= 4 and (response.numpy()[~contact] == 0).all()
    np.testing.assert_allclose(response.numpy()[contact], dense[contact][:, contact].sum(axis=1), rtol=tolerance)
