"""The overdamped coupling (docs/theory/transport.md, "Couplings"): each step is the backward-Euler step of
ζ ṗ = f per unit rest area, a minimization of E + ½ (ζ/Δt) ∫ |p − a|² dω̄⁰ (wavewarp/drag.py).

The answer known in advance: under a uniform concentration a sphere stays a sphere of radius λR, and the drag's
energy is ½ (ζ/Δt) (λ − λₙ)² ∫ |P|² dω̄⁰ = ½ (ζ/Δt) (λ − λₙ)² 4πR⁴ (P the rest limit points, |P| = R): the shell's
steps are the scalar backward-Euler steps of the closed-form sphere energy E(λ) (tests/test_shell.py), and they tend
to its quasi-static minimizer as ζ/Δt → 0.
"""

import math

import numpy as np
import pytest
import warp as wp
from scipy.optimize import minimize_scalar

from wavewarp.coupled import FoldError, QuasiStatic
from wavewarp.drag import Drag
from wavewarp.geometry import limit_positions
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.shell import Shell
from wavewarp.waves import Telegraph

R, H, YOUNG, NU, AC, AI = 2.0, 0.1, 1.0, 0.33, 0.5, 0.3


def sphere_energy(lam, c=1.0, mu_v=0.0):
    """E(λ) of a sphere of radius λR under uniform c (docs/theory/scenes.md; tests/test_shell.py)."""
    s, k = math.exp(-AC * c), 1 - AI * c
    membrane = (lam**2 - s) ** 2 / s
    bending = H**2 / (3 * R**2) * (lam - k) ** 2 / s
    volume = mu_v * (4 / 3 * math.pi * R**3 * (lam**3 - 1)) ** 2
    return math.pi * R**2 * YOUNG * H / (1 - NU) * (membrane + bending) + volume


def backward_euler(lam, coefficient, mu_v=0.0):
    """The scalar step: argmin E(λ) + ½ (ζ/Δt) (λ − λₙ)² 4πR⁴."""

    def stepped(x):
        return sphere_energy(x, mu_v=mu_v) + 0.5 * coefficient * (x - lam) ** 2 * 4 * math.pi * R**4

    return minimize_scalar(stepped, bounds=(0.3, 1.5), method="bounded", options={"xatol": 1e-13}).x


def radius(mesh, x, device):
    return float(np.linalg.norm(limit_positions(mesh, x, device=device, dtype="float64"), axis=1).mean() / R)


@pytest.mark.parametrize("ratio", [0.05, 1.0, 20.0])
def test_overdamped_steps_are_the_backward_euler_steps_of_the_sphere_energy(ratio, device):
    """ζ/Δt in units of the membrane stiffness Y h / R⁴ per rest area: the shell's radius after each of three steps
    equals the scalar backward-Euler sequence to the level-3 discretization (1e-3 of the contraction)."""
    mesh = icosphere(R, 3)
    shell = Shell(mesh, H, YOUNG, poisson=NU, AC=AC, AI=AI, device=device, dtype="float64")
    coefficient = ratio * YOUNG * H / R**4
    drag = Drag(shell, drag=coefficient * 0.5)
    drag.set_interval(0.5)
    shell.terms = (drag,)
    quasi_static = backward_euler(1.0, 0.0)
    x, lam = mesh.vertices, 1.0
    for _ in range(3):
        drag.begin_step(shell_positions(shell, x))
        x = shell.relax(x, 1.0, method="ncg")
        lam = backward_euler(lam, coefficient)
        assert abs(radius(mesh, x, device) - lam) <= 1e-3 * abs(1 - quasi_static)


def shell_positions(shell, x):
    return wp.array(np.asarray(x, dtype=np.float64), dtype=shell.vec3, device=shell.device)


def test_a_vanishing_drag_is_the_quasi_static_coupling_and_a_stiff_one_barely_moves(device):
    """QuasiStatic with drag ζ → 0 takes the quasi-static step; with a large ζ the first step moves the radius by
    the scalar backward-Euler step, part of the way."""
    mesh = icosphere(R, 3)

    def first_step(drag):
        shell = Shell(mesh, H, YOUNG, poisson=NU, AC=AC, AI=AI, device=device, dtype="float64")
        wave = Telegraph(
            LaplaceBeltrami(mesh, device=device, dtype="float64"), 1.0, c0=np.zeros(mesh.n_vertices), dt=0.05
        )
        coupled = QuasiStatic(shell, wave, drag=drag)
        wave.state.c.fill_(1.0)  # a uniform step of c (K·1 = 0 keeps it uniform)
        coupled.step()
        return radius(mesh, coupled.positions(), device)

    quasi_static = backward_euler(1.0, 0.0)
    assert abs(first_step(1e-9) - quasi_static) <= 1e-3 * abs(1 - quasi_static)
    zeta = 50 * YOUNG * H / R**4 * 0.05
    moved = first_step(zeta)
    assert abs(moved - backward_euler(1.0, zeta / 0.05)) <= 1e-3 * abs(1 - quasi_static)
    assert 0 < (1 - moved) / (1 - quasi_static) < 0.5


def test_the_float32_newton_finish_carries_the_drag_on_its_float64_twin():
    """CG given one iteration hands over to the Newton finish, which works on the float64 twin with the drag's own
    twin: the result is the backward-Euler step, not the quasi-static minimizer."""
    mesh = icosphere(R, 2)
    shell = Shell(mesh, H, YOUNG, poisson=NU, AC=AC, AI=AI, device="cpu", dtype="float32")
    coefficient = YOUNG * H / R**4
    drag = Drag(shell, drag=coefficient)
    drag.set_interval(1.0)
    shell.terms = (drag,)
    x = shell.relax(mesh.vertices, 1.0, max_iterations=1, method="auto")
    assert shell.newton_steps > 0
    quasi_static, stepped = backward_euler(1.0, 0.0), backward_euler(1.0, coefficient)
    assert abs(radius(mesh, x, "cpu") - stepped) <= 3e-3 * abs(1 - quasi_static)


def test_the_newton_finish_with_a_drag_converges_off_the_sphere(device):
    """A pulse of c at a pole (no symmetry left) and a drag: the drag holds the rigid motions, which the Newton
    finish then must not project out; from the rest shape it reaches 1e-11 in float64 and the energy falls at
    every step."""
    mesh = icosphere(10.0, 2)
    shell = Shell(mesh, 0.5, 1.0, AC=0.5, AI=0.5, volume_penalty=24 * 0.5 / 1e4, device=device, dtype="float64")
    drag = Drag(shell, drag=0.3 * 0.5 / 100)
    drag.set_interval(0.2)
    shell.terms = (drag,)
    c = np.exp(-(np.linalg.norm(mesh.vertices - [0.0, 0.0, 10.0], axis=1) ** 2) / 4)
    drag.begin_step(shell_positions(shell, mesh.vertices))
    energies = []
    shell.relax(mesh.vertices, c, tol=1e-11, method="newton", callback=lambda i, e, r: energies.append(e))
    assert np.all(np.diff(energies) <= 1e-12 * abs(energies[0]))


def test_drag_refuses_what_is_not_a_drag():
    shell = Shell(icosphere(R, 1), H, YOUNG, device="cpu", dtype="float64")
    with pytest.raises(ValueError, match="drag ζ"):
        Drag(shell, drag=0.0)
    with pytest.raises(ValueError, match="interval"):
        Drag(shell, drag=1.0).set_interval(-1.0)


def test_a_conservative_run_past_the_fold_stops_and_says_why(device):
    """A strong uniform contraction with conservative transport: every vertex's area falls below 1/e of its rest
    value, where no equilibrium holds the chemical it concentrates; the material reading goes on."""
    mesh = icosphere(R, 2)

    def run(transport):
        shell = Shell(mesh, H, YOUNG, poisson=NU, AC=2.5, device=device, dtype="float64")
        wave = Telegraph(
            LaplaceBeltrami(mesh, device=device, dtype="float64"),
            1.0,
            c0=np.zeros(mesh.n_vertices),
            dt=0.05,
            transport=transport,
        )
        coupled = QuasiStatic(shell, wave)
        wave.state.c.fill_(1.0)
        return coupled.step()

    with pytest.raises(FoldError, match="past the fold of conservative transport.*below 1/e"):
        run("conservative")
    run("material")


# the oocytes at half size (R = 5, h = 0.25, the pulse √2/2 wide, τ_m halved: the R = 10 scene with lengths and
# times halved) on level 3, which resolves it as level 4 resolves R = 10
HALF_SIZE = ["radius=5", "thickness=0.25", "width=0.7071", "tau_m=0.5", "level=3", "dtype=float64"]


def oocyte_run(scene: str, *sets):
    from wavewarp.driver import simulate
    from wavewarp.parameters import load_scene, resolve

    module = load_scene(scene)
    run = module.build(resolve(module.Parameters, None, [*HALF_SIZE, *sets]), device="cpu", report=lambda m: None)
    outcome = simulate(run, [])
    assert outcome.failure is None and not outcome.interrupted
    return run, outcome.measurements


@pytest.mark.slow
def test_the_default_ascidian_converges_in_the_time_step():
    """The default reading (conservative transport, overdamped coupling) of the ascidian, the scene that tells the
    readings apart, at its step and at half of it: the front speed agrees to 0.5%, the contraction depth to 3% (its
    first-order step error: 2.2% here, 0.9% for the scene at level 4), the smallest concentration while the front
    expands to 0.01 (of the pulse's peak 1), the shape asymmetry to 0.2% R, both runs stay axisymmetric (below
    1% R) with the chemical on the invariant (docs/studies/2026-12-02-readings-of-the-model.md). The quasi-static
    coupling fails this: its wrinkle grows with each halving, and at a quarter of the step the pole folds."""
    run, coarse = oocyte_run("ascidian", "relax_every=1")
    assert run.p.coupling == "overdamped" and run.p.transport == "conservative"
    _, fine = oocyte_run("ascidian", "relax_every=1", f"dt={run.resolved['dt'] / 2!r}")
    assert fine["wave_speed"] == pytest.approx(coarse["wave_speed"], rel=5e-3)
    assert fine["contraction_depth"] == pytest.approx(coarse["contraction_depth"], rel=3e-2)
    assert abs(fine["min_concentration_expanding"] - coarse["min_concentration_expanding"]) < 1e-2
    assert abs(fine["shape_asymmetry"] - coarse["shape_asymmetry"]) < 2e-3
    for m in (coarse, fine):
        assert m["shape_asymmetry"] < 0.01 and m["total_concentration_error"] < 1e-8
