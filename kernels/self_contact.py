"""Self-contact of a shell (ours; the paper has none): parts far apart on the rest surface repel once
they come within the contact distance d in space (docs/theory/shell.md#self-contact).

A double integral over the limit surface at its quadrature points q, with rest areas w_q = dω̄⁰_q:

    E = ½ Σ_q Σ_o w_q w_o φ(|p_q - p_o|),   φ(r) = A (d/r - 1)³ for r < d, else 0,

over pairs whose rest points lie at least the exclusion distance apart (neighbours on the sheet
never interact). φ is C² at r = d and diverges as r → 0, so two sheets cannot be pressed
through each other. Candidates come from a hash grid, rebuilt outside the solver loops.
"""

from typing import Any

import warp as wp

from . import declare_overloads
from .limit_surface import entry_point


@wp.kernel
def self_contact_candidates_kernel(
    grid: wp.uint64, p: wp.array(dtype=Any), rest: wp.array(dtype=Any), radius: Any, exclusion: Any,
    neighbours: wp.array2d(dtype=wp.int32), counts: wp.array(dtype=wp.int32),
):  # fmt: skip
    """Row q: the points o within `radius` of p_q whose rest points are at least `exclusion` from
    q's; counts[q] is their number (it may exceed the row's capacity: the caller grows it)."""
    q = wp.tid()
    capacity = neighbours.shape[1]
    n = int(0)
    o = int(0)
    query = wp.hash_grid_query(grid, p[q], radius)
    while wp.hash_grid_query_next(query, o):
        if o != q and wp.length(p[o] - p[q]) < radius and wp.length(rest[o] - rest[q]) >= exclusion:
            if n < capacity:
                neighbours[q, n] = o
            n += 1
    counts[q] = n


@wp.kernel
def self_contact_pressure_kernel(
    p: wp.array(dtype=Any), area: wp.array(dtype=Any), neighbours: wp.array2d(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32), distance: Any, strength: Any, with_energy: int,
    pressure: wp.array(dtype=Any), energy_density: wp.array(dtype=wp.float64),
):  # fmt: skip
    """pressure_q = -(1/w_q) ∂E/∂p_q = Σ_o w_o 3A u² (d/r²) (p_q - p_o)/r, u = d/r - 1; with
    `with_energy`, energy_density[q] += ½ w_q Σ_o w_o A u³ (the shell's energy terms are there)."""
    q = wp.tid()
    push = p[q] - p[q]
    zero = distance - distance
    energy = zero
    for k in range(wp.min(counts[q], neighbours.shape[1])):
        o = neighbours[q, k]
        gap = p[q] - p[o]
        r = wp.length(gap)
        if r < distance and r > zero:
            u = distance / r - type(r)(1.0)
            energy += area[o] * strength * u * u * u
            push += (area[o] * type(r)(3.0) * strength * u * u * distance / (r * r * r)) * gap
    pressure[q] = push
    if with_energy != 0:
        energy_density[q] = energy_density[q] + wp.float64(type(distance)(0.5) * area[q] * energy)


@wp.kernel
def quadrature_gather_kernel(
    pressure: wp.array(dtype=Any), area: wp.array(dtype=Any), vertex_entry_start: wp.array(dtype=wp.int32),
    vertex_entries: wp.array(dtype=wp.int32), entry_triangle: wp.array(dtype=wp.int32),
    patch_start: wp.array(dtype=wp.int32), triangle_type: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any),
    points_per_triangle: int, forces: wp.array(dtype=Any),
):  # fmt: skip
    """forces_I += Σ_q N_I(q) f_q w_q over the patches I belongs to, in a fixed order (the
    deterministic counterpart of `quadrature_spread_kernel`)."""
    i = wp.tid()
    f = forces[i]
    for e in range(vertex_entry_start[i], vertex_entry_start[i + 1]):
        for point in range(points_per_triangle):
            q, b = entry_point(vertex_entries[e], point, entry_triangle, patch_start, triangle_type, basis,
                               points_per_triangle)  # fmt: skip
            f += (b[0] * area[q]) * pressure[q]
    forces[i] = f


@wp.kernel
def moved_kernel(p: wp.array(dtype=Any), built: wp.array(dtype=Any), far: Any, near: Any,
                 flags: wp.array(dtype=wp.int32), far_slot: int, near_slot: int):  # fmt: skip
    """flags[far_slot] / flags[near_slot] = 1 when some point has left its place at the last
    candidate search by `far` / `near` or more."""
    q = wp.tid()
    moved = wp.length(p[q] - built[q])
    if moved >= far:
        flags[far_slot] = 1
    if moved >= near:
        flags[near_slot] = 1


declare_overloads(self_contact_candidates_kernel, p="vec3[]", rest="vec3[]", radius="scalar", exclusion="scalar")
declare_overloads(self_contact_pressure_kernel, p="vec3[]", area="scalar[]", distance="scalar", strength="scalar",
                  pressure="vec3[]")  # fmt: skip
declare_overloads(quadrature_gather_kernel, pressure="vec3[]", area="scalar[]", basis="vec6[,]", forces="vec3[]")
declare_overloads(moved_kernel, p="vec3[]", built="vec3[]", far="scalar", near="scalar")
