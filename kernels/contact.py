"""External forces on the walkers (docs/theory/dynamics.md), one kernel per term, each with its launcher.

Gravity acts on the control points (exact: ∂/∂x_I of ρ g ∫ z dω̄⁰ is M_I g). Contact and
friction act on the limit points p = L x with velocities u = L v (L the Loop limit mask) and
reach the control points through Lᵀ, which does the same virtual work (f·u = (Lᵀf)·v).

The per-area contact (`Ground(contact="area")`, ours: it converges under refinement) evaluates the
same laws as pressures at the quadrature points of the limit surface, p_q = Σ N_I(q) x_I and
u_q = Σ N_I(q) v_I, and spreads f_q dω̄⁰_q back with the same basis (virtual work again).
The implicit solve of the same laws: kernels/implicit_contact.py.
"""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .limit_surface import basis_row, limit_motion_kernel, patch_scalar


@wp.kernel
def ground_contact_kernel(
    p: wp.array(dtype=Any), u: wp.array(dtype=Any), k: Any, beta: Any,
    normal_force: wp.array(dtype=Any), limit_forces: wp.array(dtype=Any),
):  # fmt: skip
    """Ground z = 0: F_n = max(k z² - β u_z, 0) ẑ where z ≤ 0 (docs/theory/dynamics.md; the max drops adhesion)."""
    i = wp.tid()
    z = p[i][2]
    zero = type(z)(0.0)
    fn = k * z * z - beta * u[i][2]
    if z > zero or fn < zero:  # above ground, or pulling down: no contact force
        fn = zero
    normal_force[i] = fn
    limit_forces[i] = type(p[i])(zero, zero, fn)


@wp.kernel
def friction_kernel(
    u: wp.array(dtype=Any), normal_force: wp.array(dtype=Any), mu: Any, k_f: Any, limit_forces: wp.array(dtype=Any)
):  # fmt: skip
    """F_f = -μ |F_n| tanh(k_f |v_t|) v_t / |v_t|, v_t the velocity tangential to the ground (docs/theory/dynamics.md)."""
    i = wp.tid()
    fn = normal_force[i]
    zero = type(fn)(0.0)
    v_t = type(u[i])(u[i][0], u[i][1], zero)
    speed = wp.length(v_t)
    if speed > zero and fn > zero:
        limit_forces[i] = limit_forces[i] - (mu * fn * wp.tanh(k_f * speed) / speed) * v_t


@wp.func
def limit_transpose_at(
    values: wp.array(dtype=Any), ring_start: wp.array(dtype=wp.int32), ring: wp.array(dtype=wp.int32),
    centre_weight: wp.array(dtype=Any), ring_weight: wp.array(dtype=Any), j: int,
):  # fmt: skip
    """(Lᵀ values)_J = (1 - N_J χ_J) values_J + Σ_{I ∈ ring(J)} χ_I values_I (rings are symmetric)."""
    s = centre_weight[j] * values[j]
    for k in range(ring_start[j], ring_start[j + 1]):
        i = ring[k]
        s += ring_weight[i] * values[i]
    return s


@wp.kernel
def limit_transpose_kernel(
    limit_forces: wp.array(dtype=Any),
    ring_start: wp.array(dtype=wp.int32),
    ring: wp.array(dtype=wp.int32),
    centre_weight: wp.array(dtype=Any),
    ring_weight: wp.array(dtype=Any),
    forces: wp.array(dtype=Any),
):
    """forces_J += (Lᵀ f)_J = (1 - N_J χ_J) f_J + Σ_{I ∈ ring(J)} χ_I f_I (rings are symmetric)."""
    j = wp.tid()
    forces[j] = forces[j] + limit_transpose_at(limit_forces, ring_start, ring, centre_weight, ring_weight, j)


@wp.kernel
def quadrature_motion_kernel(
    x: wp.array(dtype=Any), v: wp.array(dtype=Any), patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32), triangle_type: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any),
    points_per_triangle: int, p: wp.array(dtype=Any), u: wp.array(dtype=Any),
):  # fmt: skip
    """p_q = Σ N_I(q) x_I, u_q = Σ N_I(q) v_I: limit-surface points and velocities at quadrature point q."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    p[q] = patch_scalar(x, patch_start, patch_vertices, basis, t, row)
    u[q] = patch_scalar(v, patch_start, patch_vertices, basis, t, row)


@wp.kernel
def quadrature_spread_kernel(
    pressure: wp.array(dtype=Any), area: wp.array(dtype=Any), patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32), triangle_type: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any),
    points_per_triangle: int, forces: wp.array(dtype=Any),
):  # fmt: skip
    """forces_I += N_I(q) f_q dω̄⁰_q (atomic; only the few points touching the ground add anything)."""
    q = wp.tid()
    f = pressure[q] * area[q]
    zero = area[q] - area[q]
    if f[0] == zero and f[1] == zero and f[2] == zero:
        return
    t, row = basis_row(triangle_type, points_per_triangle, q)
    start = patch_start[t]
    for k in range(patch_start[t + 1] - start):
        wp.atomic_add(forces, patch_vertices[start + k], basis[row, k][0] * f)


declare_overloads(ground_contact_kernel, p="vec3[]", u="vec3[]", k="scalar", beta="scalar", normal_force="scalar[]",
                  limit_forces="vec3[]")  # fmt: skip
declare_overloads(friction_kernel, u="vec3[]", normal_force="scalar[]", mu="scalar", k_f="scalar", limit_forces="vec3[]")
declare_overloads(limit_transpose_kernel, limit_forces="vec3[]", centre_weight="scalar[]", ring_weight="scalar[]",
                  forces="vec3[]")  # fmt: skip
declare_overloads(quadrature_motion_kernel, x="vec3[]", v="vec3[]", basis="vec6[,]", p="vec3[]", u="vec3[]")
declare_overloads(quadrature_spread_kernel, pressure="vec3[]", area="scalar[]", basis="vec6[,]", forces="vec3[]")


# ---------------------------------------------------------------- launchers


def ground_motion(ground, x: wp.array, v: wp.array, mask, patch: list, points: wp.array, velocities: wp.array) -> None:
    """The ground's points and their velocities: limit points p = L x, u = L v (`mask`, "point"), or the
    quadrature points of the limit surface (`patch` tables, "area")."""
    if ground.contact == "point":
        ring = [mask.ring_start, mask.ring, mask.centre_weight, mask.ring_weight]
        wp.launch(limit_motion_kernel, dim=len(points), inputs=[x, v, *ring], outputs=[points, velocities],
                  device=x.device)  # fmt: skip
    else:
        wp.launch(quadrature_motion_kernel, dim=len(points), inputs=[x, v, *patch], outputs=[points, velocities],
                  device=x.device)  # fmt: skip


def spread_to_control_points(ground, point_forces: wp.array, mask, patch: list, rest_area, forces: wp.array) -> None:
    """forces += Lᵀ f (point contact), or Σ_q N_I(q) f_q dω̄⁰_q (area contact: f a pressure)."""
    n = len(point_forces)
    if ground.contact == "point":
        ring = [mask.ring_start, mask.ring, mask.centre_weight, mask.ring_weight]
        wp.launch(limit_transpose_kernel, dim=n, inputs=[point_forces, *ring], outputs=[forces], device=forces.device)
    else:
        wp.launch(quadrature_spread_kernel, dim=n, inputs=[point_forces, rest_area, *patch], outputs=[forces],
                  device=forces.device)  # fmt: skip


@one_device
def eval_ground(ground, x: wp.array, v: wp.array, mask, patch: list, rest_area, points: wp.array, velocities: wp.array,
                normal_force: wp.array, point_forces: wp.array, forces: wp.array) -> None:  # fmt: skip
    """Contact and friction of `ground` (a wavewarp.Ground) on the shell at x, v, added to the control points'
    `forces`: on the limit points (`mask`, Loop's limit mask; "point") or as pressures on the quadrature
    points (`patch` tables, `rest_area` dω̄⁰; "area"). `points`, `velocities`, `normal_force` and
    `point_forces` are scratch over the ground's points."""
    n, s, device = len(points), scalar_of(normal_force), x.device
    ground_motion(ground, x, v, mask, patch, points, velocities)
    wp.launch(ground_contact_kernel, dim=n, inputs=[points, velocities, s(ground.stiffness), s(ground.damping)],
              outputs=[normal_force, point_forces], device=device)  # fmt: skip
    if ground.friction > 0:
        wp.launch(friction_kernel, dim=n, inputs=[velocities, normal_force, s(ground.friction), s(ground.sharpness)],
                  outputs=[point_forces], device=device)  # fmt: skip
    spread_to_control_points(ground, point_forces, mask, patch, rest_area, forces)
