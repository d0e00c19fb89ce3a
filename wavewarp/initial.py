"""Initial conditions of the chemical waves (docs/theory/chemistry.md): the outgoing Gaussian pulse and the steady front."""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.linalg import spsolve

from .checks import finite, plain, positive
from .laplace import LaplaceBeltrami


def _origin_point(operator: LaplaceBeltrami, origin) -> np.ndarray:
    if isinstance(origin, (int, np.integer)) and not isinstance(origin, bool):
        if not 0 <= origin < operator.n_vertices:
            raise ValueError(f"origin vertex must lie in [0, {operator.n_vertices}), got {origin}")
        return operator.points()[int(origin)]
    point = np.asarray(origin, dtype=np.float64)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ValueError(f"origin must be a vertex index or a finite point (3,), got {plain(origin)!r}")
    return point


def nodal_normals(operator: LaplaceBeltrami) -> np.ndarray:
    """(V, 3) unit normals at `points()`: area-weighted normals of the polyhedron they span."""
    p, tri = operator.points(), operator.mesh.triangles
    face = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    normal = np.zeros_like(p)
    for k in range(3):
        np.add.at(normal, tri[:, k], face)
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def gaussian_pulse(operator: LaplaceBeltrami, origin, sigma, *, gamma, amplitude=1.0, radius=None, distance="chord"):
    """Outgoing Gaussian pulse (docs/theory/chemistry.md): control values (c0, v0) of

        c = C0 exp(-(s/R)² / (2σ²)),   c_t = -γ ∂c/∂s = γ C0 s / (R² σ²) exp(-(s/R)² / (2σ²)) ≥ 0

    so the total concentration rises. s is the distance from `origin` (a vertex index or a
    point): distance="chord" the straight-line distance (adequate for a narrow pulse),
    "arc" the great-circle distance 2R asin(chord / 2R) on a sphere of radius R. R is `radius`
    (default: the radius of the sphere with the surface's area); σ is dimensionless (the
    paper's oocytes: σ² = 2/R² in its units). Values at `points()`, interpolated.
    """
    sigma, gamma, amplitude = positive("sigma", sigma), positive("gamma", gamma), finite("amplitude", amplitude)
    if distance not in ("chord", "arc"):
        raise ValueError(f"distance must be 'chord' or 'arc', got {distance!r}")
    R = math.sqrt(operator.area / (4 * math.pi)) if radius is None else positive("radius", radius)
    chord = np.linalg.norm(operator.points() - _origin_point(operator, origin), axis=1)
    s = chord if distance == "chord" else 2 * R * np.arcsin(np.minimum(1.0, chord / (2 * R)))
    c = amplitude * np.exp(-((s / R) ** 2) / (2 * sigma**2))
    v = gamma * s / (R**2 * sigma**2) * c
    return operator.control_values(c), operator.control_values(v)


def steady_front(operator: LaplaceBeltrami, origin, *, k, delta, gamma, axis=None):
    """The buckling-mode runs' steady front (docs/theory/chemistry.md, supplement Fig. S1b): control values (c0, v0).

        c = [1 + e^{-δk}] / [1 + e^{k(|z| - δ)}]        (c = 1 at the origin, the front at |z| = δ)
        c_t = -γ (dc/d|z|) |∇_Γ |z||,  |∇_Γ z| = sqrt(1 - (n·ê)²)      (outgoing at speed γ)

    z = (p - x)·ê is the height below the origin p along `axis` ê (default: the outward normal
    at the origin, so z ≥ 0 on a sphere); k (1/length) sets the front's steepness, δ (length)
    its height. n are `nodal_normals`. Values at `points()`, interpolated.
    """
    k, delta, gamma = positive("k", k), positive("delta", delta), positive("gamma", gamma)
    p = _origin_point(operator, origin)
    normals = nodal_normals(operator)
    if axis is None:
        axis = normals[np.argmin(np.linalg.norm(operator.points() - p, axis=1))]
    axis = np.asarray(axis, dtype=np.float64)
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0:
        raise ValueError(f"axis must be a finite non-zero vector (3,), got {plain(axis)!r}")
    axis = axis / np.linalg.norm(axis)
    height = np.abs((p - operator.points()) @ axis)
    e = np.exp(np.minimum(k * (height - delta), 700.0))
    c = (1 + math.exp(-delta * k)) / (1 + e)
    dc_dheight = -(1 + math.exp(-delta * k)) * k * e / (1 + e) ** 2
    slope = np.sqrt(np.maximum(0.0, 1 - (normals @ axis) ** 2))
    return operator.control_values(c), operator.control_values(-gamma * dc_dheight * slope)


def gaussian_pulse_adjoint(mesh, x, origin: int, sigma, c_hat, *, radius, amplitude=1.0) -> tuple:
    """(x̂ (V, 3), σ̂) = ((∂c0/∂x)ᵀ ĉ, ĉ·∂c0/∂σ) of `gaussian_pulse`'s c0 (chord distance from the vertex `origin`) on
    the limit surface of `mesh` at control positions x (V, 3): c0 = L⁻¹ g with g_I = C0 exp(-|p_I - p_o|² / (2σ²R²))
    at the limit points p = L x (L Loop's limit mask), so ĝ = L⁻ᵀ ĉ, p̂_I = -ĝ_I g_I (p_I - p_o) / (σ²R²), p̂_o gains
    minus their sum, x̂ = Lᵀ p̂ and σ̂ = Σ ĝ_I g_I |p_I - p_o|² / (σ³R²), R held (given, as the walkers give it)."""
    n = mesh.n_vertices
    rows, cols, vals = mesh.limit_mask_matrix()
    limit = csr_matrix((vals, (rows, cols)), shape=(n, n))
    points = limit @ np.asarray(x, dtype=np.float64)
    offset = points - points[int(origin)]
    scale = (positive("sigma", sigma) * positive("radius", radius)) ** 2
    g = finite("amplitude", amplitude) * np.exp(-np.sum(offset**2, axis=1) / (2.0 * scale))
    g_hat = spsolve(limit.T.tocsc(), np.asarray(c_hat, dtype=np.float64))
    points_hat = -(g_hat * g)[:, None] * offset / scale
    points_hat[int(origin)] -= points_hat.sum(axis=0)
    sigma_hat = float(np.sum(g_hat * g * np.sum(offset**2, axis=1))) / (scale * sigma)
    return np.asarray(limit.T @ points_hat), sigma_hat
