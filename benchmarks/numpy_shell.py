"""The vectorised NumPy implementation of the Koiter energy and its gradient (docs/theory/shell.md).

The baseline a researcher would write: identical discretisation (same patch tables, same
quadrature, same active reference and volume term), computed with NumPy array operations,
triangles of one patch type at a time and in chunks to bound memory. Used by
`benchmarks/shell.py` for the speed ratio and by the tests as an independent computation.
"""

from __future__ import annotations

import numpy as np

from wavewarp.geometry import patch_tables


def _inv2(m):
    det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    inv = np.empty_like(m)
    inv[..., 0, 0], inv[..., 1, 1] = m[..., 1, 1] / det, m[..., 0, 0] / det
    inv[..., 0, 1], inv[..., 1, 0] = -m[..., 0, 1] / det, -m[..., 1, 0] / det
    return inv, det


def _groups(tables, chunk):
    """(triangle ids, basis (P, K, 6), rings (n, K)) per patch type, in chunks of triangles."""
    P = tables.points_per_triangle
    for type_id, (valence, _) in enumerate(tables.types):
        members = np.flatnonzero(tables.triangle_type == type_id)
        k = valence + 6
        basis = tables.basis[type_id * P : (type_id + 1) * P, :k]
        for start in range(0, len(members), chunk):
            ids = members[start : start + chunk]
            rings = tables.patch_vertices[tables.patch_start[ids][:, None] + np.arange(k)]
            yield ids, basis, rings


def _jet(basis, x_ring):
    """(n, P, 6, 3): x, x,1, x,2, x,11, x,12, x,22 at every point."""
    return np.einsum("pkc,nkd->npcd", basis, x_ring)


def _forms(jet):
    x1, x2 = jet[:, :, 1], jet[:, :, 2]
    cross = np.cross(x1, x2)
    j = np.linalg.norm(cross, axis=-1)
    n = cross / j[..., None]
    a = np.stack([np.einsum("...i,...i", u, v) for u in (x1, x2) for v in (x1, x2)], -1).reshape(j.shape + (2, 2))
    second = jet[:, :, [3, 4, 4, 5]]
    b = np.einsum("...i,...ki->...k", n, second).reshape(j.shape + (2, 2))
    return a, b, n, j, cross


class NumpyShell:
    """Energy and forces of `wavewarp.Shell` with the same parameters, in NumPy float64."""

    def __init__(self, mesh, thickness, young, poisson=0.33, AC=0.0, AI=0.0, volume_penalty=0.0, rule="3",
                 chunk=20000):  # fmt: skip
        self.mesh, self.tables, self.chunk = mesh, patch_tables(mesh, rule), chunk
        nu = poisson
        self.nu, self.AC, self.AI, self.mu = nu, AC, AI, volume_penalty
        self.ks, self.kb = young * thickness / (8 * (1 - nu**2)), young * thickness**3 / (24 * (1 - nu**2))
        self.rest = {}
        for ids, basis, rings in _groups(self.tables, chunk):
            a, b, *_ = _forms(_jet(basis, mesh.vertices[rings]))
            self.rest[ids[0]] = (a, b)
        self.rest_volume = self._volume(mesh.vertices)[0]

    def _volume(self, x):
        w = self.tables.weights
        centroid = x.mean(axis=0)
        volume, normal_sum = 0.0, np.zeros(3)
        for ids, basis, rings in _groups(self.tables, self.chunk):
            jet = _jet(basis, x[rings])
            cross = np.cross(jet[:, :, 1], jet[:, :, 2]) * (w[None, :, None] / 3)
            volume += np.einsum("npi,npi->", jet[:, :, 0] - centroid, cross)
            normal_sum += cross.sum(axis=(0, 1))
        return volume, normal_sum, centroid

    def energy_and_forces(self, x, c):
        x, c = np.asarray(x, dtype=np.float64), np.asarray(c, dtype=np.float64)
        nu, w = self.nu, self.tables.weights
        forces = np.zeros_like(x)
        energy = 0.0
        if self.mu > 0:
            volume, normal_sum, centroid = self._volume(x)
            dv = volume - self.rest_volume
            energy += self.mu * dv**2
            forces += 2 * self.mu * dv * normal_sum / len(x)
        for ids, basis, rings in _groups(self.tables, self.chunk):
            jet = _jet(basis, x[rings])
            a, b, n, j, cross = _forms(jet)
            a0, b0 = self.rest[ids[0]]
            cq = np.einsum("pk,nk->np", basis[..., 0], c[rings])
            stretch = np.exp(-self.AC * cq)[..., None, None]
            a_bar, b_bar = stretch * a0, (1 - self.AI * cq)[..., None, None] * b0
            inv, det = _inv2(a_bar)
            weight = np.sqrt(det) * w[None, :]
            membrane, bending = inv @ (a - a_bar), inv @ (b - b_bar)
            tr_m, tr_b = np.trace(membrane, axis1=-2, axis2=-1), np.trace(bending, axis1=-2, axis2=-1)
            density = self.ks * ((1 - nu) * np.trace(membrane @ membrane, axis1=-2, axis2=-1) + nu * tr_m**2)
            density += self.kb * ((1 - nu) * np.trace(bending @ bending, axis1=-2, axis2=-1) + nu * tr_b**2)
            energy += np.sum(density * weight)
            S = (self.ks * weight)[..., None, None] * (2 * (1 - nu) * membrane @ inv + (2 * nu * tr_m)[..., None, None] * inv)
            B = (self.kb * weight)[..., None, None] * (2 * (1 - nu) * bending @ inv + (2 * nu * tr_b)[..., None, None] * inv)
            x1, x2, x11, x12, x22 = (jet[:, :, k] for k in range(1, 6))
            g = np.zeros(jet.shape)
            g[:, :, 1] = 2 * (S[..., 0, 0, None] * x1 + S[..., 0, 1, None] * x2)
            g[:, :, 2] = 2 * (S[..., 1, 0, None] * x1 + S[..., 1, 1, None] * x2)
            m = B[..., 0, 0, None] * x11 + 2 * B[..., 0, 1, None] * x12 + B[..., 1, 1, None] * x22
            u = (m - np.einsum("...i,...i", n, m)[..., None] * n) / j[..., None]
            g[:, :, 1] += np.cross(x2, u)
            g[:, :, 2] += np.cross(u, x1)
            g[:, :, 3], g[:, :, 4], g[:, :, 5] = B[..., 0, 0, None] * n, 2 * B[..., 0, 1, None] * n, B[..., 1, 1, None] * n
            if self.mu > 0:
                scale = (2 / 3 * self.mu * dv * w)[None, :, None]
                r = jet[:, :, 0] - centroid
                g[:, :, 0] += scale * cross
                g[:, :, 1] += scale * np.cross(x2, r)
                g[:, :, 2] += scale * np.cross(r, x1)
            contribution = -np.einsum("pkc,npcd->nkd", basis, g)
            for d in range(3):
                forces[:, d] += np.bincount(rings.reshape(-1), contribution[..., d].reshape(-1), len(x))
        return energy, forces
