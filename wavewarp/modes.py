"""Softest deformation modes of a shell at an equilibrium (docs/theory/shell.md#stability-of-an-equilibrium).

The smallest eigenvalues λ of H v = λ M v, with H the Hessian of E_S + E_B + E_V at the positions
(the Newton finish's exact sparse Hessian, wavewarp/newton.py) and M the lumped rest vertex areas
∫ N_I dω̄⁰, so λ is an energy per unit area and per unit displacement², independent of the mesh
size. The six rigid motions are removed. A negative λ means the equilibrium is unstable: the shell
buckles along its mode. Shift-invert Lanczos (SciPy's eigsh) on the factored H − σM, with σ below
every eigenvalue (the factorization's inertia says so).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg

from .checks import plain
from .laplace import LaplaceBeltrami
from .newton import NewtonFinish, ShiftedInverse, rigid_modes

SHIFT = 1e-3  # the first σ: −SHIFT × the mean diagonal of M⁻¹H, below the softest modes of the shells we meet


@dataclass
class Modes:
    values: np.ndarray  # (k,) ascending: energy per unit rest area per unit displacement²
    vectors: np.ndarray  # (k, V, 3), M-orthonormal: Σ_I M_I |v_I|² = 1


def softest_modes(shell, x, c=0.0, count: int = 6) -> Modes:
    """The `count` smallest eigenpairs of the shell's Hessian at positions x under concentrations c
    (docs/theory/shell.md energies), rigid motions removed; x should be an equilibrium (Shell.relax)."""
    if shell.self_contact is not None:
        raise ValueError("softest_modes: self-contact is not in the Hessian; build the shell with self_contact=None")
    largest = 3 * shell.mesh.n_vertices - 7  # eigsh needs count < n, less the six rigid motions
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 1 <= count <= largest:
        raise ValueError(f"count must be an integer from 1 to {largest} for this mesh, got {plain(count)!r}")
    x = np.asarray(x, dtype=np.float64)
    shell.forces(x, c)  # sets the active reference for c
    newton = shell._newton or NewtonFinish(shell)
    shell._newton = newton
    newton.share_reference()
    h, w, coupling = newton.hessian(x)
    area = LaplaceBeltrami(shell.mesh, rule=shell.rule, device=shell.device, dtype="float64").mass()
    scale = sparse.diags(np.repeat(area, 3) ** -0.5)
    h, w = (scale @ h @ scale).tocsr(), scale @ w
    rigid, _ = np.linalg.qr((rigid_modes(x) * np.repeat(area, 3) ** 0.5).T)
    rigid = rigid.T

    def project(v):
        return v - rigid.T @ (rigid @ v)

    def action(v):
        v = project(v)
        return project(h @ v + w @ (coupling @ (w.T @ v)))

    n = h.shape[0]
    sigma = -SHIFT * float(np.abs(h.diagonal()).mean())
    inverse = ShiftedInverse(h, w, coupling, -sigma)
    inverse.constrain(rigid)
    while inverse.negative_eigenvalues() > 0:  # H − σM has eigenvalues below σ
        sigma *= 4.0
        inverse = ShiftedInverse(h, w, coupling, -sigma)
        inverse.constrain(rigid)
    # every eigenvalue lies above σ, so the `count` nearest σ are the smallest
    values, vectors = sparse_linalg.eigsh(
        sparse_linalg.LinearOperator((n, n), action, dtype=np.float64), k=count, sigma=sigma, which="LM",
        OPinv=sparse_linalg.LinearOperator((n, n), inverse.solve, dtype=np.float64),  # in the complement (KKT)
    )  # fmt: skip
    order = np.argsort(values)
    vectors = (vectors[:, order].T * np.repeat(area, 3) ** -0.5).reshape(count, -1, 3)
    return Modes(values[order], vectors)


def azimuthal_order(x, mode, axis=(0.0, 0.0, 1.0), largest: int = 16) -> int:
    """The azimuthal order m (0 ≤ m ≤ largest) that carries most of `mode` about the line through the
    centroid of x along `axis`: Fourier power of the mode's cylindrical components, summed."""
    x, mode = np.asarray(x, dtype=np.float64), np.asarray(mode, dtype=np.float64)
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    r = x - x.mean(axis=0)
    radial = r - np.outer(r @ axis, axis)
    distance = np.linalg.norm(radial, axis=1)
    keep = distance > 1e-6 * distance.max()  # points on the axis have no azimuth
    e_r = radial[keep] / distance[keep, None]
    e_phi = np.cross(axis, e_r)
    first = np.cross(axis, np.eye(3)[np.argmin(np.abs(axis))])
    first /= np.linalg.norm(first)
    phi = np.arctan2(e_r @ np.cross(axis, first), e_r @ first)
    v = mode[keep]
    components = (np.einsum("ij,ij->i", v, e_r), np.einsum("ij,ij->i", v, e_phi), v @ axis)
    power = [sum(abs(np.sum(f * np.exp(-1j * m * phi))) ** 2 for f in components) for m in range(largest + 1)]
    return int(np.argmax(power))

