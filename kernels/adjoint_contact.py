"""Adjoint kernels of the walkers' ground laws (docs/theory/gradients.md, "Reverse mode"), each with its launcher: the
explicit law at the limit points, the implicit law at a point, and the body frame's Weiszfeld steps for the horizontal
body velocity U (kernels/contact.py, kernels/implicit_contact.py). One float64 world; the parameter gradients are summed atomically."""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .implicit_contact import friction_magnitude, friction_slope_at_rest, implicit_normal_force
from .implicit_contact import slip_speed as slip_root
from .reduce import REDUCTION_BLOCK, block_add, whole_blocks

LawGradient = wp.types.vector(length=5, dtype=wp.float64)  # ∂/∂(k, β, μ, k_f, r) of one point's law


@wp.func
def friction_factor(speed: Any, k_f: Any):
    """(φ, φ'/s) of φ(s) = tanh(k_f s)/s, by its series where k_f s is small (φ → k_f, φ'/s → -2k_f³/3)."""
    ks = k_f * speed
    if ks < type(ks)(1e-4):
        return k_f * (type(ks)(1.0) - ks * ks / type(ks)(3.0)), type(ks)(-2.0 / 3.0) * k_f * k_f * k_f
    t = wp.tanh(ks)
    phi = t / speed
    return phi, (k_f * (type(ks)(1.0) - t * t) - phi) / (speed * speed)


@wp.kernel
def ground_adjoint_kernel(
    p: wp.array(dtype=Any), u: wp.array(dtype=Any), force_hat: wp.array(dtype=Any), k: Any, beta: Any, mu: Any,
    k_f: Any, p_hat: wp.array(dtype=Any), u_hat: wp.array(dtype=Any), gradient: wp.array(dtype=wp.float64),
):  # fmt: skip
    """Adjoint of the explicit ground law at a limit point (kernels/contact.py: F_n = max(k z² - β u_z, 0) where z ≤ 0,
    F_f = -μ F_n φ(|u_t|) u_t with φ(s) = tanh(k_f s)/s), given f̂ = L F̂: p̂, û (overwritten) and
    gradient[0..3] += ∂/∂(k, β, μ, k_f) of f̂ · f."""
    i = wp.tid()
    a = force_hat[i]
    z = p[i][2]
    zero = type(z)(0.0)
    fn = k * z * z - beta * u[i][2]
    p_hat[i] = type(a)()
    u_hat[i] = type(a)()
    if z > zero or fn < zero:
        return
    u_t = type(a)(u[i][0], u[i][1], zero)
    a_t = type(a)(a[0], a[1], zero)
    phi, slope = friction_factor(wp.length(u_t), k_f)
    load = wp.dot(a_t, u_t)
    fn_hat = a[2] - mu * phi * load
    u_hat_t = -(mu * fn) * (phi * a_t + (slope * load) * u_t)
    speed = wp.length(u_t)
    ks = k_f * speed
    sech2 = type(z)(1.0) - wp.tanh(ks) * wp.tanh(ks)
    p_hat[i] = type(a)(zero, zero, type(z)(2.0) * k * z * fn_hat)
    u_hat[i] = u_hat_t + type(a)(zero, zero, -beta * fn_hat)
    wp.atomic_add(gradient, 0, wp.float64(fn_hat * z * z))
    wp.atomic_add(gradient, 1, wp.float64(-fn_hat * u[i][2]))
    wp.atomic_add(gradient, 2, wp.float64(-fn * phi * load))
    wp.atomic_add(gradient, 3, wp.float64(-mu * fn * sech2 * load))


@wp.func
def law_adjoint(z: wp.float64, u: wp.vec3d, r: wp.float64, dt: wp.float64, k: wp.float64, beta: wp.float64,
                mu: wp.float64, k_f: wp.float64, a: wp.vec3d, h_seed: wp.float64):  # fmt: skip
    """Adjoint of the implicit ground law at a point (kernels/implicit_contact.py `implicit_contact_kernel`) with slip velocity u
    (the point's velocity without friction, plus U in the body frame) and response r: F_n = max((kz² - β'u_z)/(1 +
    β'r), 0), β' = β - 2kz dt, friction -|f_t| u_t/|u_t| with |f_t| = min(μF_n, |u_t|/r) (Coulomb, k_f = ∞) or
    μF_n tanh(k_f s), s + rμF_n tanh(k_f s) = |u_t| (differentiated implicitly). Given f̂ = a and the adjoint h_seed of |f_t|/|u_t| (the
    Weiszfeld step's stiffness): (û, ẑ, ∂/∂(k, β, μ, k_f, r)) of a · f + h_seed |f_t|/|u_t|."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    two = wp.float64(2.0)
    damping = beta - two * k * z * dt
    denominator = one + damping * r
    fn = (k * z * z - damping * u[2]) / denominator
    grads = LawGradient()
    if z > zero or fn < zero:
        return wp.vec3d(), zero, grads
    fn_hat = a[2]
    r_hat = zero
    v_t = wp.vec3d(u[0], u[1], zero)
    speed = wp.length(v_t)
    u_t_hat = wp.vec3d()
    if speed > zero and fn > zero:
        d = v_t / speed
        cap = mu * fn
        a_t = wp.vec3d(a[0], a[1], zero)
        a_slip = r * cap
        s = zero
        th = zero
        magnitude = wp.min(cap, speed / r)
        if not wp.isinf(k_f):
            s = wp.min(slip_root(speed, a_slip, k_f), speed)
            th = wp.tanh(k_f * s)
            magnitude = cap * th
        magnitude_hat = -wp.dot(a_t, d) + h_seed / speed
        u_t_hat = -(magnitude / speed) * (a_t - wp.dot(a_t, d) * d)
        cap_hat = zero
        speed_hat = -h_seed * magnitude / (speed * speed)
        if wp.isinf(k_f):
            if cap < speed / r:
                cap_hat = magnitude_hat
            else:
                speed_hat = speed_hat + magnitude_hat / r
                r_hat = -magnitude_hat * speed / (r * r)
        else:
            sech2 = one - th * th
            slope = one + a_slip * k_f * sech2  # ∂/∂s of s + a tanh(k_f s)
            s_hat = magnitude_hat * cap * k_f * sech2
            speed_hat = speed_hat + s_hat / slope
            slip_hat = -s_hat * th / slope  # ∂s/∂a
            cap_hat = magnitude_hat * th + slip_hat * r
            r_hat = slip_hat * cap
            grads[3] = magnitude_hat * cap * s * sech2 - s_hat * a_slip * s * sech2 / slope
        u_t_hat = u_t_hat + speed_hat * d
        fn_hat = fn_hat + mu * cap_hat
        grads[2] = fn * cap_hat
    damping_hat = -fn_hat * (u[2] + fn * r) / denominator
    u_hat = u_t_hat + wp.vec3d(zero, zero, -fn_hat * damping / denominator)
    z_hat = fn_hat * two * k * z / denominator - damping_hat * two * k * dt
    grads[0] = fn_hat * z * z / denominator - damping_hat * two * z * dt
    grads[1] = damping_hat
    grads[4] = r_hat - fn_hat * fn * damping / denominator
    return u_hat, z_hat, grads


@wp.func
def add_law_gradient(gradient: wp.array(dtype=wp.float64), grads: LawGradient, response: wp.float64):
    """gradient[0..3] += ∂/∂(k, β, μ, k_f) and gradient[4] += ∂/∂scale (r = scale × response)."""
    for slot in range(4):
        wp.atomic_add(gradient, slot, grads[slot])
    wp.atomic_add(gradient, 4, grads[4] * response)


@wp.kernel
def implicit_law_adjoint_kernel(
    p: wp.array(dtype=wp.vec3d), u: wp.array(dtype=wp.vec3d), response: wp.array(dtype=wp.float64),
    scale: wp.float64, dt: wp.float64, k: wp.float64, beta: wp.float64, mu: wp.float64, k_f: wp.float64,
    force_hat: wp.array(dtype=wp.vec3d), u_hat: wp.array(dtype=wp.vec3d), p_hat: wp.array(dtype=wp.vec3d),
    gradient: wp.array(dtype=wp.float64), response_hat: wp.array(dtype=wp.float64),
):  # fmt: skip
    """The implicit law's adjoint at every point (`law_adjoint`; u the slip velocities) given f̂: u_hat = û
    (overwritten), p_hat += (0, 0, ẑ), the gradient's slots (`add_law_gradient`), response_hat += the point's r̂."""
    i = wp.tid()
    o_hat, z_hat, grads = law_adjoint(p[i][2], u[i], scale * response[i], dt, k, beta, mu, k_f, force_hat[i],
                                      wp.float64(0.0))  # fmt: skip
    u_hat[i] = o_hat
    if z_hat != wp.float64(0.0) or wp.length_sq(o_hat) > wp.float64(0.0):
        p_hat[i] = p_hat[i] + wp.vec3d(wp.float64(0.0), wp.float64(0.0), z_hat)
        add_law_gradient(gradient, grads, response[i])
        response_hat[i] = response_hat[i] + scale * grads[4]


@wp.kernel
def horizontal_sum_kernel(values: wp.array(dtype=wp.vec3d), total: wp.array(dtype=wp.vec3d)):
    """total[0] += Σ_i (values_i,x, values_i,y, 0) (whole blocks: the threads past the values add zero)."""
    i = wp.tid()
    value = wp.vec3d()
    if i < values.shape[0]:
        value = wp.vec3d(values[i][0], values[i][1], wp.float64(0.0))
    block_add(total, 0, value)


@wp.kernel
def body_step_seeds_kernel(force_sum: wp.array(dtype=wp.vec3d), stiffness_sum: wp.array(dtype=wp.float64),
                           external: wp.array(dtype=wp.vec3d), body_hat: wp.array(dtype=wp.vec3d),
                           force_hat: wp.array(dtype=wp.vec3d), stiffness_hat: wp.array(dtype=wp.float64)):  # fmt: skip
    """A Weiszfeld step U' = U + G/h (kernels/implicit_contact.py `body_velocity_kernel`, G = Σ a f_t + external) backwards from
    Û': Ĝ = Û'/h, ĥ = -Û'·G/h² (none where h = 0: the step left U as it was)."""
    h = stiffness_sum[0]
    force_hat[0] = wp.vec3d()
    stiffness_hat[0] = wp.float64(0.0)
    if h > wp.float64(0.0):
        force_hat[0] = body_hat[0] / h
        stiffness_hat[0] = -wp.dot(body_hat[0], force_sum[0] + external[0]) / (h * h)


@wp.kernel
def body_step_adjoint_kernel(
    p: wp.array(dtype=wp.vec3d), u: wp.array(dtype=wp.vec3d), body: wp.array(dtype=wp.vec3d),
    response: wp.array(dtype=wp.float64), weight: wp.array(dtype=wp.float64), scale: wp.float64, dt: wp.float64,
    k: wp.float64, beta: wp.float64, mu: wp.float64, k_f: wp.float64, force_hat: wp.array(dtype=wp.vec3d),
    stiffness_hat: wp.array(dtype=wp.float64), u_hat: wp.array(dtype=wp.vec3d), p_hat: wp.array(dtype=wp.vec3d),
    gradient: wp.array(dtype=wp.float64), body_hat: wp.array(dtype=wp.vec3d), response_hat: wp.array(dtype=wp.float64),
    weight_hat: wp.array(dtype=wp.float64),
):  # fmt: skip
    """Each point's share of a Weiszfeld step's adjoint, given Ĝ and ĥ (`body_step_seeds_kernel`): the point's law at
    slip velocity y = u + U seeded with f̂ = a Ĝ (horizontal) and a ĥ on |f_t|/|y|; u_hat += ŷ, p_hat += ẑ, the
    gradient's slots, r̂ (response_hat), and Û += Σ ŷ's horizontal part (y = u + U); where `weight_hat` has the
    points, their weights' adjoint â_q += Ĝ·f_t,q + ĥ |f_t,q|/|y_q| (the law's slope at rest where y = 0). Whole
    blocks: the threads past the points add zero."""
    i = wp.tid()
    value = wp.vec3d()
    if i < p.shape[0]:
        zero = wp.float64(0.0)
        y = u[i] + wp.vec3d(body[0][0], body[0][1], zero)
        a = weight[i] * wp.vec3d(force_hat[0][0], force_hat[0][1], zero)
        y_hat, z_hat, grads = law_adjoint(p[i][2], y, scale * response[i], dt, k, beta, mu, k_f, a,
                                          weight[i] * stiffness_hat[0])  # fmt: skip
        u_hat[i] = u_hat[i] + y_hat
        p_hat[i] = p_hat[i] + wp.vec3d(zero, zero, z_hat)
        add_law_gradient(gradient, grads, response[i])
        response_hat[i] = response_hat[i] + scale * grads[4]
        value = wp.vec3d(y_hat[0], y_hat[1], zero)
        if weight_hat.shape[0] > 0:
            r = scale * response[i]
            fn = implicit_normal_force(p[i][2], u[i][2], r, dt, k, beta)
            if fn > zero:
                slip = wp.vec3d(y[0], y[1], zero)
                speed = wp.length(slip)
                share = stiffness_hat[0] * friction_slope_at_rest(r, mu * fn, k_f)
                if speed > zero:
                    m = friction_magnitude(speed, r, mu * fn, k_f) / speed
                    share = stiffness_hat[0] * m - m * wp.dot(force_hat[0], slip)
                weight_hat[i] = weight_hat[i] + share
    block_add(body_hat, 0, value)


declare_overloads(ground_adjoint_kernel, p="vec3[]", u="vec3[]", force_hat="vec3[]", k="scalar", beta="scalar",
                  mu="scalar", k_f="scalar", p_hat="vec3[]", u_hat="vec3[]")  # fmt: skip


def implicit_laws(ground, scale: float, dt: float) -> list:
    """The implicit ground law's launch arguments after the points' arrays (float64): scale, dt, k, β, μ, k_f."""
    return [wp.float64(value) for value in (scale, dt, ground.stiffness, ground.damping, ground.friction,
                                            ground.sharpness)]  # fmt: skip


@one_device
def eval_implicit_law_adjoint(ground, p, u, response, scale: float, dt: float, force_hat, u_hat, p_hat,
                              gradient, response_hat) -> None:  # fmt: skip
    """û (overwritten) and p̂ += ẑ of the implicit ground law at every point given f̂; gradient[0..4] += ∂/∂(k, β, μ,
    k_f, scale), response_hat += r̂ (`implicit_law_adjoint_kernel`; u the slip velocities)."""
    wp.launch(implicit_law_adjoint_kernel, dim=len(p), inputs=[p, u, response, *implicit_laws(ground, scale, dt),
                                                               force_hat],
              outputs=[u_hat, p_hat, gradient, response_hat], device=p.device)  # fmt: skip


@one_device
def eval_horizontal_sum(values, total) -> None:
    """total[0] += Σ values' horizontal parts."""
    wp.launch(horizontal_sum_kernel, dim=whole_blocks(len(values)), inputs=[values], outputs=[total],
              block_dim=REDUCTION_BLOCK, device=values.device)  # fmt: skip


@one_device
def eval_body_step_adjoint(ground, p, u, body, response, weight, scale: float, dt: float, sums: list, external,
                           seeds: list, u_hat, p_hat, gradient, body_hat, response_hat, weight_hat) -> None:  # fmt: skip
    """A Weiszfeld step of the body velocity backwards (`body_step_seeds_kernel`, `body_step_adjoint_kernel`): `sums`
    the step's (G - external, h) at U = `body`, `seeds` scratch for (Ĝ, ĥ); body_hat: Û' in, Û out."""
    device = p.device
    wp.launch(body_step_seeds_kernel, dim=1, inputs=[*sums, external, body_hat], outputs=seeds, device=device)
    wp.launch(body_step_adjoint_kernel, dim=whole_blocks(len(p)),
              inputs=[p, u, body, response, weight, *implicit_laws(ground, scale, dt), *seeds],
              outputs=[u_hat, p_hat, gradient, body_hat, response_hat, weight_hat], block_dim=REDUCTION_BLOCK,
              device=device)  # fmt: skip


@one_device
def eval_ground_adjoint(ground, p, u, force_hat, p_hat, u_hat, gradient) -> None:
    """p̂, û of the explicit ground law at the limit points, and its parameters' gradient[0..3] (k, β, μ, k_f)."""
    s = scalar_of(p_hat)
    wp.launch(ground_adjoint_kernel, dim=len(p), inputs=[p, u, force_hat, s(ground.stiffness), s(ground.damping),
                                                         s(ground.friction), s(ground.sharpness)],
              outputs=[p_hat, u_hat, gradient], device=p.device)  # fmt: skip
