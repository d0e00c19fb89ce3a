"""Adjoint kernels of the wave on the moving surface (docs/theory/gradients.md, "The sensitive wave"), each with its
launcher: the explicit FitzHugh–Nagumo step, the Richardson mass corrections W_p, the conservative transport, and
the positions' share of the operator's bilinear forms.

The operator's forms at a quadrature point (kernels/laplace.py), a = x,α·x,β, j = √det a, G = a⁻¹, weight w:
u K v = Σ_q u,α D^{αβ} v,β with D = G j w (adj(a) w / j_floor where j < j_floor), u M_c v = Σ_q u_q v_q j w and
m·M_L = Σ_q m_q j w. Their derivative in a, a symmetric S with dΦ = S : da, gives the control points' share
x̂_I += N_I,α t_α, t_α = 2 S_αβ x,β (da = dx,α·x,β + x,α·dx,β):

    S = κ_K j w (½ (u·Gv) G - sym(Gu ⊗ Gv)) + ½ (κ_M u_q v_q + m_q) j w G.
"""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .laplace import gather_point_factors_kernel
from .limit_surface import basis_row, first_form, patch_jet


@wp.kernel
def fhn_explicit_adjoint_kernel(
    c: wp.array(dtype=Any), c_next_hat: wp.array(dtype=Any), w_next_hat: wp.array(dtype=Any), nu: Any, kappa: Any,
    epsilon: Any, gamma2: Any, dt: Any, c_hat: wp.array(dtype=Any), w_hat: wp.array(dtype=Any),
    acceleration_hat: wp.array(dtype=Any),
):  # fmt: skip
    """c' = c + dt (f(c) - w - γ² z), w' = w + dt ε (c - κ w) backwards (kernels/waves.py `fhn_explicit_kernel`):
    ĉ = ĉ'(1 + dt f'(c)) + dt ε ŵ', ŵ = -dt ĉ' + (1 - dt ε κ) ŵ', ẑ = -dt γ² ĉ' (the diffusion's share of ĉ comes
    through ẑ). Overwrites its outputs."""
    i = wp.tid()
    ci = c[i]
    one = type(ci)(1.0)
    slope = -type(ci)(3.0) * ci * ci + type(ci)(2.0) * (one + nu) * ci - nu
    g = c_next_hat[i]
    h = w_next_hat[i]
    c_hat[i] = g * (one + dt * slope) + dt * epsilon * h
    w_hat[i] = -dt * g + (one - dt * epsilon * kappa) * h
    acceleration_hat[i] = -dt * gamma2 * g


@wp.kernel
def transport_adjoint_kernel(
    value: wp.array(dtype=Any), value_next_hat: wp.array(dtype=Any), old_mass: wp.array(dtype=Any),
    mass: wp.array(dtype=Any), value_hat: wp.array(dtype=Any), old_mass_hat: wp.array(dtype=Any),
    mass_hat: wp.array(dtype=Any),
):  # fmt: skip
    """v' = v M_old / M backwards (kernels/waves.py `transport_kernel`): v̂ = v̂' M_old / M, and the masses' adjoints
    gain v̂' v / M and -v̂' v M_old / M²."""
    i = wp.tid()
    share = value_next_hat[i] * value[i] / mass[i]
    value_hat[i] = value_next_hat[i] * old_mass[i] / mass[i]
    old_mass_hat[i] = old_mass_hat[i] + share
    mass_hat[i] = mass_hat[i] - share * old_mass[i] / mass[i]


@wp.kernel
def divide_adjoint_kernel(r_hat: wp.array(dtype=Any), f: wp.array(dtype=Any), mass: wp.array(dtype=Any),
                          f_hat: wp.array(dtype=Any), mass_hat: wp.array(dtype=Any)):  # fmt: skip
    """r = f / M backwards: f̂ += r̂ / M, M̂ -= r̂ f / M²."""
    i = wp.tid()
    q = r_hat[i] / mass[i]
    f_hat[i] = f_hat[i] + q
    mass_hat[i] = mass_hat[i] - q * f[i] / mass[i]


@wp.kernel
def richardson_adjoint_kernel(
    r_hat: wp.array(dtype=Any), f: wp.array(dtype=Any), mass_product: wp.array(dtype=Any), mass: wp.array(dtype=Any),
    f_hat: wp.array(dtype=Any), mass_hat: wp.array(dtype=Any), q: wp.array(dtype=Any),
):  # fmt: skip
    """r' = r + (f - M_c r) / M backwards, but for M_c's share: q = r̂'/M, f̂ += q, M̂ -= q (f - M_c r) / M (then
    r̂ = r̂' - M_c q, and M_c's dependence on x through q and r)."""
    i = wp.tid()
    qi = r_hat[i] / mass[i]
    q[i] = qi
    f_hat[i] = f_hat[i] + qi
    mass_hat[i] = mass_hat[i] - qi * (f[i] - mass_product[i]) / mass[i]


@wp.kernel
def add_scaled_kernel(part: wp.array(dtype=Any), scale: Any, total: wp.array(dtype=Any)):
    """total += scale part."""
    i = wp.tid()
    total[i] = total[i] + scale * part[i]


@wp.kernel
def operator_position_adjoint_kernel(
    x: wp.array(dtype=Any),
    u: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
    m: wp.array(dtype=Any),
    stiffness_weight: Any,
    mass_weight: Any,
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    j_floor: wp.array(dtype=Any),
    x_hat: wp.array(dtype=Any),
):
    """x̂ += ∂/∂x (κ_K u K v + κ_M u M_c v + m·M_L) at q (module docstring), scattered to the patch."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    p, x1, x2, x11, x12, x22 = patch_jet(x, patch_start, patch_vertices, basis, t, row)
    uq, u1, u2, u11, u12, u22 = patch_jet(u, patch_start, patch_vertices, basis, t, row)
    vq, v1, v2, v11, v12, v22 = patch_jet(v, patch_start, patch_vertices, basis, t, row)
    mq, m1, m2, m11, m12, m22 = patch_jet(m, patch_start, patch_vertices, basis, t, row)
    a = first_form(x1, x2)
    j = wp.sqrt(wp.determinant(a))
    w = weights[q % points_per_triangle]
    G = wp.inverse(a)
    half = type(w)(0.5)
    du = wp.vector(u1, u2)
    dv = wp.vector(v1, v2)
    S = (half * (mass_weight * uq * vq + mq) * j * w) * G
    if j >= j_floor[q]:
        Gu = G * du
        Gv = G * dv
        S = S + (stiffness_weight * j * w) * (half * wp.dot(du, Gv) * G - half * (wp.outer(Gu, Gv) + wp.outer(Gv, Gu)))
    else:  # D = adj(a) w / j_floor: linear in a
        off = -half * (u1 * v2 + u2 * v1)
        S = S + (stiffness_weight * w / j_floor[q]) * wp.matrix(u2 * v2, off, off, u1 * v1, shape=(2, 2))
    two = type(w)(2.0)
    t1 = two * (S[0, 0] * x1 + S[0, 1] * x2)
    t2 = two * (S[1, 0] * x1 + S[1, 1] * x2)
    start = patch_start[t]
    for k in range(patch_start[t + 1] - start):
        b = basis[row, k]
        wp.atomic_add(x_hat, patch_vertices[start + k], b[1] * t1 + b[2] * t2)


_PATCH = dict(basis="vec6[,]")
declare_overloads(fhn_explicit_adjoint_kernel, c="scalar[]", c_next_hat="scalar[]", w_next_hat="scalar[]", nu="scalar",
                  kappa="scalar", epsilon="scalar", gamma2="scalar", dt="scalar", c_hat="scalar[]", w_hat="scalar[]",
                  acceleration_hat="scalar[]")  # fmt: skip
declare_overloads(transport_adjoint_kernel, value="scalar[]", value_next_hat="scalar[]", old_mass="scalar[]",
                  mass="scalar[]", value_hat="scalar[]", old_mass_hat="scalar[]", mass_hat="scalar[]")  # fmt: skip
declare_overloads(divide_adjoint_kernel, r_hat="scalar[]", f="scalar[]", mass="scalar[]", f_hat="scalar[]",
                  mass_hat="scalar[]")  # fmt: skip
declare_overloads(richardson_adjoint_kernel, r_hat="scalar[]", f="scalar[]", mass_product="scalar[]", mass="scalar[]",
                  f_hat="scalar[]", mass_hat="scalar[]", q="scalar[]")  # fmt: skip
declare_overloads(add_scaled_kernel, part="scalar[]", scale="scalar", total="scalar[]")
declare_overloads(operator_position_adjoint_kernel, x="vec3[]", u="scalar[]", v="scalar[]", m="scalar[]",
                  stiffness_weight="scalar", mass_weight="scalar", weights="scalar[]", j_floor="scalar[]",
                  x_hat="vec3[]", **_PATCH)  # fmt: skip


# ---------------------------------------------------------------- launchers


@one_device
def eval_fhn_explicit_adjoint(c, c_next_hat, w_next_hat, nu: float, kappa: float, epsilon: float, gamma: float,
                              dt: float, c_hat, w_hat, acceleration_hat) -> None:  # fmt: skip
    """ĉ, ŵ (the reaction's and the inhibitor's shares) and ẑ of an explicit FHN step
    (`fhn_explicit_adjoint_kernel`)."""
    s = scalar_of(c)
    wp.launch(fhn_explicit_adjoint_kernel, dim=len(c),
              inputs=[c, c_next_hat, w_next_hat, s(nu), s(kappa), s(epsilon), s(gamma * gamma), s(dt)],
              outputs=[c_hat, w_hat, acceleration_hat], device=c.device)  # fmt: skip


@one_device
def eval_transport_adjoint(value, value_next_hat, old_mass, mass, value_hat, old_mass_hat, mass_hat) -> None:
    """v̂ of the values before a conservative transport, and the masses' adjoints (accumulated)."""
    wp.launch(transport_adjoint_kernel, dim=len(value), inputs=[value, value_next_hat, old_mass, mass],
              outputs=[value_hat, old_mass_hat, mass_hat], device=value.device)  # fmt: skip


@one_device
def eval_divide_adjoint(r_hat, f, mass, f_hat, mass_hat) -> None:
    """r = f / M backwards (`divide_adjoint_kernel`)."""
    wp.launch(divide_adjoint_kernel, dim=len(f), inputs=[r_hat, f, mass], outputs=[f_hat, mass_hat], device=f.device)


@one_device
def eval_richardson_adjoint(r_hat, f, mass_product, mass, f_hat, mass_hat, q) -> None:
    """One Richardson step backwards but for M_c (`richardson_adjoint_kernel`)."""
    wp.launch(richardson_adjoint_kernel, dim=len(f), inputs=[r_hat, f, mass_product, mass],
              outputs=[f_hat, mass_hat, q], device=f.device)  # fmt: skip


@one_device
def eval_add_scaled(total, part, scale: float) -> None:
    """total += scale part."""
    wp.launch(add_scaled_kernel, dim=len(total), inputs=[part, scalar_of(total)(scale)], outputs=[total],
              device=total.device)  # fmt: skip


@one_device
def eval_operator_position_adjoint(x, u, v, m, stiffness_weight: float, mass_weight: float, tables, j_floor,
                                   x_hat) -> None:  # fmt: skip
    """x̂ += ∂/∂x (κ_K u K v + κ_M u M_c v + m·M_L) on the surface of `tables` (a SurfaceTables) at x."""
    s = scalar_of(u)
    wp.launch(operator_position_adjoint_kernel, dim=tables.n_quadrature_points,
              inputs=[x, u, v, m, s(stiffness_weight), s(mass_weight), *tables.weighted_patch(), j_floor],
              outputs=[x_hat], device=x.device)  # fmt: skip


@one_device
def eval_gather_point_factors(factors, tables, scratch, out) -> None:
    """out += Nᵀ s₀ (kernels/laplace.py's gather of the point factors (s₀, 0, 0); `scratch` a vertex array): per-point
    values of a field's adjoint to its control values."""
    t = tables
    wp.launch(gather_point_factors_kernel, dim=len(out),
              inputs=[factors, *t.vertex_entries(), t.patch_start, t.triangle_type, t.basis, t.points_per_triangle],
              outputs=[scratch], device=out.device)  # fmt: skip
    eval_add_scaled(out, scratch, 1.0)
