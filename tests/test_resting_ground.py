"""RestingGround: the ground, gravity and the incremental Coulomb friction as energy terms of a shell's
relaxation (the quasi-static limit, docs/theory/dynamics.md)."""

import numpy as np
import pytest
import warp as wp

from wavewarp import LaplaceBeltrami, Mesh, QuasiStatic, RelaxationError, RestingGround, Telegraph
from wavewarp.geometry import limit_positions
from wavewarp.mesh import cube, icosphere
from wavewarp.shell import Shell

F64 = dict(dtype="float64")
DENSITY, G, STIFFNESS = 0.01, 0.5, 50.0


def ball(level=2, drop=0.002, deterministic=None):
    """A unit sphere (h = 0.1, Y = 1, float64) whose bottom is `drop` below the ground z = 0."""
    mesh = icosphere(1.0, level)
    shell = Shell(mesh, 0.1, 1.0, deterministic=deterministic, device="cpu", **F64)
    return shell, mesh.vertices + np.array([0.0, 0.0, 1.0 - drop])


def device(shell, x):
    return wp.array(x, dtype=shell.vec3, device=shell.device)


@pytest.mark.parametrize("deterministic", [False, True])
def test_forces_are_minus_the_gradient_of_the_energy(deterministic):
    """−F·v against central differences of E along random directions, with points below the ground, a tilted
    gravity and friction against anchors half a slip away (float64; the atomic spread and the ordered gather)."""
    shell, x = ball(level=1, drop=0.05, deterministic=deterministic)
    ground = RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, gravity=[0.2, 0.0, -0.5], friction=0.3,
                           smoothing=1e-3)  # fmt: skip
    shell.terms = (ground,)
    ground.begin_step(device(shell, x + np.array([0.002, -0.001, 0.0])))
    assert ground.loads.numpy().max() > 0
    rng = np.random.default_rng(3)
    forces = shell.forces(x)
    for _ in range(4):
        v = rng.standard_normal(x.shape)
        h = 1e-6
        slope = (shell.energy(x + h * v) - shell.energy(x - h * v)) / (2 * h)
        assert -np.sum(forces * v) == pytest.approx(slope, rel=1e-6, abs=1e-12)


def test_a_ball_comes_to_rest_with_the_ground_carrying_its_weight():
    """At equilibrium the ground's force Σ k z² w equals the weight ρ g A (the internal forces sum to zero), the
    ball sags, and it stays where it was put horizontally (mirror symmetry)."""
    shell, x = ball()
    ground = RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, gravity=G)
    shell.terms = (ground,)
    rest = shell.relax(x, tol=1e-10)
    weight = DENSITY * G * ground.area.numpy().sum()
    assert ground.normal_force(device(shell, rest))[0] == pytest.approx(weight, rel=1e-6)
    shift = rest.mean(axis=0) - x.mean(axis=0)
    assert abs(shift[0]) < 1e-9 and abs(shift[1]) < 1e-9
    assert rest[:, 2].min() < x[:, 2].min()  # it sank into the ground and sagged


@pytest.mark.parametrize("tan_theta, holds", [(0.09, True), (0.12, False)])
def test_friction_holds_a_box_on_a_slope_only_below_mu(tan_theta, holds):
    """A box put down on a face on flat ground and anchored there is then loaded along a slope tan θ. With μ = 0.1
    and the loads of the flat ground (μ W in all), a state that holds it exists below tan θ = μ: there the box has
    moved by a shear of its walls, far less than its size, and the friction the NumPy sum of the law gives over
    the points balances the weight's pull along the slope. Above, none does (the energy falls without bound as it
    slides: the relaxation cannot converge)."""
    mesh = cube(2.0, 4)
    shell = Shell(mesh, 0.2, 100.0, device="cpu", **F64)  # stiff: the faces do not cave in under the weight
    x = mesh.vertices - np.array([0.0, 0.0, limit_positions(mesh, device="cpu", **F64)[:, 2].min() + 0.002])
    epsilon, mu = 1e-7, 0.1
    options = dict(stiffness=STIFFNESS, density=DENSITY, friction=mu, smoothing=epsilon)
    flat = RestingGround(shell, gravity=G, **options)
    shell.terms = (flat,)
    rest = shell.relax(x, tol=1e-10)
    flat.begin_step(device(shell, rest))
    pull = G * np.array([np.sin(np.arctan(tan_theta)), 0.0, -np.cos(np.arctan(tan_theta))])
    sloped = RestingGround(shell, gravity=pull, **options)
    wp.copy(sloped.anchors, flat.anchors)
    wp.copy(sloped.loads, flat.loads)
    shell.terms = (sloped,)
    if not holds:
        with pytest.raises(RelaxationError):
            shell.relax(rest, tol=1e-9, max_iterations=3000, method="ncg")
        return
    held = shell.relax(rest, tol=1e-10)
    assert 0 < held.mean(axis=0)[0] - rest.mean(axis=0)[0] < 1e-2
    sloped._points(device(shell, held))
    slip = (sloped.points.numpy() - sloped.anchors.numpy())[:, :2]
    law = -mu * sloped.loads.numpy()[:, None] * slip / np.sqrt(np.sum(slip**2, axis=1) + epsilon**2)[:, None]
    area = sloped.area.numpy()
    friction = np.sum(law * area[:, None], axis=0)
    assert friction[0] == pytest.approx(-DENSITY * pull[0] * area.sum(), rel=1e-6)
    assert abs(friction[1]) < 1e-6 * abs(friction[0])


def test_bad_settings_and_the_newton_finish_are_refused():
    shell, _ = ball(level=1)
    with pytest.raises(ValueError, match="stiffness must be"):
        RestingGround(shell, stiffness=0.0, density=DENSITY)
    with pytest.raises(ValueError, match="friction must be a finite"):
        RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, friction=-1)
    other, _ = ball(level=1)
    with pytest.raises(ValueError, match="built for this shell"):
        shell.terms = (RestingGround(other, stiffness=STIFFNESS, density=DENSITY),)
    shell.terms = (RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, gravity=G),)
    with pytest.raises(ValueError, match="Newton finish works on the shell's own energy"):
        shell.relax(shell.mesh.vertices, method="newton")


def test_quasi_static_steps_begin_where_the_last_equilibrium_left_the_shell():
    """QuasiStatic begins each load step at the last equilibrium: after a step of a uniformly contracting ball
    (c = 1, AC = 0.2) the anchors are the limit points where the step started and the loads their pressures; the
    contracted ball stays centred (mirror symmetry) and the ground still carries its weight."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.1, 1.0, AC=0.2, device="cpu", **F64)
    ground = RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, gravity=G, friction=0.1, smoothing=1e-6)
    shell.terms = (ground,)
    # K·1 = 0: c stays 1
    wave = Telegraph(LaplaceBeltrami(mesh, device="cpu", **F64), 1.0, c0=np.full(mesh.n_vertices, 1.0))
    run = QuasiStatic(shell, wave, sensitive=False, x0=mesh.vertices + np.array([0.0, 0.0, 0.998]), method="ncg",
                      tol=1e-10)  # fmt: skip
    before = run.positions()
    run.step()
    ground._points(device(shell, before))
    np.testing.assert_array_equal(ground.anchors.numpy(), ground.points.numpy())
    z = ground.points.numpy()[:, 2]
    np.testing.assert_allclose(ground.loads.numpy(), STIFFNESS * np.where(z < 0, z, 0.0) ** 2, rtol=1e-12, atol=0)
    after = run.positions()
    assert abs(after.mean(axis=0)[0]) < 1e-9 and abs(after.mean(axis=0)[1]) < 1e-9
    assert ground.normal_force(device(shell, after))[0] == pytest.approx(DENSITY * G * ground.area.numpy().sum(), rel=1e-6)


def test_batched_worlds_rest_as_each_alone():
    """Two balls of different size in one union, relaxed together: each world's equilibrium is its own run's."""
    small, large = icosphere(1.0, 1), icosphere(1.3, 1)
    lift = [np.array([0.0, 0.0, 1.0 - 0.002]), np.array([0.0, 0.0, 1.3 - 0.002])]
    alone = []
    for mesh, up in zip((small, large), lift):
        shell = Shell(mesh, 0.1, 1.0, device="cpu", **F64)
        shell.terms = (RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, gravity=G),)
        alone.append(shell.relax(mesh.vertices + up, tol=1e-10))
    union = Mesh.union([small, large])
    shell = Shell(union, 0.1, 1.0, device="cpu", **F64)
    ground = RestingGround(shell, stiffness=STIFFNESS, density=DENSITY, gravity=G)
    shell.terms = (ground,)
    together = shell.relax(np.concatenate([small.vertices + lift[0], large.vertices + lift[1]]), tol=1e-10)
    np.testing.assert_allclose(together, np.concatenate(alone), atol=1e-8)
    weights = [DENSITY * G * area.sum() for area in ground.area.numpy().reshape(2, -1)]
    np.testing.assert_allclose(ground.normal_force(device(shell, together)), weights, rtol=1e-6)
