"""Shell dynamics of the walkers (docs/theory/dynamics.md): symplectic Euler with lumped mass, or the
overdamped mobility model (explicit Euler on M ζ v = F). Each kernel with its launcher (below)."""

from typing import Any

import warp as wp

from . import declare_overloads, scalar_of
from .reduce import REDUCTION_BLOCK, block_add


@wp.kernel
def rigid_sums_kernel(
    forces: wp.array(dtype=Any), mass: wp.array(dtype=Any), x: wp.array(dtype=Any), v: wp.array(dtype=Any),
    with_momentum: int, threads: int, sums: wp.array(dtype=Any), second_moment: wp.array(dtype=Any),
):  # fmt: skip
    """sums += [Σ F, Σ x × F, Σ M x, Σ M v, Σ M x × v] (the last two with_momentum); second_moment += Σ M x xᵀ.
    Launched on whole blocks, `threads` in all, thread t taking vertices t, t + threads, ...;
    `rigid_correction_kernel` consumes the sums and zeroes them."""
    f = type(forces[0])()
    torque = f
    mr = f
    p = f
    angular = f
    second = wp.outer(f, f)
    for i in range(wp.tid(), x.shape[0], threads):
        m = mass[i]
        r = x[i]
        f += forces[i]
        torque += wp.cross(r, forces[i])
        mr += m * r
        second += m * wp.outer(r, r)
        p += m * v[i]
        angular += wp.cross(r, m * v[i])
    block_add(sums, 0, f)
    block_add(sums, 1, torque)
    block_add(sums, 2, mr)
    block_add(second_moment, 0, second)
    if with_momentum != 0:  # uniform over the launch: every thread of a block calls block_add
        block_add(sums, 3, p)
        block_add(sums, 4, angular)


@wp.kernel
def rigid_correction_kernel(
    sums: wp.array(dtype=Any), second_moment: wp.array(dtype=Any), inverse_total_mass: Any,
    correction: wp.array(dtype=Any),
):  # fmt: skip
    """Single thread: the rigid-body acceleration of the net force N and torque τ and the rigid-body
    velocity of the momentum P and angular momentum L: [N/ΣM, α = I⁻¹τ, centre c, v̄ = P/ΣM,
    Ω = I⁻¹(L - c × P)]; then zeroes the sums for the next step (no memset per step)."""
    total = type(inverse_total_mass)(1.0) / inverse_total_mass
    c = inverse_total_mass * sums[2]
    torque = sums[1] - wp.cross(c, sums[0])
    S = second_moment[0] - total * wp.outer(c, c)
    inertia = wp.inverse(wp.trace(S) * wp.identity(n=3, dtype=type(inverse_total_mass)) - S)
    correction[0] = inverse_total_mass * sums[0]
    correction[1] = inertia * torque
    correction[2] = c
    correction[3] = inverse_total_mass * sums[3]
    correction[4] = inertia * (sums[4] - wp.cross(c, sums[3]))
    for k in range(5):
        sums[k] = type(c)()
    second_moment[0] = type(S)()


@wp.func
def specific_force(force: Any, inverse_mass: Any, rigid: wp.array(dtype=Any), r: Any, gravity: Any):
    """F/M - g ẑ - a_rigid at a point r = x - c from the centre: a_rigid = N/ΣM + α × r undoes the net
    force and torque of the internal forces' round-off (zero in exact arithmetic; in float32 they
    would set a resting shell rolling)."""
    accel = inverse_mass * force - rigid[0] - wp.cross(rigid[1], r)
    accel[2] = accel[2] - gravity
    return accel


@wp.kernel
def symplectic_euler_kernel(
    forces: wp.array(dtype=Any),
    inverse_mass: wp.array(dtype=Any),
    rigid: wp.array(dtype=Any),
    damping: Any,
    gravity: Any,
    dt: Any,
    x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
):
    """v += dt (F/M - g ẑ - a_rigid - η (v - v_rigid)), then x += dt v.

    Gravity M_I g on every control point is the uniform acceleration g (`specific_force`); the damping
    acts on the velocity relative to the rigid-body motion v_rigid = v̄ + Ω × (x - c), so it exerts
    no net force and no torque (it keeps P and L, and lets a shell roll and slide freely).
    """
    i = wp.tid()
    r = x[i] - rigid[2]
    accel = specific_force(forces[i], inverse_mass[i], rigid, r, gravity)
    vi = v[i] + dt * (accel - damping * (v[i] - rigid[3] - wp.cross(rigid[4], r)))
    v[i] = vi
    x[i] = x[i] + dt * vi


@wp.kernel
def overdamped_euler_kernel(
    forces: wp.array(dtype=Any),
    inverse_mass: wp.array(dtype=Any),
    rigid: wp.array(dtype=Any),
    inverse_drag: Any,
    gravity: Any,
    dt: Any,
    x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
):
    """Mobility model: v = (F/M - g ẑ - a_rigid) / ζ (`specific_force`), then x += dt v (v is what the
    ground sees next step); ζ is the drag per unit mass against the lab frame."""
    i = wp.tid()
    vi = inverse_drag * specific_force(forces[i], inverse_mass[i], rigid, x[i] - rigid[2], gravity)
    v[i] = vi
    x[i] = x[i] + dt * vi


@wp.kernel
def reference_ramp_kernel(start: wp.array(dtype=Any), end: wp.array(dtype=Any), fraction: Any, out: wp.array(dtype=Any)):
    """out = start + fraction (end - start): the concentration the active reference follows within a chemistry step."""
    i = wp.tid()
    out[i] = start[i] + fraction * (end[i] - start[i])


@wp.kernel
def first_moment_kernel(mass: wp.array(dtype=Any), x: wp.array(dtype=Any), threads: int, moment: wp.array(dtype=Any)):
    """moment[0] += Σ M_I x_I (zeroed by the caller; launched on whole blocks, as rigid_sums_kernel)."""
    r = type(x[0])()
    for i in range(wp.tid(), x.shape[0], threads):
        r += mass[i] * x[i]
    block_add(moment, 0, r)


@wp.kernel
def trace_row_kernel(
    c: wp.array(dtype=Any), x: wp.array(dtype=Any), origin: int, moment: wp.array(dtype=Any),
    inverse_total_mass: Any, row: wp.array(dtype=wp.int32), trace: wp.array2d(dtype=Any),
):  # fmt: skip
    """Single thread: trace[row] = [c_origin, centre of mass (3), x_origin (3)], then row += 1.
    Rows past the buffer (steps advanced beyond one frame's) are counted, not written."""
    k = row[0]
    row[0] = k + 1
    if k >= trace.shape[0]:
        return
    centre = inverse_total_mass * moment[0]
    trace[k, 0] = c[origin]
    for j in range(3):
        trace[k, 1 + j] = centre[j]
        trace[k, 4 + j] = x[origin][j]


@wp.kernel
def speed_runaway_kernel(v: wp.array(dtype=Any), limit: Any, flag: wp.array(dtype=wp.int32)):
    """flag = 1 where |v_I| > limit or v_I is NaN/Inf (NaN fails every comparison)."""
    i = wp.tid()
    if not (wp.length(v[i]) <= limit):
        flag[0] = 1


declare_overloads(rigid_sums_kernel, forces="vec3[]", mass="scalar[]", x="vec3[]", v="vec3[]", sums="vec3[]",
                  second_moment="mat33[]")  # fmt: skip
declare_overloads(rigid_correction_kernel, sums="vec3[]", second_moment="mat33[]", inverse_total_mass="scalar",
                  correction="vec3[]")  # fmt: skip
declare_overloads(symplectic_euler_kernel, forces="vec3[]", inverse_mass="scalar[]", rigid="vec3[]", damping="scalar",
                  gravity="scalar", dt="scalar", x="vec3[]", v="vec3[]")  # fmt: skip
declare_overloads(overdamped_euler_kernel, forces="vec3[]", inverse_mass="scalar[]", rigid="vec3[]",
                  inverse_drag="scalar", gravity="scalar", dt="scalar", x="vec3[]", v="vec3[]")  # fmt: skip
declare_overloads(reference_ramp_kernel, start="scalar[]", end="scalar[]", fraction="scalar", out="scalar[]")
declare_overloads(first_moment_kernel, mass="scalar[]", x="vec3[]", moment="vec3[]")
declare_overloads(trace_row_kernel, c="scalar[]", x="vec3[]", moment="vec3[]", inverse_total_mass="scalar",
                  trace="scalar[,]")  # fmt: skip
declare_overloads(speed_runaway_kernel, v="vec3[]", limit="scalar")


# ---------------------------------------------------------------- launchers


def eval_rigid_correction(forces: wp.array, mass: wp.array, x: wp.array, v: wp.array, with_momentum: bool, threads: int,
                          inverse_total_mass: float, sums: wp.array, second_moment: wp.array, rigid: wp.array) -> None:  # fmt: skip
    """rigid: the rigid-body acceleration that removes the net force and torque of `forces` (their
    round-off), and with_momentum the rigid velocity of the same momentum and angular momentum."""
    device = x.device
    wp.launch(rigid_sums_kernel, dim=threads, inputs=[forces, mass, x, v, int(with_momentum), threads],
              outputs=[sums, second_moment], block_dim=REDUCTION_BLOCK, device=device)  # fmt: skip
    wp.launch(rigid_correction_kernel, dim=1, inputs=[sums, second_moment, scalar_of(mass)(inverse_total_mass)],
              outputs=[rigid], device=device)  # fmt: skip


def integrate_symplectic_euler(forces, inverse_mass, rigid, damping: float, gravity: float, dt: float, x, v) -> None:
    """v += dt (F/M - rigid - g ẑ - η (v - v_rigid)), then x += dt v."""
    s = scalar_of(inverse_mass)
    wp.launch(symplectic_euler_kernel, dim=len(x), inputs=[forces, inverse_mass, rigid, s(damping), s(gravity), s(dt)],
              outputs=[x, v], device=x.device)  # fmt: skip


def integrate_overdamped_euler(forces, inverse_mass, rigid, inverse_drag: float, gravity: float, dt: float, x, v) -> None:
    """v = (F/M - rigid - g ẑ) / ζ, x += dt v."""
    s = scalar_of(inverse_mass)
    wp.launch(overdamped_euler_kernel, dim=len(x), inputs=[forces, inverse_mass, rigid, s(inverse_drag), s(gravity),
                                                           s(dt)], outputs=[x, v], device=x.device)  # fmt: skip


def eval_reference_ramp(start: wp.array, end: wp.array, fraction: float, out: wp.array) -> None:
    """out = start + fraction (end - start)."""
    wp.launch(reference_ramp_kernel, dim=len(out), inputs=[start, end, scalar_of(out)(fraction)], outputs=[out],
              device=out.device)  # fmt: skip


def eval_trace_row(mass, x, c, origin: int, threads: int, inverse_total_mass: float, moment, row, trace) -> None:
    """trace[row] = [c_origin, centre of mass, x_origin], row += 1 (device only)."""
    moment.zero_()
    wp.launch(first_moment_kernel, dim=threads, inputs=[mass, x, threads], outputs=[moment], block_dim=REDUCTION_BLOCK,
              device=x.device)  # fmt: skip
    wp.launch(trace_row_kernel, dim=1, inputs=[c, x, int(origin), moment, scalar_of(mass)(inverse_total_mass)],
              outputs=[row, trace], device=x.device)  # fmt: skip


def eval_speed_runaway(v: wp.array, limit: float, flag: wp.array) -> None:
    """flag = 1 where some |v_I| passed `limit` or is NaN/Inf."""
    wp.launch(speed_runaway_kernel, dim=len(v), inputs=[v, scalar_of(v)(limit)], outputs=[flag], device=v.device)
