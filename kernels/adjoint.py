"""Adjoint kernels of the walkers' overdamped step and shell (docs/theory/gradients.md, "Reverse mode"), each with its
launcher (the ground laws': kernels/adjoint_contact.py). One world; the accumulators (norms, parameter gradients) are
float64 and summed atomically."""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .limit_surface import basis_row, patch_jet, patch_scalar
from .reduce import REDUCTION_BLOCK, block_add, whole_blocks
from .shell import (
    VolumeMoments,
    koiter_jet,
    material_stress,
    moments_normal_sum,
    volume_centroid_force,
    world_volume_terms,
)

ShellRates = wp.types.vector(length=6, dtype=wp.float64)  # `shell_rates_kernel`'s six sums


@wp.kernel
def largest_component_kernel(d: wp.array(dtype=Any), largest: wp.array(dtype=wp.float64)):
    """largest[0] = max over i of the largest |component| of d_i (zeroed by the caller)."""
    i = wp.tid()
    a = d[i]
    wp.atomic_max(largest, 0, wp.float64(wp.max(wp.max(wp.abs(a[0]), wp.abs(a[1])), wp.abs(a[2]))))


@wp.kernel
def probe_kernel(x: wp.array(dtype=Any), d: wp.array(dtype=Any), largest: wp.array(dtype=wp.float64), step: Any,
                 out: wp.array(dtype=Any)):  # fmt: skip
    """out = x + step d / max|d| (x where d = 0): a probe at a fixed length `step` along d."""
    i = wp.tid()
    size = largest[0]
    if size > wp.float64(0.0):
        out[i] = x[i] + (step / type(step)(size)) * d[i]
    else:
        out[i] = x[i]


@wp.kernel
def directional_difference_kernel(plus: wp.array(dtype=Any), minus: wp.array(dtype=Any),
                                  largest: wp.array(dtype=wp.float64), step: Any, out: wp.array(dtype=Any)):  # fmt: skip
    """out += (plus - minus) max|d| / (2 step): the central difference of F(x ± step d/max|d|), the derivative along d."""
    i = wp.tid()
    out[i] = out[i] + (type(step)(largest[0]) / (type(step)(2.0) * step)) * (plus[i] - minus[i])


@wp.kernel
def weighted_dot_kernel(a: wp.array(dtype=Any), b: wp.array(dtype=Any), weight: wp.float64, slot: int,
                        total: wp.array(dtype=wp.float64)):  # fmt: skip
    """total[slot] += weight Σ a_i · b_i."""
    i = wp.tid()
    wp.atomic_add(total, slot, weight * wp.float64(wp.dot(a[i], b[i])))


@wp.kernel
def damping_sums_kernel(w_hat: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.vec3d), mass: wp.array(dtype=wp.float64),
                        rigid: wp.array(dtype=wp.vec3d), sums: wp.array(dtype=wp.vec3d),
                        second_moment: wp.array(dtype=wp.mat33d)):  # fmt: skip
    """One world: sums[0] += Σ ŵ_i, sums[1] += Σ r_i × ŵ_i, second_moment[0] += Σ M_i r_i r_iᵀ (r = x - c, c = rigid[2])."""
    i = wp.tid()
    r = x[i] - rigid[2]
    wp.atomic_add(sums, 0, w_hat[i])
    wp.atomic_add(sums, 1, wp.cross(r, w_hat[i]))
    wp.atomic_add(second_moment, 0, mass[i] * wp.outer(r, r))


@wp.kernel
def damping_solve_kernel(sums: wp.array(dtype=wp.vec3d), second_moment: wp.array(dtype=wp.mat33d)):
    """sums[2] = T = I⁻¹ Σ r × ŵ, I = tr(S) 1 - S the inertia about the centre (one thread)."""
    S = second_moment[0]
    sums[2] = wp.inverse(wp.trace(S) * wp.identity(n=3, dtype=wp.float64) - S) * sums[1]


@wp.kernel
def damping_adjoint_kernel(
    w_hat: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d),
    mass: wp.array(dtype=wp.float64), rigid: wp.array(dtype=wp.vec3d), sums: wp.array(dtype=wp.vec3d),
    total_mass: wp.float64, rate: wp.float64, x_hat: wp.array(dtype=wp.vec3d), v_hat: wp.array(dtype=wp.vec3d),
):  # fmt: skip
    """Adjoint of the damping dt η (v_rigid(x, v) - v) in v' (rate = dt η; one world): v_rigid_i = v̄ + Ω × r_i with
    v̄ = ΣMv/ΣM, Ω = I⁻¹ Σ M r × v, r = x - c. With A = Σŵ, T = I⁻¹ Σ r × ŵ (`damping_solve_kernel`), P = ΣM v̄:
    v̂_j = ŵ_j (1 - rate) + rate M_j (A/ΣM + T × r_j) and x̂_j += rate [ŵ_j × Ω - (M_j/ΣM) A × Ω + M_j v_j × T
    - (M_j/ΣM) P × T + M_j ((r_j·Ω) T + (T·r_j) Ω - 2 (T·Ω) r_j)] (docs/theory/gradients.md, "Reverse mode")."""
    j = wp.tid()
    w = w_hat[j]
    r = x[j] - rigid[2]
    omega = rigid[4]
    A = sums[0]
    T = sums[2]
    m = mass[j]
    share = m / total_mass
    momentum = total_mass * rigid[3]
    v_hat[j] = (wp.float64(1.0) - rate) * w + rate * m * (A / total_mass + wp.cross(T, r))
    inertia = m * (wp.dot(r, omega) * T + wp.dot(T, r) * omega - wp.float64(2.0) * wp.dot(T, omega) * r)
    x_hat[j] = x_hat[j] + rate * (wp.cross(w, omega) - share * wp.cross(A, omega) + m * wp.cross(v[j], T)
                                  - share * wp.cross(momentum, T) + inertia)  # fmt: skip


@wp.kernel
def scaled_inverse_mass_kernel(w: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), scale: Any,
                               out: wp.array(dtype=Any)):  # fmt: skip
    """out = scale w / M (the contact's velocity change, transposed: f̂ = L out)."""
    i = wp.tid()
    out[i] = (scale * inverse_mass[i]) * w[i]


@wp.kernel
def step_adjoint_kernel(x_hat: wp.array(dtype=Any), dt: Any, v_hat: wp.array(dtype=Any), w_hat: wp.array(dtype=Any)):
    """ŵ = v̂' + dt x̂' (the new velocity's adjoint through x' = x + dt v'), v̂ = 0 (filled by what follows)."""
    i = wp.tid()
    w_hat[i] = v_hat[i] + dt * x_hat[i]
    v_hat[i] = type(w_hat[i])()


@wp.kernel
def coupling_transpose_kernel(gathered: wp.array(dtype=Any), area: wp.array(dtype=Any), response: wp.array(dtype=Any),
                              scale: Any, o_hat: wp.array(dtype=Any), out: wp.array(dtype=Any)):  # fmt: skip
    """out = a ∘ gathered - scale r ô: the sweep coupling's transpose, scale (Sᵀ M⁻¹ G - r) ô, from `gathered` =
    scale G M⁻¹ Gᵀ ô (G the points' gather, S = G's transpose weighted by the points' areas a; a = 1 on limit points)."""
    i = wp.tid()
    out[i] = area[i] * gathered[i] - (scale * response[i]) * o_hat[i]


@wp.kernel
def area_scale_kernel(values: wp.array(dtype=Any), area: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    """out = a ∘ values (a quadrature point's dω̄⁰)."""
    i = wp.tid()
    out[i] = area[i] * values[i]


@wp.kernel
def add_vectors_kernel(part: wp.array(dtype=Any), total: wp.array(dtype=Any)):
    """total += part."""
    i = wp.tid()
    total[i] = total[i] + part[i]


@wp.kernel
def push_vectors_kernel(source: wp.array(dtype=wp.vec3d), counter: wp.array(dtype=wp.int32),
                        store: wp.array2d(dtype=wp.vec3d)):  # fmt: skip
    """store[counter[0], i] = source[i]: a row of the stored trajectory at the device's own index (float64: the
    reverse mode's dtype; one kernel per element type, as Warp's CPU graphs replay one overload per kernel)."""
    i = wp.tid()
    store[counter[0], i] = source[i]


@wp.kernel
def push_scalars_kernel(source: wp.array(dtype=wp.float64), counter: wp.array(dtype=wp.int32),
                        store: wp.array2d(dtype=wp.float64)):  # fmt: skip
    """store[counter[0], i] = source[i]."""
    i = wp.tid()
    store[counter[0], i] = source[i]


@wp.kernel
def pull_vectors_kernel(store: wp.array2d(dtype=wp.vec3d), counter: wp.array(dtype=wp.int32), offset: int,
                        out: wp.array(dtype=wp.vec3d)):  # fmt: skip
    """out[i] = store[counter[0] + offset, i]."""
    i = wp.tid()
    out[i] = store[counter[0] + offset, i]


@wp.kernel
def pull_scalars_kernel(store: wp.array2d(dtype=wp.float64), counter: wp.array(dtype=wp.int32), offset: int,
                        out: wp.array(dtype=wp.float64)):  # fmt: skip
    """out[i] = store[counter[0] + offset, i]."""
    i = wp.tid()
    out[i] = store[counter[0] + offset, i]


@wp.kernel
def count_kernel(counter: wp.array(dtype=wp.int32), by: int):
    """counter[0] += by (one thread)."""
    counter[0] = counter[0] + by


@wp.func
def form_rates(x1: Any, x2: Any, x11: Any, x12: Any, x22: Any, n: Any, j: Any, d1: Any, d2: Any, d11: Any, d12: Any,
               d22: Any):  # fmt: skip
    """ȧ, ḃ: the first and second forms' derivatives as the patch moves along d (d,α and d,αβ its jet), with
    ṅ = (I - nnᵀ)(d,1 × x,2 + x,1 × d,2)/j; and the area vector's derivative."""
    area_rate = wp.cross(d1, x2) + wp.cross(x1, d2)
    n_rate = (area_rate - wp.dot(n, area_rate) * n) / j
    a12 = wp.dot(d1, x2) + wp.dot(x1, d2)
    a_rate = wp.matrix(type(j)(2.0) * wp.dot(d1, x1), a12, a12, type(j)(2.0) * wp.dot(d2, x2), shape=(2, 2))
    b12 = wp.dot(n_rate, x12) + wp.dot(n, d12)
    b11 = wp.dot(n_rate, x11) + wp.dot(n, d11)
    b_rate = wp.matrix(b11, b12, b12, wp.dot(n_rate, x22) + wp.dot(n, d22), shape=(2, 2))
    return a_rate, b_rate, area_rate


@wp.func
def point_rates(
    x: wp.array(dtype=Any),
    direction: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    t: int,
    row: int,
    inv: Any,
    metric: Any,
    curvature: Any,
):
    """At a point of triangle t: the strains E, K against the reference (ā, ā⁻¹ = inv, b̄), the point p, x,1, x,2,
    and as x moves along d: d's value dp, ȧ, ḃ and the area vector's rate (`form_rates`)."""
    membrane, bending, p, x1, x2, x11, x12, x22, n, j = koiter_jet(
        x, patch_start, patch_vertices, basis, t, row, inv, metric, curvature
    )
    dp, d1, d2, d11, d12, d22 = patch_jet(direction, patch_start, patch_vertices, basis, t, row)
    a_rate, b_rate, area_rate = form_rates(x1, x2, x11, x12, x22, n, j, d1, d2, d11, d12, d22)
    return membrane, bending, p, x1, x2, dp, a_rate, b_rate, area_rate


@wp.kernel
def shell_rates_kernel(
    x: wp.array(dtype=Any),
    direction: wp.array(dtype=Any),
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    ref_metric: wp.array(dtype=Any),
    ref_metric_inv: wp.array(dtype=Any),
    ref_curvature: wp.array(dtype=Any),
    ref_weight: wp.array(dtype=Any),
    rest_metric: wp.array(dtype=Any),
    rest_curvature: wp.array(dtype=Any),
    stretching_modulus: wp.array(dtype=Any),
    bending_modulus: wp.array(dtype=Any),
    nu: Any,
    AC: Any,
    AI: Any,
    bilayer_radius: Any,
    moments: wp.array(dtype=VolumeMoments),
    target: wp.array(dtype=wp.float64),
    penalty: wp.array(dtype=wp.float64),
    ramp: Any,
    rates: wp.array(dtype=ShellRates),
    by_start: wp.array(dtype=Any),
    by_end: wp.array(dtype=Any),
):
    """rates[0] += the rates of change of E_S, E_B and E_V as x moves along d, the derivatives of Ė_S + Ė_B in AC
    and AI, and 2μV V̇ (Ė_V per unit of V - V̄: the volume target's share, -∂Ė/∂V̄) (one world; docs/theory/gradients.md, "Walkers: reverse mode"): with ā = λā⁰ (λ = e^{-AC c}),
    ∂/∂AC (Ė_S + Ė_B) = c (Ė_S + Ė_B + S_m ω̄ 2(1+ν) ā⁻¹ : ȧ) per point, and ∂K/∂AI = c ā⁻¹ b̄⁰; the bilayer
    (bilayer_radius R > 0: b̄ = Λb̄⁰ - A c ā⁰, Λ = √λ, A = (AC/2 - AI)/R) adds b̄'s share through Λ and A. One thread
    per quadrature point (whole blocks: the threads past them add zero); the first V threads add the volume's
    centroid term -d_I · F_x̄ (kernels/shell.py `volume_centroid_force`). The reference is a function of AC c and AI c,
    so -∂Ė/∂c_q = -(AC ∂/∂AC + AI ∂/∂AI)/c: where `by_start` holds the points (the wave's adjoint) its first
    component gains (1 - ramp) of it and `by_end`'s ramp of it (the substep's reference c_start + ramp (c_end -
    c_start)), as the point factors (s₀, 0, 0) of kernels/laplace.py's gather."""
    q = wp.tid()
    value = ShellRates()
    if q < ref_weight.shape[0]:
        t, row = basis_row(triangle_type, points_per_triangle, q)
        inv = ref_metric_inv[q]
        membrane, bending, p, x1, x2, dp, a_rate, b_rate, area_rate = point_rates(
            x, direction, patch_start, patch_vertices, basis, t, row, inv, ref_metric[q], ref_curvature[q]
        )
        stretching_weight = stretching_modulus[0] * ref_weight[q]
        bending_weight = bending_modulus[0] * ref_weight[q]
        stretching = stretching_weight * wp.ddot(material_stress(membrane, inv, nu), a_rate)
        bending_rate = bending_weight * wp.ddot(material_stress(bending, inv, nu), b_rate)
        cq = patch_scalar(c, patch_start, patch_vertices, basis, t, row)
        one = type(nu)(1.0)
        metric = stretching + bending_rate + stretching_weight * (one + one) * (one + nu) * wp.ddot(inv, a_rate)
        curvature = bending_weight * wp.ddot(material_stress(inv * rest_curvature[q], inv, nu), b_rate)
        if bilayer_radius > type(nu)(0.0):  # ∂b̄/∂Λ = b̄⁰ (Λ = e^{-AC c/2}), ∂b̄/∂A = -c ā⁰
            by_a = bending_weight * wp.ddot(material_stress(inv * rest_metric[q], inv, nu), b_rate)
            stretch = wp.exp(-AC * cq / (one + one))
            metric = metric + stretch / (one + one) * curvature + by_a / ((one + one) * bilayer_radius)
            curvature = -by_a / bilayer_radius
        if by_start.shape[0] > 0:
            by_c = -(AC * metric + AI * curvature)
            zero = type(nu)(0.0)
            by_start[q] = by_start[q] + type(by_start[q])((one - ramp) * by_c, zero, zero)
            by_end[q] = by_end[q] + type(by_end[q])(ramp * by_c, zero, zero)
        metric = cq * metric
        curvature = cq * curvature
        centroid, pressure = world_volume_terms(x, moments, target, penalty, 1, 0)
        swept = weights[q % points_per_triangle] * (wp.dot(dp, wp.cross(x1, x2)) + wp.dot(p - centroid, area_rate))
        volume = type(nu)(pressure) * swept
        unit = type(nu)(wp.float64(2.0) / wp.float64(3.0) * penalty[0]) * swept  # per unit of V - V̄
        if q < x.shape[0]:
            volume = volume - wp.dot(direction[q], type(x[q])(volume_centroid_force(moments, target, penalty,
                                                                                    x.shape[0], q)))  # fmt: skip
            per_excess = moments_normal_sum(moments[0]) * (wp.float64(2.0) * penalty[0] / wp.float64(x.shape[0]))
            unit = unit - wp.dot(direction[q], type(x[q])(per_excess))
        value = ShellRates(wp.float64(stretching), wp.float64(bending_rate), wp.float64(volume), wp.float64(metric),
                           wp.float64(curvature), wp.float64(unit))  # fmt: skip
    block_add(rates, 0, value)


@wp.kernel
def shell_parameter_gradient_kernel(rates: wp.array(dtype=ShellRates), factors: wp.array2d(dtype=wp.float64),
                                    gradient: wp.array(dtype=wp.float64)):  # fmt: skip
    """gradient[i] -= Σ_k factors[i, k] rates[0][k]: F̂ · ∂F/∂θ = -∂Ė/∂θ, Ė's terms scaled by each parameter's power."""
    i = wp.tid()
    total = wp.float64(0.0)
    for k in range(5):
        total += factors[i, k] * rates[0][k]
    gradient[i] = gradient[i] - total


declare_overloads(largest_component_kernel, d="vec3[]")
declare_overloads(step_adjoint_kernel, x_hat="vec3[]", dt="scalar", v_hat="vec3[]", w_hat="vec3[]")
declare_overloads(add_vectors_kernel, part="vec3[]", total="vec3[]")
declare_overloads(coupling_transpose_kernel, gathered="vec3[]", area="scalar[]", response="scalar[]", scale="scalar",
                  o_hat="vec3[]", out="vec3[]")  # fmt: skip
declare_overloads(area_scale_kernel, values="vec3[]", area="scalar[]", out="vec3[]")
declare_overloads(scaled_inverse_mass_kernel, w="vec3[]", inverse_mass="scalar[]", scale="scalar", out="vec3[]")
declare_overloads(probe_kernel, x="vec3[]", d="vec3[]", step="scalar", out="vec3[]")
declare_overloads(directional_difference_kernel, plus="vec3[]", minus="vec3[]", step="scalar", out="vec3[]")
declare_overloads(weighted_dot_kernel, a="vec3[]", b="vec3[]")
declare_overloads(shell_rates_kernel, x="vec3[]", direction="vec3[]", c="scalar[]", basis="vec6[,]", weights="scalar[]",
                  ref_metric="mat22[]", ref_metric_inv="mat22[]", ref_curvature="mat22[]", ref_weight="scalar[]",
                  rest_metric="mat22[]", rest_curvature="mat22[]", stretching_modulus="scalar[]",
                  bending_modulus="scalar[]", nu="scalar", AC="scalar", AI="scalar", bilayer_radius="scalar",
                  ramp="scalar", by_start="vec3[]", by_end="vec3[]")



# ---------------------------------------------------------------- launchers


@one_device
def eval_push(source: wp.array, counter: wp.array, store: wp.array) -> None:
    """store[counter] = source (the row the device's counter names)."""
    kernel = push_scalars_kernel if source.dtype == wp.float64 else push_vectors_kernel
    wp.launch(kernel, dim=len(source), inputs=[source, counter], outputs=[store], device=source.device)


@one_device
def eval_pull(store: wp.array, counter: wp.array, offset: int, out: wp.array) -> None:
    """out = store[counter + offset]."""
    kernel = pull_scalars_kernel if out.dtype == wp.float64 else pull_vectors_kernel
    wp.launch(kernel, dim=len(out), inputs=[store, counter, int(offset)], outputs=[out], device=out.device)


@one_device
def eval_count(counter: wp.array, by: int) -> None:
    """counter += by, on the device."""
    wp.launch(count_kernel, dim=1, inputs=[counter, int(by)], device=counter.device)


@one_device
def eval_directional_derivative(x: wp.array, d: wp.array, step: float, evaluate, largest: wp.array, probe: wp.array,
                                plus: wp.array, minus: wp.array, out: wp.array) -> None:  # fmt: skip
    """out += D_d F(x) = the central difference of `evaluate(probe, forces)` at x ± step d/max|d| (step a length)."""
    s, device = scalar_of(x), x.device
    largest.zero_()
    wp.launch(largest_component_kernel, dim=len(d), inputs=[d], outputs=[largest], device=device)
    for sign, forces in ((1.0, plus), (-1.0, minus)):
        wp.launch(probe_kernel, dim=len(x), inputs=[x, d, largest, s(sign * step)], outputs=[probe], device=device)
        evaluate(probe, forces)
    wp.launch(directional_difference_kernel, dim=len(x), inputs=[plus, minus, largest, s(step)], outputs=[out],
              device=device)  # fmt: skip


@one_device
def eval_weighted_dot(a: wp.array, b: wp.array, weight: float, slot: int, total: wp.array) -> None:
    """total[slot] += weight a · b."""
    wp.launch(weighted_dot_kernel, dim=len(a), inputs=[a, b, wp.float64(weight), int(slot)], outputs=[total],
              device=a.device)  # fmt: skip


@one_device
def eval_damping_adjoint(w_hat, x, v, mass, rigid, total_mass: float, rate: float, sums, second_moment, x_hat,
                         v_hat) -> None:  # fmt: skip
    """v̂ and x̂ of the damping toward the rigid-body motion (`damping_adjoint_kernel`); `rigid` the rows of x, v
    (kernels/dynamics.py), `sums` (3 vec3) and `second_moment` (1 mat33) scratch."""
    device = x.device
    sums.zero_()
    second_moment.zero_()
    wp.launch(damping_sums_kernel, dim=len(x), inputs=[w_hat, x, mass, rigid], outputs=[sums, second_moment],
              device=device)  # fmt: skip
    wp.launch(damping_solve_kernel, dim=1, inputs=[sums, second_moment], device=device)
    wp.launch(damping_adjoint_kernel, dim=len(x), inputs=[w_hat, x, v, mass, rigid, sums, wp.float64(total_mass),
                                                          wp.float64(rate)], outputs=[x_hat, v_hat], device=device)


@one_device
def eval_step_adjoint(x_hat, v_hat, dt: float, w_hat) -> None:
    """ŵ = v̂ + dt x̂, v̂ = 0."""
    wp.launch(step_adjoint_kernel, dim=len(x_hat), inputs=[x_hat, scalar_of(x_hat)(dt)], outputs=[v_hat, w_hat],
              device=x_hat.device)  # fmt: skip


@one_device
def eval_coupling_transpose(gathered, area, response, scale: float, o_hat, out) -> None:
    """out = a ∘ gathered - scale r ô (`coupling_transpose_kernel`)."""
    wp.launch(coupling_transpose_kernel, dim=len(out), inputs=[gathered, area, response, scalar_of(area)(scale), o_hat],
              outputs=[out], device=out.device)  # fmt: skip


@one_device
def eval_area_scale(values, area, out) -> None:
    """out = a ∘ values."""
    wp.launch(area_scale_kernel, dim=len(out), inputs=[values, area], outputs=[out], device=out.device)


@one_device
def eval_add(total, part) -> None:
    """total += part."""
    wp.launch(add_vectors_kernel, dim=len(total), inputs=[part], outputs=[total], device=total.device)


@one_device
def eval_scaled_inverse_mass(w, inverse_mass, scale: float, out) -> None:
    """out = scale w / M."""
    wp.launch(scaled_inverse_mass_kernel, dim=len(w), inputs=[w, inverse_mass, scalar_of(inverse_mass)(scale)],
              outputs=[out], device=w.device)  # fmt: skip


@one_device
def eval_shell_rates(x, direction, c, patch: list, reference: list, rest: list, moduli: list, nu, AC, AI,
                     bilayer_radius, volume: list, rates, by_concentration: tuple, ramp: float) -> None:  # fmt: skip
    """rates[0] = `shell_rates_kernel`'s sums (zeroed here): `patch` the weighted patch tables, `reference` ā, ā⁻¹, b̄,
    dω̄, `rest` ā⁰, b̄⁰, `moduli` the stretching and bending moduli's arrays, bilayer_radius 0 for the Koiter
    reference, `volume` the moments at x, V̄ and the penalty; `by_concentration`: the per-point arrays (by_start,
    by_end) that gain -∂Ė/∂c_q split by `ramp`, or two empty arrays."""
    rates.zero_()
    points, s = len(reference[-1]), scalar_of(x)
    wp.launch(shell_rates_kernel, dim=whole_blocks(points),
              inputs=[x, direction, c, *patch, *reference, *rest, *moduli, s(nu), s(AC), s(AI), s(bilayer_radius),
                      *volume, s(ramp)],
              outputs=[rates, *by_concentration], block_dim=REDUCTION_BLOCK, device=x.device)  # fmt: skip


@one_device
def eval_shell_parameter_gradient(rates, factors, gradient) -> None:
    """gradient[i] -= factors[i] · rates[0] (`shell_parameter_gradient_kernel`; one row per slot)."""
    wp.launch(shell_parameter_gradient_kernel, dim=factors.shape[0], inputs=[rates, factors], outputs=[gradient],
              device=gradient.device)  # fmt: skip
