"""Self-contact (ours, docs/theory/shell.md#self-contact): an exact energy term that keeps layers apart."""

import math

import numpy as np
import pytest
import warp as wp

from wavewarp.geometry import limit_positions, limit_surface
from wavewarp.mesh import icosphere
from wavewarp.dynamics import ShellDynamics
from wavewarp.self_contact import SelfContact
from wavewarp.shell import Shell

F64 = dict(dtype="float64")


def squashed(mesh, factor):
    """The sphere flattened along z: its two caps face each other across a gap 2 R factor at the axis."""
    x = mesh.vertices.copy()
    x[:, 2] *= factor
    return x


def brute_force_energy(mesh, x, contact):
    """½ Σ_q Σ_o w_q w_o A (d/r - 1)³ over every pair of quadrature points (no grid, no candidate list)."""
    rest, now = limit_surface(mesh, device="cpu", **F64), limit_surface(mesh, x, device="cpu", **F64)
    p, w = now.points, rest.area
    r = np.linalg.norm(p[:, None] - p[None], axis=2)
    far = np.linalg.norm(rest.points[:, None] - rest.points[None], axis=2) >= contact.exclusion
    close = far & (r < contact.distance)
    u = np.where(close, contact.distance / np.where(close, r, 1.0) - 1.0, 0.0)
    return 0.5 * np.sum(w[:, None] * w[None] * contact.strength * u**3)


@pytest.fixture
def pressed(device):
    """A squashed unit sphere with h = 0.1: its caps overlap the contact distance d = h near the axis."""
    mesh = icosphere(1.0, 3)
    shell = Shell(mesh, 0.1, 1.0, device=device, **F64)
    return mesh, shell, squashed(mesh, 0.04)


def test_energy_is_the_double_integral_over_close_far_pairs(pressed):
    mesh, shell, x = pressed
    elastic = shell.energy(x)
    shell.self_contact = SelfContact(shell)
    expected = brute_force_energy(mesh, x, shell.self_contact)
    assert expected > 0.1 * elastic  # the caps press: the term is not negligible here
    assert shell.energy(x) - elastic == pytest.approx(expected, rel=1e-10)


def test_forces_are_the_exact_balanced_gradient(pressed, rng):
    mesh, shell, x = pressed
    elastic = shell.forces(x)
    shell.self_contact = SelfContact(shell)
    forces = shell.forces(x)
    contact = forces - elastic
    scale = np.abs(contact).max()
    assert scale > 0.1 * np.abs(elastic).max()
    # internal: no net force, no net torque
    assert np.abs(contact.sum(axis=0)).max() < 1e-12 * scale * mesh.n_vertices
    assert np.abs(np.cross(x, contact).sum(axis=0)).max() < 1e-12 * scale * mesh.n_vertices
    # central differences along random directions (within the search's skin: the same pairs)
    for _ in range(3):
        direction = rng.normal(size=x.shape)
        step = 1e-6
        slope = (shell.energy(x + step * direction) - shell.energy(x - step * direction)) / (2 * step)
        assert -np.sum(forces * direction) == pytest.approx(slope, rel=1e-6)


def test_a_full_candidate_row_grows_the_table(pressed):
    mesh, shell, x = pressed
    contact = shell.self_contact = SelfContact(shell)
    contact.capacity = 2  # far fewer than the caps' pairs: the search must grow the table
    contact.neighbours = wp.zeros((len(contact.built), 2), dtype=wp.int32, device=shell.device)
    elastic = Shell(mesh, 0.1, 1.0, device=shell.device, **F64).energy(x)
    assert shell.energy(x) - elastic == pytest.approx(brute_force_energy(mesh, x, contact), rel=1e-10)
    assert contact.capacity >= contact.counts.numpy().max() > 2


def test_deterministic_gather_equals_the_atomic_spread(pressed):
    mesh, shell, x = pressed
    shell.self_contact = SelfContact(shell)
    gathered = Shell(mesh, 0.1, 1.0, deterministic=True, device=shell.device, **F64)
    gathered.self_contact = SelfContact(gathered)
    assert np.allclose(gathered.forces(x), shell.forces(x), rtol=0, atol=1e-12 * np.abs(shell.forces(x)).max())


def test_two_facing_layers_push_with_the_continuum_pressure():
    """Near the axis the squashed sphere's caps are two nearly flat layers at gap s = 2 R f: the
    force per area there approaches the flat-layer law 2π A s (d/s - 1)³ (docs/theory/shell.md)."""
    mesh = icosphere(1.0, 4)
    shell = Shell(mesh, 0.1, 1.0, device="cpu", **F64)
    contact = shell.self_contact = SelfContact(shell)
    for factor in (0.03, 0.04):
        x = squashed(mesh, factor)
        shell.forces(x)  # fills the pressures at the quadrature points
        points, pressure = contact.points.numpy(), contact.pressures.numpy()
        axis = np.linalg.norm(points[:, :2], axis=1) < 0.05
        gap = 2 * factor * math.sqrt(1 - 0.05**2 / 2)
        law = 2 * math.pi * contact.strength * gap * (contact.distance / gap - 1) ** 3
        measured = np.abs(pressure[axis, 2])
        assert np.all(np.sign(pressure[axis, 2]) == np.sign(points[axis, 2]))  # apart
        assert np.mean(measured) == pytest.approx(law, rel=0.05)
        assert np.abs(pressure[axis, :2]).max() < 0.1 * law  # the lattice of points, not a slope


def test_relaxation_keeps_an_everting_cap_out_of_the_far_side():
    """A cap with strongly inverted preferred curvature (c = 1 on z > z₀, AI = 11, R/h = 20, as the
    buckling scene) stays everted while z₀ falls, warm-started from its mirror image about z = 0.6.
    Without self-contact its pole passes through the far side; with it the pole stops at about the
    contact distance d = h above the far pole, and the relaxations converge."""
    mesh = icosphere(1.0, 3)
    h = 0.05
    top, bottom = int(np.argmax(mesh.vertices[:, 2])), int(np.argmin(mesh.vertices[:, 2]))
    gaps = {}
    for with_contact in (False, True):
        shell = Shell(mesh, h, 1.0, AI=11.0, device="cpu", **F64)
        if with_contact:
            shell.self_contact = SelfContact(shell)
        x = mesh.vertices.copy()
        cap = x[:, 2] > 0.6
        x[cap, 2] = 1.2 - x[cap, 2]
        for z0 in (0.6, 0.4, 0.2):
            x = shell.relax(x, (mesh.vertices[:, 2] > z0).astype(float), tol=1e-6, max_iterations=5000)
            if with_contact:  # the cap moves by many skins: the loop stopped for new searches and went on
                assert shell.self_contact.searches > 2 and len(shell.relax_history) > 1
        limit = limit_positions(mesh, x, device="cpu", **F64)
        gaps[with_contact] = limit[top, 2] - limit[bottom, 2]
    assert gaps[False] < -0.1  # through the far side
    assert 0.5 * h < gaps[True] < 1.2 * h


def test_bad_settings_are_refused_with_the_fix():
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, device="cpu", **F64)
    with pytest.raises(ValueError, match="refine the mesh"):
        SelfContact(shell)  # quadrature points 0.11 apart against d = 0.05
    fine = Shell(icosphere(1.0, 3), 0.05, 1.0, device="cpu", **F64)
    with pytest.raises(ValueError, match="exclusion"):
        SelfContact(fine, exclusion=0.02)
    with pytest.raises(ValueError, match="distance"):
        SelfContact(fine, distance=-1.0)
    with pytest.raises(ValueError, match="for this shell"):
        shell.self_contact = SelfContact(fine)
    with pytest.raises(ValueError, match="analytic gradient"):
        SelfContact(Shell(icosphere(1.0, 3), 0.05, 1.0, gradient="autodiff", device="cpu", **F64))
    fine.self_contact = SelfContact(fine)
    with pytest.raises(ValueError, match="quasi-static relaxations only"):
        ShellDynamics(fine, density=1.0)
