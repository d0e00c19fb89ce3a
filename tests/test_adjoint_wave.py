"""The sensitive wave's adjoint pieces (kernels/adjoint_wave.py, wavewarp/adjoint_wave.py): the operator's forms'
dependence on the positions, one explicit FitzHugh–Nagumo step with the mass corrections and the transport, the
reference's dependence on the concentrations, and the initial pulse's on the surface — each against central
differences of the forward computation (float64)."""

from types import SimpleNamespace

import numpy as np
import pytest
import warp as wp

from wavewarp.adjoint_wave import WaveAdjoint
from wavewarp.chemistry import FitzHughNagumoSolver
from wavewarp.initial import gaussian_pulse, gaussian_pulse_adjoint
from wavewarp.kernels.adjoint import ShellRates
from wavewarp.kernels.adjoint_wave import eval_gather_point_factors, eval_operator_position_adjoint
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.shell import Shell


def deformed_sphere(level=2, seed=3):
    mesh, rng = icosphere(1.0, level=level), np.random.default_rng(seed)
    return mesh, rng, mesh.vertices + 0.03 * rng.standard_normal(mesh.vertices.shape)


def forms(operator, x, u, v, m, stiffness, mass) -> float:
    """κ_K u K v + κ_M u M_c v + m·M_L on the surface at x."""
    operator.update(x)
    return stiffness * u @ operator.apply(v) + mass * u @ (operator.mass_matrix() @ v) + m @ operator.mass()


@pytest.mark.parametrize("floor", [False, True], ids=["metric", "floored"])
def test_the_forms_position_adjoint_matches_central_differences(floor):
    """x̂ of the stiffness, consistent and lumped mass forms along a random direction; `floored`: every point below
    the area floor of D (D = adj(a) w / j_floor, the singular surface's branch)."""
    mesh, rng, x = deformed_sphere()
    operator = LaplaceBeltrami(mesh, x, assembled=False, device="cpu", dtype="float64")
    if floor:
        operator.j_floor.assign(10.0 * np.ones(operator.tables.n_quadrature_points))
    u, v, m = (rng.standard_normal(len(x)) for _ in range(3))
    direction = rng.standard_normal(x.shape)
    x_hat = wp.zeros(len(x), dtype=wp.vec3d, device="cpu")
    arrays = [wp.array(a, dtype=wp.float64, device="cpu") for a in (u, v, m)]
    operator.update(x)
    eval_operator_position_adjoint(wp.array(x, dtype=wp.vec3d, device="cpu"), *arrays, 0.7, -1.3, operator.tables,
                                   operator.j_floor, x_hat)
    step = 1e-6
    ends = [forms(operator, x + sign * step * direction, u, v, m, 0.7, -1.3) for sign in (1.0, -1.0)]
    assert np.sum(x_hat.numpy() * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-7)


def chemistry_step(solver, c, w, x, x_next) -> tuple:
    """One explicit FHN step from (c, w) on the surface at x, then the transport to x_next: (c', w')."""
    solver.operator.update(x)
    state = solver.state(c, w)
    solver.step(state, state, 0.4)
    solver.move_surface(state, x_next)
    return state.c.numpy(), state.w.numpy()


@pytest.mark.parametrize("transport, corrections", [("conservative", 2), ("material", 2), ("conservative", 0)])
def test_one_wave_step_backwards_matches_central_differences(transport, corrections):
    """J = a·c' + b·w' of one explicit step on the moving surface: its gradients in c, w, x (the step's surface) and
    x' (the next, through the transport) along random directions."""
    mesh, rng, x = deformed_sphere(level=1)
    x_next = x + 0.01 * rng.standard_normal(x.shape)
    operator = LaplaceBeltrami(mesh, x, assembled=False, device="cpu", dtype="float64")
    solver = FitzHughNagumoSolver(operator, mass_corrections=corrections, transport=transport)
    c, w = rng.uniform(0.0, 1.0, len(x)), 0.1 * rng.uniform(0.0, 1.0, len(x))
    a, b = rng.standard_normal(len(x)), rng.standard_normal(len(x))
    adjoint = WaveAdjoint(SimpleNamespace(solver=solver, operator=operator, dt=0.4), operator.tables)
    adjoint.c_hat.assign(a)
    adjoint.w_hat.assign(b)
    x_hat, x_next_hat = (wp.zeros(len(x), dtype=wp.vec3d, device="cpu") for _ in range(2))
    arrays = [wp.array(values, dtype=wp.float64, device="cpu") for values in (c, w)]
    positions = [wp.array(values, dtype=wp.vec3d, device="cpu") for values in (x, x_next)]
    adjoint.recompute(*arrays, positions[0])
    adjoint.transport_back(positions[1], x_next_hat)
    adjoint.step_back(arrays[0], positions[0], x_hat)

    def objective(c, w, x, x_next):
        c_next, w_next = chemistry_step(solver, c, w, x, x_next)
        return a @ c_next + b @ w_next

    start = {"c": c, "w": w, "x": x, "x_next": x_next}
    gradients = {"c": adjoint.c_hat.numpy(), "w": adjoint.w_hat.numpy(), "x": x_hat.numpy(),
                 "x_next": x_next_hat.numpy()}  # fmt: skip
    for name, gradient in gradients.items():
        direction, step = rng.standard_normal(gradient.shape), 1e-6
        ends = [objective(**{**start, name: start[name] + sign * step * direction}) for sign in (1.0, -1.0)]
        assert np.sum(gradient * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-7), name


@pytest.mark.parametrize("model", ["koiter", "bilayer"])
def test_the_references_concentration_adjoint_matches_central_differences_of_the_forces(model):
    """-∂Ė/∂c per quadrature point, split by the ramp and gathered to the control values: Σ of both parts along a
    random direction e of c against central differences of d·F(x; c ± δe), and the split (1 - ramp) : ramp."""
    mesh, rng, x = deformed_sphere(level=1)
    shell = Shell(mesh, 0.05, 3.0, AC=0.3, AI=0.7, volume_penalty=5.0, model=model, dtype="float64", device="cpu")
    c, direction, e = rng.uniform(0.0, 1.0, len(x)), rng.standard_normal(x.shape), rng.standard_normal(len(x))
    points = shell.tables.n_quadrature_points
    by = (wp.zeros(points, dtype=wp.vec3d, device="cpu"), wp.zeros(points, dtype=wp.vec3d, device="cpu"))
    shell.rates_device(shell._set(x, c), wp.array(direction, dtype=wp.vec3d, device="cpu"),
                       wp.zeros(1, dtype=ShellRates, device="cpu"), by, 0.25)
    gathered = []
    for values in by:
        out = wp.zeros(len(x), dtype=wp.float64, device="cpu")
        eval_gather_point_factors(values, shell.tables, wp.empty_like(out), out)
        gathered.append(out.numpy())
    step = 1e-6
    ends = [np.sum(shell.forces(x, c + sign * step * e) * direction) for sign in (1.0, -1.0)]
    assert np.sum((gathered[0] + gathered[1]) * e) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-7)
    assert np.allclose(gathered[0], 3.0 * gathered[1], rtol=1e-12, atol=0.0)


def test_the_pulse_adjoint_matches_central_differences_of_the_pulse_on_a_moved_surface():
    """c₀ = gaussian_pulse on the surface at x: (∂c₀/∂x)ᵀ ĉ along a random direction, and ĉ·∂c₀/∂σ."""
    mesh, rng, x = deformed_sphere(level=1)
    operator = LaplaceBeltrami(mesh, x, device="cpu", dtype="float64")
    c_hat, direction = rng.standard_normal(len(x)), rng.standard_normal(x.shape)

    def pulse(x, sigma=0.4):
        operator.update(x)
        return gaussian_pulse(operator, 5, sigma, gamma=0.2, radius=1.1)[0]

    step = 1e-6
    ends = [c_hat @ pulse(x + sign * step * direction) for sign in (1.0, -1.0)]
    x_hat, sigma_hat = gaussian_pulse_adjoint(mesh, x, 5, 0.4, c_hat, radius=1.1)
    assert np.sum(x_hat * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-7)
    ends = [c_hat @ pulse(x, 0.4 + sign * step) for sign in (1.0, -1.0)]
    assert sigma_hat == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-7)
