"""Koiter forces of regular patches with their basis compiled in (kernels/regular.py): which triangles take it,
and its forces and energy against the general kernel's, in float64, for single and batched worlds; the vector
atomics' padded accumulator (float32) against the general kernel and cleared after each evaluation."""

import numpy as np
import pytest
import warp as wp
from meshes import random_genus0

from wavewarp.kernels.regular import regular_forces_kernel
from wavewarp.mesh import Mesh, icosphere
from wavewarp.patches import regular_patch_basis
from wavewarp.shell import HELD_FROM_TRIANGLES, VECTOR_FROM_TRIANGLES, Shell, auto_regular_patches

ACTIVE = dict(thickness=0.06, young=3.0, AC=0.4, AI=0.7, volume_penalty=3.0)


def valence_six_triangles(mesh: Mesh) -> np.ndarray:
    """Triangles whose three corners each lie in six triangles (a closed mesh: valence 6), counted directly."""
    valence = np.bincount(mesh.triangles.ravel(), minlength=mesh.n_vertices)
    return np.flatnonzero((valence[mesh.triangles] == 6).all(axis=1))


@pytest.mark.parametrize("mode", ["compiled", "held", "vector"])
def test_the_regular_triangles_take_the_compiled_kernel_and_every_other_the_general_one(mode):
    mesh = random_genus0(24, 3).subdivided(1)  # valences 3 to 8 and regular triangles between them
    shell = Shell(mesh, **ACTIVE, regular_patches=mode, device="cpu", dtype="float32")
    assert shell.regular_kernel == mode and (shell._padded_forces is not None) == (mode == "vector")
    (regular_kernel, regular), (general_kernel, others) = shell._force_launches
    assert general_kernel is shell._force_kernel and regular_kernel is not general_kernel
    assert shell.twin("float32").regular_patches == mode
    expected = valence_six_triangles(mesh)
    assert 0 < len(expected) < mesh.n_triangles
    assert np.array_equal(regular.numpy(), expected)
    assert np.array_equal(np.sort(np.concatenate([regular.numpy(), others.numpy()])), np.arange(mesh.n_triangles))
    for choice in ("general", "auto"):  # on the CPU "auto" is the general kernel
        (kernel, every), = Shell(mesh, **ACTIVE, regular_patches=choice, device="cpu")._force_launches
        assert kernel is shell._force_kernel and np.array_equal(every.numpy(), np.arange(mesh.n_triangles))


def test_auto_takes_vector_atomics_on_sm90_and_holds_before_for_large_float32_shells_on_cuda_only():
    assert auto_regular_patches(90, wp.float32, VECTOR_FROM_TRIANGLES) == "vector"
    assert auto_regular_patches(100, wp.float32, VECTOR_FROM_TRIANGLES) == "vector"
    assert auto_regular_patches(90, wp.float32, VECTOR_FROM_TRIANGLES - 1) == "general"
    assert auto_regular_patches(80, wp.float32, HELD_FROM_TRIANGLES) == "held"
    assert auto_regular_patches(80, wp.float32, HELD_FROM_TRIANGLES - 1) == "general"
    for arch in (80, 90):
        assert auto_regular_patches(arch, wp.float64, 10 * HELD_FROM_TRIANGLES) == "general"
    assert auto_regular_patches(None, wp.float32, 10 * HELD_FROM_TRIANGLES) == "general"  # the CPU
    shell = Shell(icosphere(1.0, 2), **ACTIVE, device="cpu")
    assert shell.regular_patches == "auto" and shell.regular_kernel == "general"


def test_vector_atomics_in_float64_are_the_held_kernel():
    """float64 has no vector atomics: "vector" asked of a float64 shell (or its float64 twin) holds positions."""
    shell = Shell(icosphere(1.0, 2), **ACTIVE, regular_patches="vector", device="cpu", dtype="float32")
    twin = shell.twin("float64")
    assert twin.regular_patches == "vector" and twin.regular_kernel == "held" and twin._padded_forces is None


EPS = np.finfo(np.float64).eps


def volume_round_off(mesh: Mesh, x: np.ndarray, rest_volumes) -> tuple:
    """Each world's volume of the flat mesh at x, and the largest force difference, divided by 2 μV, that the
    volume term's round-off allows between two kernels summing the volume moments in different orders (regular
    triangles per triangle, the general kernel per point): |δ(V - V̄)| |∂V/∂x_I|, with |δV| and |δV̄| each at
    most 256 ε V and |∂V/∂x_I| at most the area of vertex I's triangles (both independent of the code)."""
    corners = x[mesh.triangles]
    volumes = np.einsum("ti,ti->t", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])) / 6
    volumes = np.abs(volumes.reshape(mesh.worlds, -1).sum(axis=1))
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    ring = np.bincount(mesh.triangles.ravel(), np.repeat(areas, 3), minlength=mesh.n_vertices)
    volume = max(volumes.max(), np.max(rest_volumes))
    return volumes, 2 * 256 * EPS * volume * ring.max()


@pytest.mark.parametrize("rule", ["3", "6"])
@pytest.mark.parametrize("model", ["koiter", "bilayer"])
@pytest.mark.parametrize("mode", ["compiled", "held"])
def test_compiled_basis_forces_and_energy_equal_the_general_kernels(mode, model, rule, rng):
    """Two worlds of different couplings and moduli, away from rest, volume term on; float64. The kernels sum the
    volume moments in different orders: their forces may differ by the volume term's round-off too."""
    base = random_genus0(30, 5).subdivided(1)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(2)])  # fmt: skip
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    options = dict(ACTIVE, AC=[0.1, 0.3], young=[3.0, 5.0], model=model, rule=rule, device="cpu", dtype="float64")
    general = Shell(mesh, **options, regular_patches="general")
    compiled = Shell(mesh, **options, regular_patches=mode)
    expected = general.forces(x, c)
    volumes, slack = volume_round_off(mesh, x, general.rest_volume)
    np.testing.assert_allclose(compiled.forces(x, c), expected, rtol=0,
                               atol=1e-13 * np.abs(expected).max() + 2 * ACTIVE["volume_penalty"] * slack)  # fmt: skip
    energies = []
    for shell in (general, compiled):  # the energy the force launch writes (with_energy), not the energy kernel's
        with wp.ScopedDevice("cpu"):
            xs = wp.array(x, dtype=shell.vec3)
            forces, energy = wp.zeros_like(xs), wp.zeros(1, dtype=wp.float64)
        shell.forces_device(xs, forces, energy)
        energies.append(energy.numpy()[0])
    # E_V = μV (V - V̄)²: its round-off 2 μV |V - V̄| (δV + δV̄), δV bounded as for the forces
    departure = np.abs(volumes - general.rest_volume).max()
    energy_slack = 2 * ACTIVE["volume_penalty"] * departure * 2 * 256 * EPS * volumes.max()
    assert energies[0] > 0 and energies[1] == pytest.approx(energies[0], rel=1e-13, abs=energy_slack)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="the CUDA launches of both kernels")
@pytest.mark.parametrize("dtype, tolerance", [("float64", 1e-12), ("float32", 1e-5)])
@pytest.mark.parametrize("mode", ["compiled", "held", "vector"])
def test_compiled_basis_forces_equal_the_general_kernels_on_cuda(mode, dtype, tolerance, rng):
    base = icosphere(3.0, 3)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(3)])  # fmt: skip
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    options = dict(ACTIVE, AC=[0.1, 0.2, 0.3], device="cuda:0", dtype=dtype)
    general = Shell(mesh, **options, regular_patches="general")
    expected = general.forces(x, c)
    forces = Shell(mesh, **options, regular_patches=mode).forces(x, c)
    slack = volume_round_off(mesh, x, general.rest_volume)[1]  # the volume moments' round-off (float64 bound)
    np.testing.assert_allclose(forces, expected, rtol=0,
                               atol=tolerance * np.abs(expected).max() + 2 * ACTIVE["volume_penalty"] * slack)  # fmt: skip


def test_float32_compiled_forces_track_the_float64_general_kernel(rng):
    mesh = icosphere(3.0, 3)
    x, c = mesh.vertices * (1 + 0.01 * rng.normal(size=(mesh.n_vertices, 1))), rng.random(mesh.n_vertices)
    f64 = Shell(mesh, **ACTIVE, regular_patches="general", device="cpu", dtype="float64").forces(x, c)
    f32 = Shell(mesh, **ACTIVE, regular_patches="compiled", device="cpu", dtype="float32").forces(x, c)
    assert np.abs(f32 - f64).max() < 1e-4 * np.abs(f64).max()


@pytest.mark.parametrize("worlds", [1, 2])
def test_vector_atomics_forces_equal_the_general_kernels_to_float32_round_off(worlds, rng):
    """The padded accumulator (the CPU's scalar-add path of `add_padded_force`) and its fold, in float32, against
    the general kernel in float32 (round-off apart) and in float64 (float32 accuracy); repeated evaluations equal
    (the fold clears the accumulator) and nothing is left in it."""
    base = icosphere(3.0, 2)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(worlds)])  # fmt: skip
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    options = dict(ACTIVE, AC=[0.1, 0.3][:worlds], device="cpu")
    general = Shell(mesh, **options, regular_patches="general", dtype="float32").forces(x, c)
    exact = Shell(mesh, **options, regular_patches="general", dtype="float64").forces(x, c)
    vector = Shell(mesh, **options, regular_patches="vector", dtype="float32")
    first, second = vector.forces(x, c), vector.forces(x, c)
    scale = np.abs(exact).max()
    np.testing.assert_allclose(first, general, rtol=0, atol=1e-5 * scale)  # as the float32 CUDA test
    np.testing.assert_allclose(first, exact, rtol=0, atol=1e-4 * scale)  # as the float32 against float64 test
    assert np.array_equal(first, second)
    assert not vector._padded_forces.numpy().any()


def test_vector_atomics_refuse_float64_by_name():
    with pytest.raises(ValueError, match="vector atomics add float32 forces"):
        regular_forces_kernel(*regular_patch_basis("3"), wp.float64, True, True)


def test_an_unknown_choice_of_kernel_is_refused_by_name():
    expected = "regular_patches must be one of auto, vector, held, compiled, general, got 'fast'"
    with pytest.raises(ValueError, match=expected):
        Shell(icosphere(1.0, 1), **ACTIVE, regular_patches="fast", device="cpu")


@pytest.mark.parametrize("rule", ["3", "6"])
@pytest.mark.parametrize("deterministic", [False, True])
def test_the_regular_volume_kernel_sums_the_general_kernels_moments(rule, deterministic, rng):
    """Volume moments [S, V₀, Σx] of two worlds of a mesh with valences 3 to 8 (regular triangles from literals,
    the others through the table), float64, against the one-point-an-item kernel's; the rest volume too."""
    base = random_genus0(30, 5).subdivided(1)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(2)])  # fmt: skip
    x = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape)
    options = dict(ACTIVE, rule=rule, deterministic=deterministic, device="cpu", dtype="float64")
    general, held = Shell(mesh, **options, regular_patches="general"), Shell(mesh, **options, regular_patches="held")
    assert held._volume_kernel is not general._volume_kernel
    np.testing.assert_allclose(held.rest_volume, general.rest_volume, rtol=1e-13)
    moments = []
    for shell in (general, held):
        with wp.ScopedDevice("cpu"):
            shell._volume_of(wp.array(x, dtype=shell.vec3))
        moments.append(shell._moments.numpy())
    assert np.abs(moments[0][:, 3]).min() > 1.0  # V₀ of each world well away from zero
    np.testing.assert_allclose(moments[1], moments[0], rtol=1e-13, atol=1e-13 * np.abs(moments[0]).max())


@pytest.mark.skipif(not wp.is_cuda_available(), reason="the CUDA launch of the regular volume kernel")
@pytest.mark.parametrize("dtype, tolerance", [("float64", 1e-13), ("float32", 1e-6)])
def test_the_regular_volume_kernel_sums_the_general_kernels_moments_on_cuda(dtype, tolerance, rng):
    base = icosphere(3.0, 3)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(3)])  # fmt: skip
    options = dict(ACTIVE, device="cuda:0", dtype=dtype)
    general, held = Shell(mesh, **options, regular_patches="general"), Shell(mesh, **options, regular_patches="held")
    np.testing.assert_allclose(held.rest_volume, general.rest_volume, rtol=tolerance)
