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


@pytest.mark.parametrize("rule", ["3", "6"])
@pytest.mark.parametrize("model", ["koiter", "bilayer"])
@pytest.mark.parametrize("mode", ["compiled", "held"])
def test_compiled_basis_forces_and_energy_equal_the_general_kernels(mode, model, rule, rng):
    """Two worlds of different couplings and moduli, away from rest, volume term on; float64."""
    base = random_genus0(30, 5).subdivided(1)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(2)])  # fmt: skip
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    options = dict(ACTIVE, AC=[0.1, 0.3], young=[3.0, 5.0], model=model, rule=rule, device="cpu", dtype="float64")
    general = Shell(mesh, **options, regular_patches="general")
    compiled = Shell(mesh, **options, regular_patches=mode)
    expected = general.forces(x, c)
    np.testing.assert_allclose(compiled.forces(x, c), expected, rtol=0, atol=1e-13 * np.abs(expected).max())
    energies = []
    for shell in (general, compiled):  # the energy the force launch writes (with_energy), not the energy kernel's
        with wp.ScopedDevice("cpu"):
            xs = wp.array(x, dtype=shell.vec3)
            forces, energy = wp.zeros_like(xs), wp.zeros(1, dtype=wp.float64)
        shell.forces_device(xs, forces, energy)
        energies.append(energy.numpy()[0])
    assert energies[0] > 0 and energies[1] == pytest.approx(energies[0], rel=1e-13)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="the CUDA launches of both kernels")
@pytest.mark.parametrize("dtype, tolerance", [("float64", 1e-12), ("float32", 1e-5)])
@pytest.mark.parametrize("mode", ["compiled", "held", "vector"])
def test_compiled_basis_forces_equal_the_general_kernels_on_cuda(mode, dtype, tolerance, rng):
    base = icosphere(3.0, 3)
    mesh = Mesh.union([Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles)
                       for _ in range(3)])  # fmt: skip
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    options = dict(ACTIVE, AC=[0.1, 0.2, 0.3], device="cuda:0", dtype=dtype)
    expected = Shell(mesh, **options, regular_patches="general").forces(x, c)
    forces = Shell(mesh, **options, regular_patches=mode).forces(x, c)
    np.testing.assert_allclose(forces, expected, rtol=0, atol=tolerance * np.abs(expected).max())


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
    with pytest.raises(ValueError, match="regular_patches must be one of auto, vector, held, compiled, general, got 'fast'"):
        Shell(icosphere(1.0, 1), **ACTIVE, regular_patches="fast", device="cpu")
