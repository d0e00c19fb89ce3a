"""Adjoint kernels of the shell's rest forms (docs/theory/gradients.md, "The rest forms"), each with its launcher: the
derivative of the energy's rate Ė(x; d) in the rest metric ā⁰ and curvature b̄⁰ at every quadrature point, and the
rest forms' derivative in the rest shape's control points.

At a point, with the active reference ā, b̄, G = ā⁻¹, ω̄ = √det ā w, the mixed strains E = G(a − ā), K = G(b − b̄),
the rates H_S = G ȧ, H_B = G ḃ and B(X, Y) = 2(1 − ν) tr(XY) + 2ν trX trY, the rate is Ė = ω̄ (C_s B(E, H_S) +
C_b B(K, H_B)), and with T(M, N) = 2(1 − ν) sym(M N G) + 2ν tr(N) sym(M G) (so that B(−G δā M, N) = −T(M, N):δā):

    ∂Ė/∂ā = ½ Ė G − ω̄ C_s (T(Ga, H_S) + T(H_S, E)) − ω̄ C_b (T(K, H_B) + T(H_B, K)),   ∂Ė/∂b̄ = −ω̄ C_b σ(H_B, G),

σ(H, G) = 2(1 − ν) H G + 2ν tr(H) G. The reference follows c: Koiter's ā = λā⁰, b̄ = (1 − AI c) b̄⁰ (λ = e^{−AC c});
the bilayer's ā = λā⁰, b̄ = √λ b̄⁰ − A c ā⁰.
"""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .adjoint import ShellRates, point_rates
from .limit_surface import basis_row, patch_jet, patch_scalar
from .shell import material_stress


@wp.func
def sym(m: Any):
    """(m + mᵀ)/2."""
    return type(m[0, 0])(0.5) * (m + wp.transpose(m))


@wp.func
def stress_pair(m: Any, n: Any, inv: Any, nu: Any):
    """T(M, N) = 2(1 − ν) sym(M N G) + 2ν tr(N) sym(M G)."""
    two = type(nu)(2.0)
    return two * (type(nu)(1.0) - nu) * sym(m * n * inv) + (two * nu * wp.trace(n)) * sym(m * inv)


@wp.kernel
def rest_forms_rate_kernel(
    x: wp.array(dtype=Any),
    direction: wp.array(dtype=Any),
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    ref_metric: wp.array(dtype=Any),
    ref_metric_inv: wp.array(dtype=Any),
    ref_curvature: wp.array(dtype=Any),
    ref_weight: wp.array(dtype=Any),
    stretching_modulus: wp.array(dtype=Any),
    bending_modulus: wp.array(dtype=Any),
    nu: Any,
    AC: Any,
    AI: Any,
    bilayer_A: Any,
    bilayer: int,
    metric_hat: wp.array(dtype=Any),
    curvature_hat: wp.array(dtype=Any),
):
    """metric_hat_q −= ∂Ė/∂ā⁰, curvature_hat_q −= ∂Ė/∂b̄⁰ (F̂·∂F/∂θ = −∂Ė/∂θ; module docstring) as x moves along d."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    inv = ref_metric_inv[q]
    membrane, bending, p, x1, x2, dp, a_rate, b_rate, area_rate = point_rates(
        x, direction, patch_start, patch_vertices, basis, t, row, inv, ref_metric[q], ref_curvature[q]
    )
    stretching = stretching_modulus[0] * ref_weight[q]
    bending_weight = bending_modulus[0] * ref_weight[q]
    h_s = inv * a_rate
    h_b = inv * b_rate
    rate = stretching * wp.ddot(material_stress(membrane, inv, nu), a_rate)
    rate = rate + bending_weight * wp.ddot(material_stress(bending, inv, nu), b_rate)
    identity = wp.identity(n=2, dtype=type(nu))
    half = type(nu)(0.5)
    by_metric = half * rate * inv - stretching * (stress_pair(membrane + identity, h_s, inv, nu)
                                                  + stress_pair(h_s, membrane, inv, nu))  # fmt: skip
    by_metric = by_metric - bending_weight * (stress_pair(bending, h_b, inv, nu) + stress_pair(h_b, bending, inv, nu))
    by_curvature = -bending_weight * material_stress(h_b, inv, nu)
    cq = patch_scalar(c, patch_start, patch_vertices, basis, t, row)
    stretch = wp.exp(-AC * cq)
    if bilayer == 0:
        metric_hat[q] = metric_hat[q] - stretch * by_metric
        curvature_hat[q] = curvature_hat[q] - (type(nu)(1.0) - AI * cq) * by_curvature
    else:
        metric_hat[q] = metric_hat[q] - (stretch * by_metric - bilayer_A * cq * by_curvature)
        curvature_hat[q] = curvature_hat[q] - wp.sqrt(stretch) * by_curvature


@wp.kernel
def rest_forms_adjoint_kernel(
    x: wp.array(dtype=Any),
    metric_hat: wp.array(dtype=Any),
    curvature_hat: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    x_hat: wp.array(dtype=Any),
):
    """x̂_I += (∂ā⁰_q/∂x_I)ᵀ Â_q + (∂b̄⁰_q/∂x_I)ᵀ B̂_q, ā⁰ = x,α·x,β and b̄⁰ = n·x,αβ of the surface at x: with S = sym Â,
    N_I,α 2 S_αβ x,β; and, ḃ = ṅ·x,αβ + n·d,αβ with ṅ = (I − nnᵀ)(d,1 × x,2 + x,1 × d,2)/j, B̂_αβ N_I,αβ n +
    N_I,1 (x,2 × u) + N_I,2 (u × x,1), u = (I − nnᵀ) Σ B̂_αβ x,αβ / j. Scattered to the patch."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    origin, x1, x2, x11, x12, x22 = patch_jet(x, patch_start, patch_vertices, basis, t, row)
    cross = wp.cross(x1, x2)
    j = wp.length(cross)
    n = cross / j
    S = sym(metric_hat[q])
    B = curvature_hat[q]
    two = type(j)(2.0)
    t1 = two * (S[0, 0] * x1 + S[0, 1] * x2)
    t2 = two * (S[1, 0] * x1 + S[1, 1] * x2)
    pull = B[0, 0] * x11 + (B[0, 1] + B[1, 0]) * x12 + B[1, 1] * x22
    u = (pull - wp.dot(n, pull) * n) / j
    t1 = t1 + wp.cross(x2, u)
    t2 = t2 + wp.cross(u, x1)
    start = patch_start[t]
    for k in range(patch_start[t + 1] - start):
        b = basis[row, k]
        second = B[0, 0] * b[3] + (B[0, 1] + B[1, 0]) * b[4] + B[1, 1] * b[5]
        wp.atomic_add(x_hat, patch_vertices[start + k], b[1] * t1 + b[2] * t2 + second * n)


@wp.kernel
def volume_target_rate_kernel(rates: wp.array(dtype=ShellRates), out: wp.array(dtype=wp.float64)):
    """out[0] −= ∂Ė/∂V̄: E_V = μV (V − V̄)², so Ė_V = 2μV (V − V̄) V̇ and −∂Ė_V/∂V̄ = 2μV V̇ (`shell_rates_kernel`'s
    sixth sum; one world)."""
    out[0] = out[0] + rates[0][5]


_PATCH = dict(basis="vec6[,]")
declare_overloads(rest_forms_rate_kernel, x="vec3[]", direction="vec3[]", c="scalar[]", ref_metric="mat22[]",
                  ref_metric_inv="mat22[]", ref_curvature="mat22[]", ref_weight="scalar[]",
                  stretching_modulus="scalar[]", bending_modulus="scalar[]", nu="scalar", AC="scalar", AI="scalar",
                  bilayer_A="scalar", metric_hat="mat22[]", curvature_hat="mat22[]", **_PATCH)  # fmt: skip
declare_overloads(rest_forms_adjoint_kernel, x="vec3[]", metric_hat="mat22[]", curvature_hat="mat22[]", x_hat="vec3[]",
                  **_PATCH)  # fmt: skip


# ---------------------------------------------------------------- launchers


@one_device
def eval_rest_forms_rate(x, direction, c, patch: list, reference: list, moduli: list, nu: float,
                         AC: float, AI: float, bilayer_A, metric_hat, curvature_hat) -> None:  # fmt: skip
    """Â⁰ −= ∂Ė/∂ā⁰, B̂⁰ −= ∂Ė/∂b̄⁰ at every point (`rest_forms_rate_kernel`); `patch` the patch tables, `reference`
    ā, ā⁻¹, b̄, dω̄; bilayer_A None for Koiter's reference, else the bilayer's A."""
    s = scalar_of(x)
    wp.launch(rest_forms_rate_kernel, dim=len(metric_hat),
              inputs=[x, direction, c, *patch, *reference, *moduli, s(nu), s(AC), s(AI),
                      s(bilayer_A or 0.0), int(bilayer_A is not None)],
              outputs=[metric_hat, curvature_hat], device=x.device)  # fmt: skip


@one_device
def eval_rest_forms_adjoint(x, metric_hat, curvature_hat, tables, x_hat) -> None:
    """x̂ += the rest forms' adjoints Â⁰, B̂⁰ taken to the control points at x (`rest_forms_adjoint_kernel`)."""
    wp.launch(rest_forms_adjoint_kernel, dim=len(metric_hat), inputs=[x, metric_hat, curvature_hat, *tables.patch()],
              outputs=[x_hat], device=x.device)  # fmt: skip


@one_device
def eval_volume_target_rate(rates, out) -> None:
    """out[0] −= ∂Ė/∂V̄ from `shell_rates_kernel`'s sums."""
    wp.launch(volume_target_rate_kernel, dim=1, inputs=[rates], outputs=[out], device=out.device)
