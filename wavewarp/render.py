"""`wavewarp render`: a mesh's Loop limit surface to USD, coloured by its mean curvature."""

from __future__ import annotations

import time

import numpy as np

from .device import resolve_device
from .geometry import limit_positions, limit_surface
from .mesh import Mesh
from .usd import UsdAnimation


def vertex_mean_curvature(mesh: Mesh, surface) -> np.ndarray:
    """(V,) mean curvature per control vertex: the area-weighted average over the vertex's triangles."""
    per_triangle = np.bincount(surface.triangle, surface.mean_curvature * surface.area) / np.bincount(
        surface.triangle, surface.area
    )
    weight, value = np.zeros(mesh.n_vertices), np.zeros(mesh.n_vertices)
    triangle_area = np.bincount(surface.triangle, surface.area)
    for k in range(3):
        np.add.at(weight, mesh.triangles[:, k], triangle_area)
        np.add.at(value, mesh.triangles[:, k], triangle_area * per_triangle)
    return value / weight


def render(mesh: Mesh, out: str, *, rule="3", device=None, dtype="float32", name="mesh", surface="loop",
           bake_levels=2) -> dict:  # fmt: skip
    """Write the limit surface of `mesh` to the USD file `out` (`surface` "loop" or "baked" `bake_levels`
    times, as `UsdAnimation`), coloured by mean curvature on its 1st to 99th percentile; returns what
    `--json` prints (sizes, area, Gauss–Bonnet error, the largest limit-point radius, device, wall time)."""
    start = time.perf_counter()
    limit = limit_surface(mesh, rule=rule, device=device, dtype=dtype)
    curvature = vertex_mean_curvature(mesh, limit)
    low, high = np.percentile(curvature, [1, 99])
    with UsdAnimation(out, mesh.triangles, field_name="meanCurvature", field_range=(low, high), surface=surface,
                      bake_levels=bake_levels) as usd:  # fmt: skip
        usd.add_frame(0.0, {"positions": mesh.vertices, "meanCurvature": curvature})
    points = limit_positions(mesh, device=device, dtype=dtype)
    return {"mesh": name, "vertices": mesh.n_vertices, "triangles": mesh.n_triangles, "quadrature_points": len(limit.area),
            "area": limit.total_area, "gauss_bonnet_error": limit.integrate(limit.gauss_curvature) / (4 * np.pi) - 1,
            "max_limit_point_radius": float(np.linalg.norm(points, axis=1).max()), "device": str(resolve_device(device)),
            "dtype": dtype, "wall_time_s": time.perf_counter() - start, "outputs": [out]}  # fmt: skip
