"""Adjoint kernels of the walkers' masses and contact weights (docs/theory/gradients.md, "The rest shape"), each with
its launcher: the control points' masses M_J = ρ ∫ N_J dω̄⁰ enter a step through F/M, through the rigid-body motion
the inertial damping acts relative to, and through the implicit contact's M⁻¹ (its coupling and its points'
responses); the area contact's weights a_q = dω̄⁰_q through the spread of its pressures. One float64 world; M̂ and
â are the masses' and the weights' adjoints."""

import warp as wp

from . import one_device

@wp.kernel
def inverse_mass_share_kernel(a: wp.array(dtype=wp.vec3d), b: wp.array(dtype=wp.vec3d),
                              inverse_mass: wp.array(dtype=wp.float64), scale: wp.float64,
                              mass_hat: wp.array(dtype=wp.float64)):  # fmt: skip
    """A term scale a_J · M_J⁻¹ b_J backwards into the masses: M̂_J -= scale a_J·b_J / M_J² (∂M⁻¹/∂M = -M⁻²)."""
    j = wp.tid()
    m = inverse_mass[j]
    mass_hat[j] = mass_hat[j] - scale * m * m * wp.dot(a[j], b[j])


@wp.kernel
def rigid_motion_mass_share_kernel(
    x: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d), rigid: wp.array(dtype=wp.vec3d),
    sums: wp.array(dtype=wp.vec3d), total_mass: wp.float64, rate: wp.float64, mass_hat: wp.array(dtype=wp.float64),
):  # fmt: skip
    """The damping dt η (v_rigid - v) backwards into the masses (rate = dt η; one world): v_rigid_i = v̄ + Ω × r_i,
    v̄ = ΣMv/ΣM, c = ΣMx/ΣM, Ω = I⁻¹ Σ M r × v, I = Σ M (|r|² 1 - r rᵀ), r = x - c. With A = Σŵ and T = I⁻¹ Σ r × ŵ
    (kernels/adjoint.py `damping_solve_kernel`, the same sums): M̂_j += rate [A·(v_j - v̄)/ΣM + (Ω × A)·r_j/ΣM
    + T·(r_j × (v_j - v̄)) - |r_j|² T·Ω + (T·r_j)(r_j·Ω)]."""
    j = wp.tid()
    r = x[j] - rigid[2]
    relative = v[j] - rigid[3]
    omega = rigid[4]
    A = sums[0]
    T = sums[2]
    share = (wp.dot(A, relative) + wp.dot(wp.cross(omega, A), r)) / total_mass
    rotation = wp.dot(T, wp.cross(r, relative)) - wp.dot(r, r) * wp.dot(T, omega) + wp.dot(T, r) * wp.dot(r, omega)
    mass_hat[j] = mass_hat[j] + rate * (share + rotation)


@wp.kernel
def response_share_kernel(o_hat: wp.array(dtype=wp.vec3d), forces: wp.array(dtype=wp.vec3d), scale: wp.float64,
                          response_hat: wp.array(dtype=wp.float64)):  # fmt: skip
    """A sweep's o = u* + scale (G M⁻¹ S f - r f) backwards into the points' responses: r̂_i -= scale ô_i·f_i."""
    i = wp.tid()
    response_hat[i] = response_hat[i] - scale * wp.dot(o_hat[i], forces[i])


@wp.kernel
def point_weight_share_kernel(a: wp.array(dtype=wp.vec3d), b: wp.array(dtype=wp.vec3d),
                              divisor: wp.array(dtype=wp.float64), weight_hat: wp.array(dtype=wp.float64)):  # fmt: skip
    """A spread term a_q b_q weighted by the point's a_q backwards into the weights: â_q += a_q·b_q / divisor_q (the
    divisor undoes a weight already in b, or is 1)."""
    q = wp.tid()
    weight_hat[q] = weight_hat[q] + wp.dot(a[q], b[q]) / divisor[q]


@wp.kernel
def first_component_kernel(values: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.vec3d)):
    """out_i = (values_i, 0, 0): a point scalar as the vector the gather's transpose spreads."""
    i = wp.tid()
    out[i] = wp.vec3d(values[i], wp.float64(0.0), wp.float64(0.0))


@one_device
def eval_inverse_mass_share(a, b, inverse_mass, scale: float, mass_hat) -> None:
    """M̂_J -= scale a_J·b_J / M_J² (`inverse_mass_share_kernel`)."""
    wp.launch(inverse_mass_share_kernel, dim=len(a), inputs=[a, b, inverse_mass, wp.float64(scale)],
              outputs=[mass_hat], device=a.device)  # fmt: skip


@one_device
def eval_rigid_motion_mass_share(x, v, rigid, sums, total_mass: float, rate: float, mass_hat) -> None:
    """M̂ += the damping's rigid-body motion's share (`rigid_motion_mass_share_kernel`), `sums` as the damping's
    adjoint left them."""
    wp.launch(rigid_motion_mass_share_kernel, dim=len(x),
              inputs=[x, v, rigid, sums, wp.float64(total_mass), wp.float64(rate)], outputs=[mass_hat],
              device=x.device)  # fmt: skip


@one_device
def eval_response_share(o_hat, forces, scale: float, response_hat) -> None:
    """r̂ -= scale ô·f (`response_share_kernel`)."""
    wp.launch(response_share_kernel, dim=len(o_hat), inputs=[o_hat, forces, wp.float64(scale)],
              outputs=[response_hat], device=o_hat.device)  # fmt: skip


@one_device
def eval_point_weight_share(a, b, divisor, weight_hat) -> None:
    """â_q += a_q·b_q / divisor_q (`point_weight_share_kernel`)."""
    wp.launch(point_weight_share_kernel, dim=len(a), inputs=[a, b, divisor], outputs=[weight_hat], device=a.device)


@one_device
def eval_first_component(values, out) -> None:
    """out = (values, 0, 0) per point."""
    wp.launch(first_component_kernel, dim=len(values), inputs=[values], outputs=[out], device=values.device)
