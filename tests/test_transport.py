"""The chemical on a moving surface (docs/theory/transport.md; docs/theory/chemistry.md).

Conservative transport keeps each vertex's amount M_I c_I across a surface move, so the total
C = Σ M_I c_I changes only through the equation's own terms: for the telegraph equation
C'' + α C' = 0 step by step, for FitzHugh–Nagumo d/dt C = ∫ r(c, w). The surfaces here move as
prescribed (non-uniformly, in time), and the answers are the discrete invariants, written out in
the tests; "material" transport, the old reading, must miss them.
"""

import math

import numpy as np
import pytest

from test_coupled import closed_form_stretch
from test_walkers import walk

from wavewarp.coupled import QuasiStatic
from wavewarp.initial import gaussian_pulse
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.parameters import as_dict, load_scene, resolve, resumed
from wavewarp.shell import Shell
from wavewarp.chemistry import telegraph_total
from wavewarp.waves import FitzHughNagumo, Telegraph

F64 = dict(device="cpu", dtype="float64")


def wobbling_sphere(mesh, t):
    """Control positions of a sphere whose radius varies with height and time, and that turns:
    a non-uniform, non-rigid motion (area elements change by up to ±20% from point to point)."""
    x = mesh.vertices
    z = x[:, 2] / np.linalg.norm(x, axis=1)
    scale = 1.0 + 0.2 * math.sin(1.3 * t) * z + 0.1 * math.sin(0.7 * t) * z**2
    angle = 0.3 * t
    turn = np.array([[math.cos(angle), -math.sin(angle), 0.0], [math.sin(angle), math.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    return (x * scale[:, None]) @ turn.T


@pytest.mark.parametrize("dtype, tol", [("float64", 1e-12), ("float32", 2e-5)])
@pytest.mark.parametrize("mass_corrections", [0, 2])
def test_telegraph_total_follows_its_invariant_on_a_moving_surface(device, dtype, tol, mass_corrections):
    """Leapfrog in the amounts: Σ M v^{n+½} = r Σ M v^{n-½} with r = (1 - αdt/2)/(1 + αdt/2), and
    C^{n+1} = C^n + dt Σ M v^{n+½}, whatever the surface does between the steps (K·1 = 0, and
    1ᵀ M W_p = 1ᵀ for the mass corrections). α is large here so that the decay shows."""
    mesh = icosphere(1.0, 2)
    op = LaplaceBeltrami(mesh, device=device, dtype=dtype)
    alpha = 0.5
    c0, v0 = gaussian_pulse(op, 0, 0.4, gamma=1.0)
    dt = 0.5 * Telegraph(op, 1.0, alpha, c0=c0, mass_corrections=mass_corrections).stable_dt
    wave = Telegraph(op, 1.0, alpha, c0=c0, v0=v0, dt=dt, mass_corrections=mass_corrections, check_every=1)
    total, rate = wave.total(), wave.total_rate()
    initial = (total, rate)
    ratio = (1 - 0.5 * alpha * dt) / (1 + 0.5 * alpha * dt)
    expected = []
    for n in range(1, 41):
        wave.advance(1)
        wave.move_surface(wobbling_sphere(mesh, n * dt))
        rate *= ratio
        total += dt * rate
        expected.append((wave.total(), total, wave.total_rate(), rate))
    measured, exact, measured_rate, exact_rate = np.array(expected).T
    assert np.abs(measured - exact).max() <= tol * np.abs(exact).max()
    assert np.abs(measured_rate - exact_rate).max() <= tol * np.abs(exact).max()
    # the continuous invariant C(0) + C'(0)(1 - e^{-αt})/α agrees to O(α² dt²)
    assert telegraph_total(*initial, alpha, dt, 40 * dt) == pytest.approx(exact[-1], rel=alpha**2 * dt**2)


def test_material_transport_misses_the_invariant():
    """The old reading (control values kept across a move) changes C by Σ ΔM_I c_I at every move."""
    mesh = icosphere(1.0, 2)
    op = LaplaceBeltrami(mesh, **F64)
    c0, v0 = gaussian_pulse(op, 0, 0.4, gamma=1.0)
    wave = Telegraph(op, 1.0, 0.0, c0=c0, v0=v0, transport="material")
    start = wave.total() + 10 * wave.dt * wave.total_rate()
    for n in range(1, 11):
        wave.advance(1)
        wave.move_surface(wobbling_sphere(mesh, 2.0 + n * wave.dt))
    assert abs(wave.total() - start) > 1e-2 * abs(start)


def test_uniform_concentration_on_a_scaled_sphere_becomes_c_over_s_squared(device):
    """A sphere scaled by s: every lumped mass scales by s², so c and c_t become c/s², v/s² (exactly,
    to round-off), and scaling back returns them."""
    mesh = icosphere(1.0, 2)
    op = LaplaceBeltrami(mesh, device=device, dtype="float64")
    n = mesh.n_vertices
    wave = Telegraph(op, 1.0, 0.0, c0=np.full(n, 2.0), v0=np.full(n, 0.3), dt=0.01)
    c, v = wave.concentration(), wave.velocity()  # uniform: K c = 0
    for s in (1.5, 0.6, 1.0):
        wave.move_surface(s * mesh.vertices)
        np.testing.assert_allclose(wave.concentration(), c / s**2, rtol=1e-13)
        np.testing.assert_allclose(wave.velocity(), v / s**2, rtol=1e-13)


@pytest.mark.parametrize("scheme, mass_corrections, tol", [("explicit", 0, 1e-13), ("explicit", 2, 1e-13), ("imex", 0, 1e-9)])
def test_fhn_total_changes_only_by_the_reaction_on_a_moving_surface(device, scheme, mass_corrections, tol):
    """d/dt Σ M c = Σ M r(c, w), r = c(1-c)(c-ν) - w, and d/dt Σ M w = Σ M ε (c - κ w): each step's
    change, computed here from the state before the step, is the step's whole change (IMEX: to its
    CG tolerance); `produced()` sums the reaction's part."""
    mesh = icosphere(1.0, 2)
    op = LaplaceBeltrami(mesh, device=device, dtype="float64")
    nu, kappa, epsilon, dt = -0.01, 1e-4, 0.05, 0.05
    c0, _ = gaussian_pulse(op, 0, 0.5, gamma=0.2)
    wave = FitzHughNagumo(op, 0.2, nu, kappa, epsilon, c0=c0, w0=0.1 * c0, dt=dt, scheme=scheme,
                          mass_corrections=mass_corrections)  # fmt: skip
    start = wave.total()
    for n in range(1, 31):
        c, w, mass = wave.concentration(), wave.inhibitor(), op.mass()
        total_c, total_w = mass @ c, mass @ w
        wave.advance(1)
        reaction = c * (1 - c) * (c - nu) - w
        new_w = wave.inhibitor()
        c_source = c if scheme == "explicit" else wave.concentration()
        w_source = w if scheme == "explicit" else new_w
        assert mass @ wave.concentration() == pytest.approx(total_c + dt * mass @ reaction, abs=tol * mass.sum())
        assert mass @ new_w == pytest.approx(total_w + dt * epsilon * mass @ (c_source - kappa * w_source),
                                             abs=tol * mass.sum())  # fmt: skip
        wave.move_surface(wobbling_sphere(mesh, n * dt))
    assert wave.total() == pytest.approx(start + wave.produced(), abs=30 * tol * op.area)


def rising_crossings(values, dt, level=0.5):
    k = np.flatnonzero((values[:-1] < level) & (values[1:] >= level))
    return (k + (level - values[k]) / (values[k + 1] - values[k])) * dt


@pytest.mark.parametrize("transport", ["conservative", "material"])
def test_uniform_fhn_on_a_contracting_sphere_oscillates_faster(transport):
    """FitzHugh–Nagumo with uniform c on a quasi-static sphere: c stays uniform (K·1 = 0), and the
    sphere's area follows the closed-form stretch λ(c)² of docs/theory/scenes.md. Conserving the chemical, each
    step is the scalar map c ← c̃ λ(c̃_prev)² / λ(c̃)² after the kinetic step c̃ (the shell relaxes to
    c̃, then the surface moves); written out here, it oscillates 15% faster than the bare kinetics,
    the paper's "mechanical feedback increases the wave frequency". The material reading keeps the
    kinetic period."""
    R, h, AC, nu, kappa, epsilon, dt, steps = 1.0, 0.05, 0.5, -0.01, 1e-4, 0.005, 0.5, 800
    mesh = icosphere(R, 1)
    c0 = 0.1
    wave = FitzHughNagumo(LaplaceBeltrami(mesh, **F64), 0.2, nu, kappa, epsilon, c0=np.full(mesh.n_vertices, c0), dt=dt,
                          transport=transport)  # fmt: skip
    run = QuasiStatic(Shell(mesh, thickness=h, young=1.0, AC=AC, **F64), wave)
    measured = [c0]
    for _ in range(steps):
        run.step()
        c = wave.concentration()
        assert np.ptp(c) < 1e-4
        measured.append(c.mean())

    def area(c):
        return closed_form_stretch(AC, 0.0, c, h / R) ** 2

    c, w, relaxed_to, expected = c0, 0.0, c0, [c0]  # relaxed_to: the reference the current surface has
    for _ in range(steps):
        reference = c + dt * (c * (1 - c) * (c - nu) - w)
        w = w + dt * epsilon * (c - kappa * w)
        factor = area(relaxed_to) / area(reference) if transport == "conservative" else 1.0
        c, w, relaxed_to = reference * factor, w * factor, reference
        expected.append(c)
    kinetic, c, w = [c0], c0, 0.0
    for _ in range(steps):
        c, w = c + dt * (c * (1 - c) * (c - nu) - w), w + dt * epsilon * (c - kappa * w)
        kinetic.append(c)
    measured, expected = np.array(measured), np.array(expected)
    assert np.abs(measured - expected).max() < 1e-4
    period, predicted, bare = (np.diff(rising_crossings(np.array(x), dt)) for x in (measured, expected, kinetic))
    assert len(period) >= 1
    np.testing.assert_allclose(period, predicted, rtol=1e-5)
    if transport == "conservative":
        assert period[0] < 0.9 * bare[0]
    else:
        np.testing.assert_allclose(period, bare, rtol=1e-5)


def test_insensitive_twin_is_the_same_under_either_transport():
    """The twin's wave stays on the rest surface: its operator never moves, so conservative and
    material transport give the same run, bit for bit."""
    mesh = icosphere(1.0, 2)
    runs = []
    for transport in ("conservative", "material"):
        op = LaplaceBeltrami(mesh, **F64)
        c0, v0 = gaussian_pulse(op, 0, 0.4, gamma=1.0)
        wave = Telegraph(op, 1.0, c0=c0, v0=v0, transport=transport)
        run = QuasiStatic(Shell(mesh, thickness=0.05, young=1.0, AC=0.5, AI=0.5, **F64), wave, sensitive=False,
                          chemistry_steps=4)  # fmt: skip
        for _ in range(3):
            run.step()
        runs.append((wave.concentration(), wave.velocity(), run.positions()))
    for a, b in zip(*runs):
        assert np.array_equal(a, b)


def scene_run(name, **overrides):
    """A scene's quick run through the scene API (every frame recorded); returns its measurements."""
    return walk(name, **overrides).measurements()


def test_coupled_starfish_keeps_the_telegraph_invariant():
    """The deforming starfish (quasi-static shell, two mass corrections) in float64: C stays on
    C(0) + C'(0)(1 - e^{-αt})/α to 1e-6; the material reading leaves it."""
    conservative = scene_run("starfish", dtype="float64", level=2, frames=2, t_end=1.0)
    assert conservative["total_concentration_error"] < 1e-6
    material = scene_run("starfish", dtype="float64", level=2, frames=2, t_end=1.0, transport="material")
    assert material["total_concentration_error"] > 1e-3


def test_coupled_walker_keeps_the_reaction_balance():
    """The sensitive sphere walker (FHN on the moving shell, inside the captured coupled step) in
    float64: C = C(0) + the reaction's amount at every frame, to round-off."""
    measured = scene_run("sphere-walker", dtype="float64", periods=0.1, frames=2)
    assert measured["total_concentration_error"] < 1e-10
    assert measured["min_concentration"] < 0  # FHN's lower branch


def test_a_trajectory_without_a_transport_resumes_with_the_material_one():
    """Files written before `transport` existed ran the material reading: a resume keeps it."""
    module = load_scene("starfish")
    assert resolve(module.Parameters).transport == "conservative"
    stored = {k: v for k, v in as_dict(resolve(module.Parameters)).items() if k != "transport"}
    assert resumed(module.Parameters, stored).transport == "material"
    assert resumed(module.Parameters, {**stored, "transport": "conservative"}).transport == "conservative"


def test_unknown_transport_is_refused():
    op = LaplaceBeltrami(icosphere(1.0, 1), **F64)
    with pytest.raises(ValueError, match="transport must be one of conservative, material"):
        Telegraph(op, 1.0, c0=np.zeros(op.n_vertices), transport="lagrangian")
