"""Softest modes of a shell equilibrium (wavewarp/modes.py, docs/theory/shell.md#stability-of-an-equilibrium): the classical buckling pressure of a sphere, eigenpairs checked on the energy itself,
and the azimuthal order of a mode."""

import math

import numpy as np
import pytest

from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.modes import azimuthal_order, softest_modes
from wavewarp.shell import Shell

R, Y, NU, MU = 10.0, 1.0, 0.33, 1.0


def zoelly_pressure(thickness, radius):
    """Classical buckling pressure of a complete sphere (Zoelly 1915), the thin-shell limit."""
    return 2.0 * Y * thickness**2 / (radius**2 * math.sqrt(3.0 * (1.0 - NU**2)))


def pressurised_sphere(mesh, thickness, fraction):
    """A sphere under the external pressure `fraction` × Zoelly's, set through the volume penalty
    μV (V − V̄)², whose pressure is 2 μV (V − V̄); V̄ from the membrane strain p R (1 − ν) / (2 Y h)."""
    shell = Shell(mesh, thickness, Y, NU, volume_penalty=MU, device="cpu", dtype="float64")
    p = fraction * zoelly_pressure(thickness, R)
    strain = p * R * (1 - NU) / (2 * Y * thickness)
    shell.rest_volume = shell.rest_volume * (1 - strain) ** 3 - p / (2 * MU)
    x = shell.relax(mesh.vertices, 0.0, method="newton")
    volume = shell.volume(x)
    radius = (3 * volume / (4 * math.pi)) ** (1 / 3)
    return shell, x, 2 * MU * (volume - shell.rest_volume) / zoelly_pressure(thickness, radius)


def critical_fraction(mesh, thickness):
    """Pressure / Zoelly's where the softest eigenvalue crosses zero, from 0.8 and 0.9 (below it the
    softest eigenvalue falls linearly with the pressure), and that mode's degree ℓ(ℓ+1)."""
    points = []
    for fraction in (0.8, 0.9):
        shell, x, loaded = pressurised_sphere(mesh, thickness, fraction)
        modes = softest_modes(shell, x, count=2)
        assert modes.values[0] > 0  # stable below the critical pressure
        points.append((loaded, modes.values[0]))
    (p1, v1), (p2, v2) = points
    radial = np.einsum("ij,ij->i", modes.vectors[0], x / np.linalg.norm(x, axis=1)[:, None])
    operator = LaplaceBeltrami(mesh, device="cpu", dtype="float64")
    degree = R**2 * (radial @ operator.apply(radial)) / (radial @ (operator.mass() * radial))
    return p1 - v1 * (p2 - p1) / (v2 - v1), degree


@pytest.mark.slow
def test_softest_modes_buckle_a_pressurised_sphere_at_zoellys_pressure_in_the_thin_limit():
    """Known in advance: p_cr = 2 Y h² / (R² √(3(1 − ν²))) with critical degree
    ℓ(ℓ+1) ≈ √(12(1 − ν²)) R/h, the thin-shell limit. Its error is O(h/R) (the modes' 1/ℓ² ~ h/R):
    halving h/R halves it, and the Richardson extrapolation 2 p(h/2) − p(h) recovers Zoelly's
    pressure. Level 4 gives the same 0.859 and 0.929: the mesh is not what limits it."""
    mesh = icosphere(R, 3)
    thick, thick_degree = critical_fraction(mesh, 0.1 * R)
    thin, _ = critical_fraction(mesh, 0.05 * R)
    assert 0.8 < thick < thin < 1.0
    assert 2 * thin - thick == pytest.approx(1.0, abs=0.03)
    # the buckling mode is the short-wave one, not the sphere's breathing or lowest modes
    assert 0.6 * math.sqrt(12 * (1 - NU**2)) * 10 < thick_degree < 1.1 * math.sqrt(12 * (1 - NU**2)) * 10


def test_softest_modes_are_eigenpairs_of_the_energy_and_orthogonal_to_rigid_motion():
    """Independent of the Hessian's assembly: the energy's second difference along each mode equals
    its eigenvalue (modes are M-orthonormal), and every mode is M-orthogonal to the rigid motions. Two equilibria: a
    pressurised sphere (the volume term) and a sphere dented by a curvature patch (AI, no volume term).
    The difference's own truncation error at this step: 1e-3 (pressurised), 3e-7 (dented)."""
    mesh = icosphere(R, 2)
    area = LaplaceBeltrami(mesh, device="cpu", dtype="float64").mass()
    shell, x, _ = pressurised_sphere(mesh, 0.1 * R, 0.5)
    dented = Shell(mesh, 0.1 * R, Y, NU, AI=3.0, device="cpu", dtype="float64")
    patch = np.exp(-np.sum((mesh.vertices - [0.0, 0.0, R]) ** 2, axis=1) / 32.0)
    for shell, x, c in ((shell, x, 0.0), (dented, dented.relax(mesh.vertices, patch, method="newton"), patch)):
        modes = softest_modes(shell, x, c, count=4)
        assert np.all(np.diff(modes.values) >= 0) and modes.values[0] > 0
        energy = shell.energy(x, c)
        for value, v in zip(modes.values, modes.vectors):
            assert np.sum(area * np.sum(v**2, axis=1)) == pytest.approx(1.0, rel=1e-9)
            step = 3e-4 * R / np.abs(v).max()
            curvature = (shell.energy(x + step * v, c) + shell.energy(x - step * v, c) - 2 * energy) / step**2
            assert curvature == pytest.approx(value, rel=3e-3)
            weighted, size = area[:, None] * v, np.sum(area * np.linalg.norm(v, axis=1))
            assert np.linalg.norm(weighted.sum(axis=0)) < 1e-9 * size  # M-orthogonal to translations
            assert np.linalg.norm(np.cross(x - x.mean(axis=0), weighted).sum(axis=0)) < 1e-9 * size * R  # and rotations


def test_softest_modes_find_the_most_negative_eigenvalues_as_a_dense_solver_does():
    """Past the buckling pressure the Hessian has negative eigenvalues far below the first shift; the
    factorization's inertia must move the shift below them. Checked against a dense eigensolver on a
    Hessian built independently, by central differences of the forces one coordinate at a time.
    The state: a sphere scaled by its membrane strain under twice Zoelly's pressure (the symmetric
    state, unstable there)."""
    mesh = icosphere(R, 2)
    thickness, p = 0.1 * R, 2.0 * zoelly_pressure(0.1 * R, R)
    shell = Shell(mesh, thickness, Y, NU, volume_penalty=MU, device="cpu", dtype="float64")
    strain = p * R * (1 - NU) / (2 * Y * thickness)
    x = mesh.vertices * (1 - strain)
    shell.rest_volume = shell.volume(x) - p / (2 * MU)
    modes = softest_modes(shell, x, count=3)
    n, step = 3 * mesh.n_vertices, 1e-5 * R
    hessian = np.empty((n, n))
    for k in range(n):
        shift = np.zeros(n)
        shift[k] = step
        minus, plus = shell.forces(x - shift.reshape(-1, 3)), shell.forces(x + shift.reshape(-1, 3))
        hessian[:, k] = (minus - plus).ravel() / (2 * step)
    hessian = 0.5 * (hessian + hessian.T)
    weight = np.repeat(LaplaceBeltrami(mesh, device="cpu", dtype="float64").mass(), 3) ** -0.5
    scaled = weight[:, None] * hessian * weight[None, :]
    r = x - x.mean(axis=0)
    rigid = np.stack([np.broadcast_to(a, x.shape).ravel() for a in np.eye(3)]
                     + [np.cross(a, r).ravel() for a in np.eye(3)], axis=1)  # fmt: skip
    q, _ = np.linalg.qr(rigid / weight[:, None])
    projector = np.eye(n) - q @ q.T
    dense = np.linalg.eigvalsh(projector @ scaled @ projector)
    dense = np.sort(dense[np.abs(dense) > 1e-9 * np.abs(dense).max()])  # the six rigid zeros dropped
    assert modes.values[0] < -1e-3 * np.abs(np.diag(scaled)).mean()  # below the first shift (modes.SHIFT)
    # 3e-5 measured: the sparse Hessian leaves out the volume term's small rank-6 centroid part (newton.py)
    np.testing.assert_allclose(modes.values, dense[:3], rtol=1e-4)


def test_azimuthal_order_reads_a_known_pattern_about_any_axis():
    x = icosphere(R, 3).vertices
    axis = np.array([0.3, -0.5, 0.81])
    axis /= np.linalg.norm(axis)
    e1 = np.cross(axis, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    phi = np.arctan2(x @ e2, x @ e1)
    normal = x / R
    for m in (0, 2, 5, 7):
        pattern = (np.cos(m * phi + 0.4) * np.exp(-((x @ axis / R) ** 2) * 4))[:, None] * normal
        assert azimuthal_order(x, pattern, axis) == m
    twist = np.cross(axis, x) * np.cos(3 * phi)[:, None]  # tangential: the azimuthal component carries it
    assert azimuthal_order(x, twist, axis) == 3


def test_softest_modes_refuse_a_shell_with_self_contact():
    from wavewarp.self_contact import SelfContact

    mesh = icosphere(R, 2)
    shell = Shell(mesh, 2.0, Y, NU, device="cpu", dtype="float64")
    shell.self_contact = SelfContact(shell)
    with pytest.raises(ValueError, match="self-contact"):
        softest_modes(shell, mesh.vertices)


@pytest.mark.parametrize("count", [0, -1, 2.5, True, 10**6])
def test_softest_modes_refuse_a_bad_count(count):
    mesh = icosphere(R, 1)
    shell = Shell(mesh, 1.0, Y, NU, device="cpu", dtype="float64")
    with pytest.raises(ValueError, match="count must be an integer from 1 to"):
        softest_modes(shell, mesh.vertices, count=count)
