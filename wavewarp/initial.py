"""Initial conditions of the chemical waves (docs/theory/chemistry.md): the outgoing Gaussian pulse and the steady front."""

from __future__ import annotations

import math

import numpy as np

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
