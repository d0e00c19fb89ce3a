"""Loop basis: partition of unity, linear precision, corner limit masks, derivatives (docs/theory/scenes.md)."""

import numpy as np
import pytest
from meshes import bipyramid, limit_mask_reference, torus

from wavewarp.geometry import patch_tables
from wavewarp.mesh import Mesh
from wavewarp.subdivision import extraordinary_rings, patch_basis, regular_basis, regular_rings

VALENCES = range(3, 13)


def rotated_corners(mesh):
    """Rotate the vertex lists of a subdivided mesh's children by their parent index mod 3,
    so that extraordinary vertices occur at every corner of their triangles."""
    return Mesh(mesh.vertices, [np.roll(t, -(k // 4 % 3)) for k, t in enumerate(mesh.triangles)])


def random_parameters(rng, n, margin=0.0):
    v, w = rng.random((2, 4 * n))
    keep = (v + w <= 1 - margin) & (v + w >= margin)
    return v[keep][:n], w[keep][:n]


@pytest.mark.parametrize("valence", VALENCES)
@pytest.mark.parametrize("corner", [0, 1, 2])
def test_partition_of_unity_and_derivative_sums(valence, corner, rng):
    v, w = random_parameters(rng, 20, margin=1e-3)
    basis = patch_basis(valence, corner, v, w)
    assert basis.shape == (len(v), valence + 6, 6)
    np.testing.assert_allclose(basis[..., 0].sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(basis[..., 1:].sum(axis=1), 0.0, atol=1e-10)


@pytest.mark.parametrize("valence", VALENCES)
def test_patches_reproduce_linear_functions_of_position(valence, rng):
    """Isoparametric fields c_I = g·X_I + c0 evaluate to g·x(θ) + c0 with gradient g·x,α."""
    mesh = rotated_corners(bipyramid(valence).subdivided(1))
    tables = patch_tables(mesh)
    g, c0 = rng.normal(size=3), rng.normal()
    field = mesh.vertices @ g + c0
    v, w = random_parameters(rng, 5, margin=1e-3)
    bases = [patch_basis(n, corner, v, w) for n, corner in tables.types]
    for t in range(mesh.n_triangles):
        ring = tables.patch_vertices[tables.patch_start[t] : tables.patch_start[t + 1]]
        basis = bases[tables.triangle_type[t]][:, : len(ring)]
        x = np.einsum("pkc,kd->pcd", basis, mesh.vertices[ring])
        c = np.einsum("pkc,k->pc", basis, field[ring])
        np.testing.assert_allclose(c[:, 0], x[:, 0] @ g + c0, atol=1e-12)
        np.testing.assert_allclose(c[:, 1:], x[:, 1:] @ g, atol=1e-11)


def test_regular_patch_has_linear_precision_on_a_flat_grid(rng):
    """Box splines over a regular planar grid map (v, w) affinely (zero second derivatives)."""
    e1, e2 = np.array([1.0, 0.0]), np.array([0.5, np.sqrt(3) / 2])
    # Stam's regular ring in lattice coordinates of the triangle (p1, p2, p3) = (3, 6, 7)
    lattice = [(0, -1), (-1, 0), (1, -1), (0, 0), (-1, 1), (2, -1), (1, 0), (0, 1), (-1, 2), (2, 0), (1, 1), (0, 2)]
    grid = np.array([i * e1 + j * e2 for i, j in lattice])
    v, w = random_parameters(rng, 30)
    basis = regular_basis(v, w)
    np.testing.assert_allclose(basis[..., 0] @ grid, np.outer(v, e1) + np.outer(w, e2), atol=1e-14)
    np.testing.assert_allclose(basis[..., 1] @ grid, np.tile(e1, (len(v), 1)), atol=1e-13)
    np.testing.assert_allclose(basis[..., 2] @ grid, np.tile(e2, (len(v), 1)), atol=1e-13)
    np.testing.assert_allclose(np.einsum("pkc,kd->pcd", basis[..., 3:], grid), 0.0, atol=1e-12)


@pytest.mark.parametrize("valence", VALENCES)
def test_corner_values_are_the_loop_limit_mask(valence):
    """At each triangle corner the patch evaluates to that vertex's closed-form limit point."""
    mesh = rotated_corners(bipyramid(valence).subdivided(1))
    tables = patch_tables(mesh)
    expected = limit_mask_reference(mesh.vertices, mesh.triangles)
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    bases = [patch_basis(n, corner, corners[:, 0], corners[:, 1])[..., 0] for n, corner in tables.types]
    seen = set()
    for t in range(mesh.n_triangles):
        seen.add(tables.types[tables.triangle_type[t]])
        ring = tables.patch_vertices[tables.patch_start[t] : tables.patch_start[t + 1]]
        values = bases[tables.triangle_type[t]][:, : len(ring)] @ mesh.vertices[ring]
        np.testing.assert_allclose(values, expected[mesh.triangles[t]], atol=1e-13)
    if valence != 6:
        assert {(valence, 0), (valence, 1), (valence, 2)} <= seen


def test_repeated_subdivision_evaluator_at_valence_six_equals_box_splines(rng):
    """The eigen/subdivision path (any corner) must reproduce Stam's box splines exactly."""
    mesh = torus(3.0, 1.0, 12, 8)
    mesh = Mesh(mesh.vertices + 0.1 * rng.normal(size=mesh.vertices.shape), mesh.triangles)
    v, w = random_parameters(rng, 8, margin=1e-3)
    regular = regular_basis(v, w)
    general = [_extraordinary_patch(corner, v, w) for corner in (0, 1, 2)]  # the same for every triangle
    for t in range(0, mesh.n_triangles, 7):
        tri = mesh.triangles[t]
        x_regular = np.einsum("pkc,kd->pcd", regular, mesh.vertices[regular_rings(mesh.topology, tri)[0]])
        for corner in (0, 1, 2):
            ring = extraordinary_rings(mesh.topology, np.roll(tri, -corner), 6)[0]
            x_general = np.einsum("pkc,kd->pcd", general[corner], mesh.vertices[ring])
            np.testing.assert_allclose(x_general, x_regular, atol=1e-11)


def _extraordinary_patch(corner, v, w):
    """patch_basis forced through the repeated-subdivision path (valence 6 treated as special)."""
    from wavewarp import subdivision

    order, jac = subdivision._rotation(corner)
    bary = np.stack([1.0 - v - w, v, w])
    rotated = subdivision._extraordinary_basis(6, bary[order[1]], bary[order[2]])
    out = np.empty_like(rotated)
    out[..., 0] = rotated[..., 0]
    out[..., 1:3] = rotated[..., 1:3] @ jac
    hessian = rotated[..., [3, 4, 4, 5]].reshape(rotated.shape[:-1] + (2, 2))
    hessian = np.einsum("ab,...ac,cd->...bd", jac, hessian, jac)
    out[..., 3], out[..., 4], out[..., 5] = hessian[..., 0, 0], hessian[..., 0, 1], hessian[..., 1, 1]
    return out


@pytest.mark.parametrize("valence", [3, 4, 5, 7, 8, 12])
@pytest.mark.parametrize("corner", [0, 1, 2])
def test_derivatives_match_finite_differences(valence, corner, rng):
    v, w = random_parameters(rng, 6, margin=0.05)
    h = 1e-5
    basis = patch_basis(valence, corner, v, w)
    dv = (patch_basis(valence, corner, v + h, w) - patch_basis(valence, corner, v - h, w)) / (2 * h)
    dw = (patch_basis(valence, corner, v, w + h) - patch_basis(valence, corner, v, w - h)) / (2 * h)
    scale = np.abs(basis[..., 3:]).max()
    np.testing.assert_allclose(dv[..., 0], basis[..., 1], atol=1e-7 * scale)
    np.testing.assert_allclose(dw[..., 0], basis[..., 2], atol=1e-7 * scale)
    np.testing.assert_allclose(dv[..., 1], basis[..., 3], atol=1e-5 * scale)
    np.testing.assert_allclose(dw[..., 1], basis[..., 4], atol=1e-5 * scale)
    np.testing.assert_allclose(dv[..., 2], basis[..., 4], atol=1e-5 * scale)
    np.testing.assert_allclose(dw[..., 2], basis[..., 5], atol=1e-5 * scale)
