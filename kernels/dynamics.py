"""Shell dynamics of the walkers (SPEC §3 "Walker scenes"): symplectic Euler with lumped mass."""

from typing import Any

import warp as wp

from . import declare_overloads
from .reduce import block_add


@wp.kernel
def momentum_kernel(
    mass: wp.array(dtype=Any), x: wp.array(dtype=Any), v: wp.array(dtype=Any), momentum: wp.array(dtype=Any)
):
    """momentum += [Σ M_I v_I, Σ M_I x_I × v_I] (zeroed by the caller; launched on whole blocks)."""
    i = wp.tid()
    p = type(v[0])()
    r = type(x[0])()
    if i < x.shape[0]:
        p = mass[i] * v[i]
        r = x[i]
    block_add(momentum, 0, p)
    block_add(momentum, 1, wp.cross(r, p))


@wp.kernel
def rigid_sums_kernel(
    forces: wp.array(dtype=Any), mass: wp.array(dtype=Any), x: wp.array(dtype=Any),
    sums: wp.array(dtype=Any), second_moment: wp.array(dtype=Any),
):  # fmt: skip
    """sums += [Σ F, Σ x × F, Σ M x]; second_moment += Σ M x xᵀ (zeroed by the caller; launched on whole blocks)."""
    i = wp.tid()
    f = type(forces[0])()
    r = type(x[0])()
    m = type(mass[0])(0.0)
    if i < x.shape[0]:
        f = forces[i]
        r = x[i]
        m = mass[i]
    block_add(sums, 0, f)
    block_add(sums, 1, wp.cross(r, f))
    block_add(sums, 2, m * r)
    block_add(second_moment, 0, m * wp.outer(r, r))


@wp.kernel
def rigid_correction_kernel(
    sums: wp.array(dtype=Any), second_moment: wp.array(dtype=Any), momentum: wp.array(dtype=Any),
    inverse_total_mass: Any, correction: wp.array(dtype=Any),
):  # fmt: skip
    """The rigid-body acceleration of the net force N and torque τ and the rigid-body velocity of the
    momentum P and angular momentum L: [N/ΣM, α = I⁻¹τ, centre c, v̄ = P/ΣM, Ω = I⁻¹(L - c × P)]."""
    total = type(inverse_total_mass)(1.0) / inverse_total_mass
    c = inverse_total_mass * sums[2]
    torque = sums[1] - wp.cross(c, sums[0])
    S = second_moment[0] - total * wp.outer(c, c)
    inertia = wp.trace(S) * wp.identity(n=3, dtype=type(inverse_total_mass)) - S
    correction[0] = inverse_total_mass * sums[0]
    correction[1] = wp.inverse(inertia) * torque
    correction[2] = c
    correction[3] = inverse_total_mass * momentum[0]
    correction[4] = wp.inverse(inertia) * (momentum[1] - wp.cross(c, momentum[0]))


@wp.kernel
def symplectic_euler_kernel(
    forces: wp.array(dtype=Any),
    inverse_mass: wp.array(dtype=Any),
    rigid: wp.array(dtype=Any),
    damping: Any,
    dt: Any,
    x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
):
    """v += dt (F/M - a_rigid - η (v - v_rigid)), then x += dt v.

    a_rigid = N/ΣM + α × (x - c) undoes the net force and torque of the internal forces' round-off
    (zero in exact arithmetic; in float32 they would set a resting shell rolling); the damping acts
    on the velocity relative to the rigid-body motion v_rigid = v̄ + Ω × (x - c), so it exerts no
    net force and no torque (it keeps P and L, and lets a shell roll and slide freely).
    """
    i = wp.tid()
    r = x[i] - rigid[2]
    accel = inverse_mass[i] * forces[i] - rigid[0] - wp.cross(rigid[1], r)
    vi = v[i] + dt * (accel - damping * (v[i] - rigid[3] - wp.cross(rigid[4], r)))
    v[i] = vi
    x[i] = x[i] + dt * vi


@wp.kernel
def first_moment_kernel(mass: wp.array(dtype=Any), x: wp.array(dtype=Any), moment: wp.array(dtype=Any)):
    """moment[0] += Σ M_I x_I (zeroed by the caller; launched on whole blocks)."""
    i = wp.tid()
    r = type(x[0])()
    if i < x.shape[0]:
        r = mass[i] * x[i]
    block_add(moment, 0, r)


@wp.kernel
def trace_row_kernel(
    c: wp.array(dtype=Any), x: wp.array(dtype=Any), origin: int, moment: wp.array(dtype=Any),
    inverse_total_mass: Any, row: wp.array(dtype=wp.int32), trace: wp.array2d(dtype=Any),
):  # fmt: skip
    """Single thread: trace[row] = [c_origin, centre of mass (3), x_origin (3)], then row += 1."""
    k = row[0]
    centre = inverse_total_mass * moment[0]
    trace[k, 0] = c[origin]
    for j in range(3):
        trace[k, 1 + j] = centre[j]
        trace[k, 4 + j] = x[origin][j]
    row[0] = k + 1


@wp.kernel
def speed_runaway_kernel(v: wp.array(dtype=Any), limit: Any, flag: wp.array(dtype=wp.int32)):
    """flag = 1 where |v_I| > limit or v_I is NaN/Inf (NaN fails every comparison)."""
    i = wp.tid()
    if not (wp.length(v[i]) <= limit):
        flag[0] = 1


declare_overloads(momentum_kernel, mass="scalar[]", x="vec3[]", v="vec3[]", momentum="vec3[]")
declare_overloads(rigid_sums_kernel, forces="vec3[]", mass="scalar[]", x="vec3[]", sums="vec3[]",
                  second_moment="mat33[]")  # fmt: skip
declare_overloads(rigid_correction_kernel, sums="vec3[]", second_moment="mat33[]", momentum="vec3[]",
                  inverse_total_mass="scalar", correction="vec3[]")  # fmt: skip
declare_overloads(symplectic_euler_kernel, forces="vec3[]", inverse_mass="scalar[]", rigid="vec3[]", damping="scalar",
                  dt="scalar", x="vec3[]", v="vec3[]")  # fmt: skip
declare_overloads(first_moment_kernel, mass="scalar[]", x="vec3[]", moment="vec3[]")
declare_overloads(trace_row_kernel, c="scalar[]", x="vec3[]", moment="vec3[]", inverse_total_mass="scalar",
                  trace="scalar[,]")  # fmt: skip
declare_overloads(speed_runaway_kernel, v="vec3[]", limit="scalar")
