"""The Newton finish of a relaxation (wavewarp/newton.py, docs/theory/shell.md#newton-finish)."""

import numpy as np
import pytest
from test_shell import sphere_stretch

from wavewarp.coupled import QuasiStatic
from wavewarp.geometry import limit_positions
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.modes import softest_modes
from wavewarp.newton import NewtonFinish, ShiftedInverse, distance_two_colouring, patch_pairs, rigid_modes
from wavewarp.relax import ROUND_OFF_SLACK
from wavewarp.self_contact import SelfContact
from wavewarp.relax import RelaxationError
from wavewarp.shell import Shell
from wavewarp.waves import Telegraph

F64 = dict(dtype="float64")


def front(mesh):
    return 0.5 + 0.5 * np.tanh(4 * mesh.vertices[:, 2] / np.abs(mesh.vertices).max())


def central_difference_hessian_action(shell, x, c, v, step=1e-6):
    """H v = -(F(x + εv) - F(x - εv)) / 2ε from the shell's own forces: the independent reference."""
    return (-(shell.forces(x + step * v, c) - shell.forces(x - step * v, c)) / (2 * step)).ravel()


def test_colouring_leaves_no_force_row_with_two_vertices_of_one_colour():
    shell = Shell(icosphere(1.0, 2), 0.05, 1.0, device="cpu", **F64)
    pattern = patch_pairs(shell.tables.host, shell.mesh.n_vertices)
    colour = distance_two_colouring(pattern)
    for row in range(pattern.shape[0]):
        members = colour[pattern.indices[pattern.indptr[row] : pattern.indptr[row + 1]]]
        assert len(np.unique(members)) == len(members)
    assert pattern.nnz == pattern.T.nnz and (pattern != pattern.T).nnz == 0


@pytest.mark.parametrize("volume_penalty", [0.0, 0.5])
def test_coloured_hessian_equals_central_differences_of_the_forces(rng, device, volume_penalty):
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, AC=0.5, AI=0.8, volume_penalty=volume_penalty, device=device, **F64)
    c = rng.uniform(0.0, 0.6, mesh.n_vertices)
    x = 0.95 * mesh.vertices + 0.01 * rng.normal(size=mesh.vertices.shape)
    shell.forces(x, c)  # sets the reference
    h, w, coupling = NewtonFinish(shell).hessian(x)
    assert abs(h - h.T).max() == 0.0 and (volume_penalty > 0) == bool(coupling.any())
    for v in [rng.normal(size=x.shape) for _ in range(3)] + [x]:  # x: the volume's own direction
        reference = central_difference_hessian_action(shell, x, c, v)
        action = h @ v.ravel() + w @ (coupling @ (w.T @ v.ravel()))
        # with volume, 2μV (V − V̄) ∇²(x̄·S) stays out: S = ⅓∫ n dω is zero up to quadrature (docs/theory/shell.md)
        bound = 1e-7 if volume_penalty == 0 else 1e-3
        assert np.abs(action - reference).max() <= bound * np.abs(reference).max()


def test_newton_reaches_the_closed_form_radius_quadratically():
    R, h, penalty = 2.0, 0.2, 0.4 * 0.2 / 2.0**4
    lam = sphere_stretch(0.5, 0.3, h, R, penalty)
    mesh = icosphere(R, 3)
    shell = Shell(mesh, h, 1.0, AC=0.5, AI=0.3, volume_penalty=penalty, device="cpu", **F64)
    residuals = []
    x = shell.relax(mesh.vertices, 1.0, method="newton", callback=lambda i, e, r: residuals.append(r))
    radius = np.linalg.norm(limit_positions(mesh, x, device="cpu", **F64), axis=1).mean() / R
    assert abs(radius - lam) < 1e-3 * abs(1 - lam)  # the same bound as CG's test at level 3 (test_shell.py)
    assert shell.newton_steps == len(residuals) <= 15 and residuals[-1] <= 1e-9
    assert residuals[2] <= 10 * residuals[1] ** 2  # quadratic from 1e-3 down (docs/theory/shell.md)
    assert np.all(np.diff(shell.relax_history) <= 1e-12 * abs(shell.relax_history[0]))


def test_a_later_relaxation_reuses_the_factorization_as_a_preconditioner():
    """Newton's next relaxation (c = 1 → 1.05) solves its steps by CG on the exact Hessian action,
    preconditioned by the first relaxation's factorization, and reaches the closed-form radius."""
    R, h, penalty = 2.0, 0.2, 0.4 * 0.2 / 2.0**4
    mesh = icosphere(R, 3)
    shell = Shell(mesh, h, 1.0, AC=0.5, AI=0.3, volume_penalty=penalty, device="cpu", **F64)
    x = shell.relax(mesh.vertices, 1.0, method="newton")
    finish = shell._newton
    factored = finish.factorizations
    x = shell.relax(x, 1.05, method="newton")
    assert shell.newton_steps > 0 and finish.factorizations == factored and finish.krylov_steps >= shell.newton_steps
    lam = sphere_stretch(0.5, 0.3, h, R, penalty, c=1.05)
    radius = np.linalg.norm(limit_positions(mesh, x, device="cpu", **F64), axis=1).mean() / R
    assert abs(radius - lam) < 1e-3 * abs(1 - lam)
    assert np.linalg.norm(shell.forces(x, 1.05), axis=1).max() / shell.force_scale() <= 1e-9
    assert np.all(np.diff(shell.relax_history) <= 1e-12 * abs(shell.relax_history[0]))


def test_a_factorization_that_does_not_precondition_is_replaced():
    """A preconditioner that is not positive definite stops the Krylov step at once; the step
    factors the current Hessian instead and the relaxation converges as before."""
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, AC=0.3, AI=0.4, volume_penalty=0.5, device="cpu", **F64)
    c = front(mesh)
    reference = shell.relax(mesh.vertices, c, tol=1e-11, method="ncg")
    shell.relax(mesh.vertices, 0.5 * c, method="newton")
    finish = shell._newton
    finish.inverse.solve = lambda f: -f  # negative definite: r·z < 0 at the first iteration
    factored, solved = finish.factorizations, finish.krylov_steps
    x = shell.relax(mesh.vertices, c, tol=1e-11, method="newton")
    assert finish.factorizations > factored and finish.krylov_steps >= solved
    assert np.abs(x - reference).max() < 1e-7


def test_the_factorization_counts_negative_eigenvalues_in_the_complement_of_the_rigid_motions():
    """The inertia of H + W C Wᵀ + shift I in the complement of the rigid motions, from the sparse LU's
    pivots, the volume term's capacitance and the rigid rows' Schur complement, against a dense
    eigensolver of the same matrix compressed to that complement; and the constrained solve is the
    minimum of the quadratic model there (the KKT conditions). The state is far from equilibrium
    (V̄ = 0.9 V): its Hessian has hundreds of negative eigenvalues, rigid rows with curvature, and a
    breathing mode that only the volume term lifts."""
    mesh = icosphere(10.0, 2)
    shell = Shell(mesh, 1.0, 1.0, 0.33, volume_penalty=1.0, device="cpu", **F64)
    shell.rest_volume = 0.9 * shell.rest_volume
    x = mesh.vertices + 0.01 * np.random.default_rng(1).standard_normal(mesh.vertices.shape)
    f = shell.forces(x, 0.0).ravel()
    h, w, coupling = NewtonFinish(shell).hessian(x)
    rigid = rigid_modes(x)
    complement = np.linalg.qr(np.concatenate([rigid.T, np.eye(len(f))], axis=1))[0][:, 6:]

    def spectrum(matrix):
        compressed = complement.T @ matrix @ complement
        return np.linalg.eigvalsh(0.5 * (compressed + compressed.T))

    full = h.toarray() + w @ coupling @ w.T
    dense, sparse_part = spectrum(full), spectrum(h.toarray())
    # a shift where the volume term decides the count: the sparse part alone has one more below zero
    edges = np.sort(-np.concatenate([dense, sparse_part]))
    flips = [s for s in 0.5 * (edges[1:] + edges[:-1]) if (sparse_part + s < 0).sum() != (dense + s < 0).sum()]
    shifts = [1e-8 * np.abs(h.diagonal()).mean(), -0.5 * (dense[0] + dense[1]), -0.5 * (dense[9] + dense[10]),
              -1.5 * dense[0], flips[0]]  # fmt: skip
    rigid_curvature = volume_lift = False
    for shift in shifts:
        inverse = ShiftedInverse(h, w, coupling, shift)
        pivots = int((inverse.lu.U.diagonal() < 0).sum())
        volume_lift |= bool(inverse.capacitance[0, 0] < 0)
        inverse.constrain(rigid)
        assert inverse.negative_eigenvalues() == (dense + shift < 0).sum()
        rigid_curvature |= pivots - int(inverse.capacitance[0, 0] < 0) != inverse.negative_eigenvalues()
        d = inverse.solve(f)
        assert np.abs(rigid @ d).max() < 1e-10 * np.abs(d).max()
        assert np.abs(complement.T @ (full @ d + shift * d - f)).max() < 1e-8 * np.abs(f).max()
    assert (dense < 0).sum() > 100 and rigid_curvature and volume_lift  # every part of the count was needed


def test_newton_keeps_the_stable_equilibrium_next_to_a_bifurcation():
    """A sphere under 0.9 × Zoelly's pressure (level 3, h/R = 0.1, whose crossing is 0.935 × on this
    mesh: test_modes.py) is stable but nearly critical. From the rest sphere, perturbed by 1e-9 R, the
    Levenberg–Marquardt steps used to solve with an indefinite H + shift I (the start is far past
    buckling: V̄ acts as a huge pressure there); their step amplified the perturbation along the soft
    modes and Newton snapped to a dented equilibrium 6 h deep, crawling there for 450 steps. CG, a
    descent method, stays with the sphere (spread 0.026 h). Shifting until the factorization shows a
    positive definite model keeps Newton in that basin as well."""
    R, h, nu, mu = 10.0, 1.0, 0.33, 1.0
    mesh = icosphere(R, 3)
    shell = Shell(mesh, h, 1.0, nu, volume_penalty=mu, device="cpu", **F64)
    p = 0.9 * 2 * h**2 / (R**2 * np.sqrt(3 * (1 - nu**2)))
    strain = p * R * (1 - nu) / (2 * h)
    shell.rest_volume = shell.rest_volume * (1 - strain) ** 3 - p / (2 * mu)
    start = mesh.vertices + 1e-9 * R * np.random.default_rng(0).standard_normal(mesh.vertices.shape)
    x = shell.relax(start, 0.0, method="newton", newton_steps=40)
    radius = np.linalg.norm(x - x.mean(axis=0), axis=1)
    assert radius.max() - radius.min() < 0.05 * h
    assert softest_modes(shell, x, count=1).values[0] > 0


def test_auto_finishes_with_newton_where_cg_spends_its_budget():
    mesh = icosphere(1.0, 2)
    shell = Shell(mesh, 0.05, 1.0, AC=0.3, AI=0.4, volume_penalty=0.5, device="cpu", **F64)
    c = front(mesh)
    reference = shell.relax(mesh.vertices, c, tol=1e-11, method="ncg")  # CG alone, with budget to spare
    with pytest.raises(RelaxationError, match="after 20 iterations"):
        shell.relax(mesh.vertices, c, tol=1e-11, max_iterations=20, method="ncg")
    x = shell.relax(mesh.vertices, c, tol=1e-11, max_iterations=20)  # auto
    history = np.array(shell.relax_history)
    assert shell.newton_steps > 0 and len(history) == 21 + shell.newton_steps
    assert np.all(np.diff(history) <= 1e-12 * abs(history[0]))  # monotone across the hand-over
    assert np.linalg.norm(shell.forces(x, c), axis=1).max() / shell.force_scale() <= 1e-11
    assert np.abs(x - reference).max() < 1e-7


def test_a_float32_shell_is_finished_on_a_float64_twin():
    mesh = icosphere(1.0, 2)
    c = front(mesh)
    parts = dict(thickness=0.05, young=1.0, AC=0.3, AI=0.4, volume_penalty=0.5, device="cpu")
    reference = Shell(mesh, **parts, **F64).relax(mesh.vertices, c, tol=1e-10)
    shell = Shell(mesh, **parts, dtype="float32")
    x = shell.relax(mesh.vertices, c, max_iterations=5)  # auto; tol 1e-5
    assert shell.newton_steps > 0
    assert np.linalg.norm(shell.forces(x, c), axis=1).max() / shell.force_scale() <= ROUND_OFF_SLACK * 1e-5
    assert np.abs(x - reference).max() < 1e-4


def test_quasi_static_counts_the_newton_finishes():
    mesh = icosphere(1.0, 2)
    c0 = np.full(mesh.n_vertices, 1.0)
    shell = Shell(mesh, thickness=0.05, young=1.0, AC=0.3, AI=0.5, device="cpu", **F64)
    run = QuasiStatic(shell, Telegraph(LaplaceBeltrami(mesh, device="cpu", **F64), 1.0, c0=c0), max_iterations=3)
    assert run.newton_finishes == 1 and run.unconverged == 0
    assert np.linalg.norm(shell.forces(run.positions(), c0), axis=1).max() / shell.force_scale() <= run.tol


def test_newton_refuses_self_contact_autodiff_and_unknown_methods():
    mesh = icosphere(1.0, 3)
    shell = Shell(mesh, 0.05, 1.0, AI=0.5, device="cpu", **F64)
    with pytest.raises(ValueError, match="method must be one of ncg, newton, auto"):
        shell.relax(mesh.vertices, 0.5, method="bfgs")
    shell.self_contact = SelfContact(shell)
    with pytest.raises(ValueError, match="does not support self-contact"):
        shell.relax(mesh.vertices, 0.5, method="newton")
    autodiff = Shell(icosphere(1.0, 1), 0.05, 1.0, AI=0.5, gradient="autodiff", device="cpu", **F64)
    with pytest.raises(ValueError, match="needs the analytic forces"):
        autodiff.relax(autodiff.mesh.vertices, 0.5, method="newton")
