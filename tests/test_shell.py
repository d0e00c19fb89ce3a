"""Koiter shell: rest state, invariances, exact gradients, closed-form sphere radius (docs/theory/shell.md, docs/theory/scenes.md)."""

import numpy as np
import pytest
from meshes import bipyramid, random_genus0
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation
from test_subdivision import rotated_corners

from wavewarp.geometry import limit_positions
from wavewarp.mesh import cube, icosphere, prism
from wavewarp.relax import RelaxationError
from wavewarp.shell import Shell

F64 = dict(dtype="float64")
ACTIVE = dict(AC=0.4, AI=0.7, volume_penalty=3.0)


def perturbed(mesh, rng, amount=0.02):
    return mesh.vertices + amount * rng.normal(size=mesh.vertices.shape)


@pytest.mark.parametrize(
    "make",
    [lambda: icosphere(1.0, 2), lambda: cube(2.0, 4), lambda: prism(2.0, 4), lambda: random_genus0(30, 1).subdivided(1)],
)
def test_rest_state_has_zero_energy_and_forces(make, device):
    mesh = make()
    shell = Shell(mesh, 0.05, 1e3, **ACTIVE, device=device, **F64)
    # exactly zero on the CPU; CUDA contracts some products into FMAs, leaving round-off
    assert abs(shell.energy(mesh.vertices, 0.0)) <= 1e-24 * shell.young * shell.thickness * shell.rest_area
    assert np.abs(shell.forces(mesh.vertices, 0.0)).max() <= 1e-12 * shell.force_scale()


@pytest.mark.parametrize("model", ["koiter", "bilayer"])
def test_energy_is_invariant_under_rigid_motion_and_forces_are_balanced(model, rng):
    mesh = random_genus0(30, 2).subdivided(1)
    shell = Shell(mesh, 0.08, 1.0, **ACTIVE, model=model, device="cpu", **F64)
    x, c = perturbed(mesh, rng), rng.random(mesh.n_vertices)
    rotation = Rotation.random(random_state=7).as_matrix()
    moved = x @ rotation.T + [0.3, -1.0, 2.0]
    assert shell.energy(moved, c) == pytest.approx(shell.energy(x, c), rel=1e-11)
    forces = shell.forces(x, c)
    scale = np.abs(forces).max()
    np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-11 * scale)
    np.testing.assert_allclose(np.cross(x, forces).sum(axis=0), 0.0, atol=1e-11 * scale)
    np.testing.assert_allclose(shell.forces(moved, c), forces @ rotation.T, atol=1e-10 * scale)


@pytest.mark.parametrize("valence", [3, 4, 5, 7, 8])
@pytest.mark.parametrize("model", ["koiter", "bilayer"])
def test_forces_are_the_exact_negative_gradient(valence, model, rng):
    """Central differences on a perturbed mesh with valence-N vertices at every corner."""
    mesh = rotated_corners(bipyramid(valence).subdivided(1))
    shell = Shell(mesh, 0.1, 2.0, **ACTIVE, model=model, device="cpu", **F64)
    x, c = perturbed(mesh, rng, 0.05), rng.random(mesh.n_vertices)
    forces = shell.forces(x, c)
    step = 1e-6
    for index in rng.choice(x.size, size=24, replace=False):
        i, k = divmod(int(index), 3)
        plus, minus = x.copy(), x.copy()
        plus[i, k] += step
        minus[i, k] -= step
        numeric = -(shell.energy(plus, c) - shell.energy(minus, c)) / (2 * step)
        assert abs(numeric - forces[i, k]) < 1e-6 * np.abs(forces).max()


@pytest.mark.parametrize("model", ["koiter", "bilayer"])
def test_autodiff_and_deterministic_paths_equal_the_hand_derived_forces(model, device, rng):
    mesh = random_genus0(24, 3).subdivided(1)
    x, c = perturbed(mesh, rng), rng.random(mesh.n_vertices)
    common = dict(thickness=0.06, young=3.0, **ACTIVE, model=model, device=device, **F64)
    analytic = Shell(mesh, **common).forces(x, c)
    autodiff = Shell(mesh, **common, gradient="autodiff").forces(x, c)
    deterministic = Shell(mesh, **common, deterministic=True)
    scale = np.abs(analytic).max()
    np.testing.assert_allclose(autodiff, analytic, atol=1e-11 * scale)
    first = deterministic.forces(x, c)
    np.testing.assert_allclose(first, analytic, atol=1e-12 * scale)
    assert np.array_equal(first, deterministic.forces(x + 0.0, c))


def test_float32_forces_track_float64(device, rng):
    mesh = icosphere(3.0, 2)
    x, c = perturbed(mesh, rng), rng.random(mesh.n_vertices)
    f64 = Shell(mesh, 0.1, 1.0, **ACTIVE, device=device, dtype="float64").forces(x, c)
    f32 = Shell(mesh, 0.1, 1.0, **ACTIVE, device=device, dtype="float32").forces(x, c)
    assert np.abs(f32 - f64).max() < 1e-4 * np.abs(f64).max()


def test_bilayer_and_koiter_bend_the_same_way_on_a_sphere():
    """Without metric activity the two models agree on an exact sphere (b̄⁰ = -ā⁰/R), so their
    relaxed radii under uniform c agree to discretisation error; with AC they agree to first order."""
    mesh = icosphere(1.0, 3)
    radii = {}
    for AC in (0.0, 0.1):
        for model in ("koiter", "bilayer"):
            shell = Shell(mesh, 0.1, 1.0, AC=AC, AI=0.8, model=model, bilayer_radius=1.0, device="cpu", **F64)
            x = shell.relax(mesh.vertices, 1.0)
            radii[AC, model] = np.linalg.norm(limit_positions(mesh, x, device="cpu", **F64), axis=1).mean()
    assert radii[0.0, "bilayer"] == pytest.approx(radii[0.0, "koiter"], abs=1e-3 * abs(1 - radii[0.0, "koiter"]))
    change = {model: radii[0.1, model] - 1.0 for model in ("koiter", "bilayer")}
    assert np.sign(change["koiter"]) == np.sign(change["bilayer"])
    assert abs(change["bilayer"] - change["koiter"]) < 0.1 * abs(change["koiter"])


def sphere_stretch(AC, AI, h, R, mu_v, young=1.0, nu=0.33, c=1.0):
    """λ = r/R minimising the 1-D energy of a sphere of radius r under uniform c (docs/theory/scenes.md)."""
    s, k = np.exp(-AC * c), 1 - AI * c

    def energy(lam):
        membrane = (lam**2 - s) ** 2 / s
        bending = h**2 / (3 * R**2) * (lam - k) ** 2 / s
        volume = mu_v * (4 / 3 * np.pi * R**3 * (lam**3 - 1)) ** 2
        return np.pi * R**2 * young * h / (1 - nu) * (membrane + bending) + volume

    return minimize_scalar(energy, bounds=(0.2, 2.0), method="bounded", options={"xatol": 1e-13}).x


@pytest.mark.parametrize(
    "AC, AI, h_over_R, mu_v",
    [(0.3, 0.5, 0.05, 0.0), (0.5, 0.0, 0.05, 24.0), (0.5, 0.3, 0.1, 0.4), (-0.2, 1.0, 0.08, 0.0)],
)
def test_uniform_concentration_sphere_reaches_the_closed_form_radius(AC, AI, h_over_R, mu_v):
    R, young = 2.0, 1.0
    h = h_over_R * R
    penalty = mu_v * young * h / R**4  # μV in units of Y h / R⁴, as in docs/theory/scenes.md
    lam = sphere_stretch(AC, AI, h, R, penalty, young)
    if mu_v == 0:  # the cubic of the issue, without the volume term
        s, k, eps = np.exp(-AC), 1 - AI, h**2 / (6 * R**2)
        assert lam**3 - (s - eps) * lam - eps * k == pytest.approx(0.0, abs=1e-7)
    errors = []
    for level in (2, 3):
        mesh = icosphere(R, level)
        shell = Shell(mesh, h, young, AC=AC, AI=AI, volume_penalty=penalty, device="cpu", **F64)
        x = shell.relax(mesh.vertices, 1.0)
        radius = np.linalg.norm(limit_positions(mesh, x, device="cpu", **F64), axis=1).mean() / R
        errors.append(abs(radius - lam) / abs(1 - lam))
    assert errors[1] < 1e-3 and errors[1] < errors[0]


def test_relax_lowers_the_energy_monotonically_and_converges_with_the_tolerance(rng):
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, AC=0.3, AI=0.4, volume_penalty=0.5, device="cpu", **F64)
    c = 0.5 + 0.5 * np.tanh(4 * mesh.vertices[:, 2])  # a front: the shape is not a sphere
    answers = {}
    for tol in (1e-4, 1e-6, 1e-8, 1e-10):
        answers[tol] = shell.relax(mesh.vertices, c, tol=tol)
        history = np.array(shell.relax_history)
        assert np.all(np.diff(history) <= 1e-12 * abs(history[0]))
        residual = np.linalg.norm(shell.forces(answers[tol], c), axis=1).max() / shell.force_scale()
        assert residual <= tol
    gaps = [np.abs(answers[t] - answers[1e-10]).max() for t in (1e-4, 1e-6, 1e-8)]
    assert gaps[0] > gaps[1] > gaps[2]


def test_float32_relax_meets_its_default_tolerance(device):
    mesh = icosphere(1.0, 3)
    shell = Shell(mesh, 0.05, 1.0, AC=0.5, volume_penalty=1.2, device=device, dtype="float32")
    x = shell.relax(mesh.vertices, 1.0)
    residual = np.linalg.norm(shell.forces(x, 1.0), axis=1).max() / shell.force_scale()
    assert residual <= 1e-5
    history = np.array(shell.relax_history)
    assert np.all(np.diff(history) <= 1e-7 * abs(history[0]))  # monotone within float32 round-off


def test_captured_relaxation_runs_the_host_loops_arithmetic_and_serves_every_later_call(device):
    """The relaxation is one captured device loop (docs/theory/shell.md); with a callback the same loop
    body runs from the host. Both take the same steps (bitwise on the CPU, up to the order of
    atomic sums on a GPU), and the shell's one graph honours each call's tolerance and budget."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, AC=0.3, AI=0.4, volume_penalty=0.5, device=device, **F64)
    c = 0.5 + 0.5 * np.tanh(4 * mesh.vertices[:, 2])
    seen = []
    host = shell.relax(mesh.vertices, c, tol=1e-8, callback=lambda *row: seen.append(row))
    host_history = np.array(shell.relax_history)
    captured = shell.relax(mesh.vertices, c, tol=1e-8)
    exact = device == "cpu"
    assert len(shell.relax_history) == len(host_history) or not exact
    np.testing.assert_allclose(captured, host, rtol=0, atol=0 if exact else 1e-9)
    assert [row[0] for row in seen] == list(range(len(host_history)))
    assert np.array_equal([row[1] for row in seen], host_history)
    assert seen[-1][2] <= 1e-8 < seen[-2][2]

    def residual(x):
        return np.linalg.norm(shell.forces(x, c), axis=1).max() / shell.force_scale()

    tighter = shell.relax(mesh.vertices, c, tol=1e-11, max_iterations=30000)  # a larger history
    assert residual(tighter) <= 1e-11 < residual(captured)
    again = shell.relax(tighter, c, tol=1e-6)  # already in equilibrium: no step
    assert len(shell.relax_history) == 1 and np.array_equal(again, tighter)
    with pytest.raises(RelaxationError, match="after 2 iterations"):
        shell.relax(mesh.vertices, c, tol=1e-8, max_iterations=2, method="ncg")


def test_relax_says_how_far_it_got():
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, AC=0.5, device="cpu", **F64)
    with pytest.raises(RelaxationError, match=r"after 3 iterations at residual .* the tolerance") as info:
        shell.relax(mesh.vertices, 1.0, max_iterations=3, method="ncg")
    assert info.value.residual > 1e-9 and info.value.x.shape == mesh.vertices.shape


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(thickness=0.0), "thickness must be a positive"),
        (dict(thickness=-1.0), "thickness must be a positive"),
        (dict(young=0.0), "young must be a positive"),
        (dict(young=np.nan), "young must be a positive"),
        (dict(poisson=0.5), r"poisson must lie in \(-1, 0.5\)"),
        (dict(poisson=-1.0), r"poisson must lie in \(-1, 0.5\)"),
        (dict(volume_penalty=-1.0), "volume_penalty must be >= 0"),
        (dict(AC=np.inf), "AC must be a finite"),
        (dict(model="plate"), "model must be one of koiter, bilayer"),
        (dict(gradient="fd"), "gradient must be one of analytic, autodiff"),
        (dict(dtype="float16"), "dtype must be"),
    ],
)
def test_bad_parameters_name_the_argument(kwargs, message):
    arguments = dict(thickness=0.1, young=1.0, device="cpu") | kwargs
    with pytest.raises(ValueError, match=message):
        Shell(icosphere(1.0, 1), **arguments)


def test_a_vertex_of_too_high_valence_is_refused_by_name():
    """The force kernel accumulates a patch in registers: valence 13 (a 13-gon bipyramid's poles) is named."""
    with pytest.raises(ValueError, match="valence 13.*up to 12"):
        Shell(bipyramid(13).subdivided(1), 0.1, 1.0, device="cpu")
    Shell(bipyramid(12).subdivided(1), 0.1, 1.0, device="cpu")


def test_bad_arrays_name_the_argument():
    mesh = icosphere(1.0, 1)
    shell = Shell(mesh, 0.1, 1.0, device="cpu")
    with pytest.raises(ValueError, match=r"x must have shape \(42, 3\)"):
        shell.energy(np.zeros((40, 3)), 0.0)
    with pytest.raises(ValueError, match=r"c must have shape \(42,\)"):
        shell.forces(mesh.vertices, np.zeros(41))
    bad = np.zeros(42)
    bad[5] = np.nan
    with pytest.raises(ValueError, match=r"c\[5\] is not finite"):
        shell.forces(mesh.vertices, bad)
    with pytest.raises(ValueError, match="tol must be a positive"):
        shell.relax(mesh.vertices, 0.0, tol=-1.0)
    with pytest.raises(ValueError, match="must be a wavewarp.mesh.Mesh"):
        Shell(mesh.vertices, 0.1, 1.0)


def test_warp_shell_equals_an_independent_numpy_implementation(rng):
    """benchmarks/numpy_shell.py: the same energy and gradient written with NumPy arrays."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from numpy_shell import NumpyShell

    mesh = random_genus0(40, 6).subdivided(1)
    x, c = perturbed(mesh, rng), rng.random(mesh.n_vertices)
    parameters = dict(thickness=0.07, young=2.0, AC=0.3, AI=-0.4, volume_penalty=1.5)
    energy, forces = NumpyShell(mesh, **parameters).energy_and_forces(x, c)
    shell = Shell(mesh, **parameters, device="cpu", **F64)
    assert shell.energy(x, c) == pytest.approx(energy, rel=1e-12)
    np.testing.assert_allclose(shell.forces(x, c), forces, atol=1e-12 * np.abs(forces).max())


def test_a_new_rest_volume_reaches_the_next_relaxation():
    """The relaxation loop is captured once (on the CPU too) and V̄ is one of its launch arguments, so
    setting V̄ must drop the captured loop: a shell relaxed before V̄ changed then relaxes as a fresh
    shell built with the new V̄ does, not back to its old volume."""
    mesh = icosphere(10.0, 2)

    def shell_with(volume_fraction, relaxed_before=None):
        shell = Shell(mesh, 1.0, 1.0, 0.33, volume_penalty=1.0, device="cpu", dtype="float64")
        rest = shell.rest_volume
        if relaxed_before is not None:
            shell.rest_volume = relaxed_before * rest
            shell.relax(mesh.vertices, 0.0, tol=1e-3, method="ncg")
        shell.rest_volume = volume_fraction * rest
        return shell, rest

    reused, rest = shell_with(0.95, relaxed_before=0.99)
    fresh, _ = shell_with(0.95)
    volume = reused.volume(reused.relax(mesh.vertices, 0.0, tol=1e-3, method="ncg"))
    assert volume == pytest.approx(fresh.volume(fresh.relax(mesh.vertices, 0.0, tol=1e-3, method="ncg")), rel=1e-12)
    assert volume < 0.97 * rest  # compressed towards the new target, not the old one
    with pytest.raises(ValueError, match="rest_volume"):
        reused.rest_volume = float("nan")


def test_a_new_rest_volume_reaches_the_newton_finish_of_a_float32_shell():
    """A float32 shell's Newton finish works on a float64 twin built at its first use: the twin must
    take a V̄ set later too, so the reused shell ends where a fresh one with that V̄ does."""
    mesh = icosphere(10.0, 2)
    volumes = []
    for relaxed_before in (0.99, None):
        shell = Shell(mesh, 1.0, 1.0, 0.33, volume_penalty=1.0, device="cpu", dtype="float32")
        rest = shell.rest_volume
        if relaxed_before is not None:
            shell.rest_volume = relaxed_before * rest
            shell.relax(mesh.vertices, 0.0, tol=1e-4, method="newton")
        shell.rest_volume = 0.95 * rest
        volumes.append(shell.volume(shell.relax(mesh.vertices, 0.0, tol=1e-4, method="newton")))
    assert volumes[0] == pytest.approx(volumes[1], rel=1e-5)
