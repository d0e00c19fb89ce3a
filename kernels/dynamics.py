"""Shell dynamics of the walkers (docs/theory/dynamics.md): symplectic Euler with lumped mass, or the
overdamped mobility model (explicit Euler on M ζ v = F, or its implicit step's anchors and velocity). Each kernel
with its launcher (below).

Batched worlds (`Mesh.union`): `worlds` equal blocks of vertices; the rigid-body sums, the rigid
correction (5 rows per world), the trace and the flags are per world."""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .reduce import REDUCTION_BLOCK, block_add


@wp.kernel
def rigid_sums_kernel(
    forces: wp.array(dtype=Any), mass: wp.array(dtype=Any), x: wp.array(dtype=Any), v: wp.array(dtype=Any),
    with_momentum: int, worlds: int, threads: int, sums: wp.array(dtype=Any), second_moment: wp.array(dtype=Any),
):  # fmt: skip
    """Per world w: sums[5w..5w+4] += [Σ F, Σ x × F, Σ M x, Σ M v, Σ M x × v] (the last two with_momentum);
    second_moment[w] += Σ M x xᵀ. Launched on whole blocks, `threads` per world, thread t of world w
    taking its vertices t, t + threads, ...; `rigid_correction_kernel` consumes the sums and zeroes them."""
    vertices = x.shape[0] // worlds
    w = wp.tid() // threads
    f = type(forces[0])()
    torque = f
    mr = f
    p = f
    angular = f
    second = wp.outer(f, f)
    for i in range(w * vertices + wp.tid() - w * threads, (w + 1) * vertices, threads):
        m = mass[i]
        r = x[i]
        f += forces[i]
        torque += wp.cross(r, forces[i])
        mr += m * r
        second += m * wp.outer(r, r)
        p += m * v[i]
        angular += wp.cross(r, m * v[i])
    block_add(sums, 5 * w, f)
    block_add(sums, 5 * w + 1, torque)
    block_add(sums, 5 * w + 2, mr)
    block_add(second_moment, w, second)
    if with_momentum != 0:  # uniform over the launch: every thread of a block calls block_add
        block_add(sums, 5 * w + 3, p)
        block_add(sums, 5 * w + 4, angular)


@wp.kernel
def rigid_correction_kernel(
    sums: wp.array(dtype=Any), second_moment: wp.array(dtype=Any), inverse_total_mass: wp.array(dtype=Any),
    correction: wp.array(dtype=Any),
):  # fmt: skip
    """One thread per world w: the rigid-body acceleration of the net force N and torque τ and the
    rigid-body velocity of the momentum P and angular momentum L: correction[5w..5w+4] = [N/ΣM,
    α = I⁻¹τ, centre c, v̄ = P/ΣM, Ω = I⁻¹(L - c × P)]; then zeroes the sums for the next step (no
    memset per step)."""
    w = wp.tid()
    k = 5 * w
    inverse = inverse_total_mass[w]
    total = type(inverse)(1.0) / inverse
    c = inverse * sums[k + 2]
    torque = sums[k + 1] - wp.cross(c, sums[k])
    S = second_moment[w] - total * wp.outer(c, c)
    inertia = wp.inverse(wp.trace(S) * wp.identity(n=3, dtype=type(inverse)) - S)
    correction[k] = inverse * sums[k]
    correction[k + 1] = inertia * torque
    correction[k + 2] = c
    correction[k + 3] = inverse * sums[k + 3]
    correction[k + 4] = inertia * (sums[k + 4] - wp.cross(c, sums[k + 3]))
    for j in range(5):
        sums[k + j] = type(c)()
    second_moment[w] = type(S)()


@wp.func
def specific_force(force: Any, inverse_mass: Any, rigid: wp.array(dtype=Any), k: int, r: Any, gravity: Any):
    """F/M + g - a_rigid at a point r = x - c from its world's centre (rigid rows k..k+4; g the gravity
    vector): a_rigid = N/ΣM + α × r undoes the net force and torque of the internal forces' round-off
    (zero in exact arithmetic; in float32 they would set a resting shell rolling)."""
    return inverse_mass * force - rigid[k] - wp.cross(rigid[k + 1], r) + gravity


@wp.kernel
def symplectic_euler_kernel(
    forces: wp.array(dtype=Any),
    inverse_mass: wp.array(dtype=Any),
    rigid: wp.array(dtype=Any),
    damping: Any,
    gravity: Any,
    dt: Any,
    worlds: int,
    move: int,
    x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
):
    """v += dt (F/M + g - a_rigid - η (v - v_rigid)), then (if `move`) x += dt v (the rigid rows of the vertex's
    world; without `move` v is the predictor the implicit contact starts from).

    Gravity M_I g on every control point is the uniform acceleration g (`specific_force`); the damping
    acts on the velocity relative to the rigid-body motion v_rigid = v̄ + Ω × (x - c), so it exerts
    no net force and no torque (it keeps P and L, and lets a shell roll and slide freely).
    """
    i = wp.tid()
    k = 5 * (i // (x.shape[0] // worlds))
    r = x[i] - rigid[k + 2]
    accel = specific_force(forces[i], inverse_mass[i], rigid, k, r, gravity)
    vi = v[i] + dt * (accel - damping * (v[i] - rigid[k + 3] - wp.cross(rigid[k + 4], r)))
    v[i] = vi
    if move != 0:
        x[i] = x[i] + dt * vi


@wp.kernel
def overdamped_euler_kernel(
    forces: wp.array(dtype=Any),
    inverse_mass: wp.array(dtype=Any),
    rigid: wp.array(dtype=Any),
    inverse_drag: Any,
    gravity: Any,
    dt: Any,
    worlds: int,
    move: int,
    x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
):
    """Mobility model: v = (F/M + g - a_rigid) / ζ (`specific_force`), then (if `move`) x += dt v (v is what the
    ground sees next step); ζ is the drag per unit mass against the lab frame."""
    i = wp.tid()
    k = 5 * (i // (x.shape[0] // worlds))
    vi = inverse_drag * specific_force(forces[i], inverse_mass[i], rigid, k, x[i] - rigid[k + 2], gravity)
    v[i] = vi
    if move != 0:
        x[i] = x[i] + dt * vi


@wp.kernel
def implicit_anchor_kernel(start: wp.array(dtype=Any), v: wp.array(dtype=Any), predictor: wp.array(dtype=Any),
                           drift: Any, dt: Any, anchors: wp.array(dtype=Any)):
    """a = x_n + dt (v − v* + g/ζ): where the implicit overdamped step's drag pulls, the step's start moved by the
    ground's velocity change v − v* (its contact and friction, with the drag as mobility) and the gravity drift g/ζ."""
    i = wp.tid()
    anchors[i] = start[i] + dt * (v[i] - predictor[i] + drift)


@wp.kernel
def shell_velocity_kernel(start: wp.array(dtype=Any), x: wp.array(dtype=Any), inverse_dt: Any,
                          v: wp.array(dtype=Any), predictor: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    """out = (x − x_n)/dt − (v − v*): the velocity of an implicit step's solution less the ground's change v − v* it
    was solved with, the shell's own velocity over the step (the next ground pass's predictor)."""
    i = wp.tid()
    out[i] = inverse_dt * (x[i] - start[i]) - (v[i] - predictor[i])


@wp.kernel
def extrapolate_kernel(x: wp.array(dtype=Any), v: wp.array(dtype=Any), dt: Any, out: wp.array(dtype=Any)):
    """out = x + dt v: the implicit step's first guess, the last step's velocity carried on."""
    i = wp.tid()
    out[i] = x[i] + dt * v[i]


@wp.kernel
def step_velocity_kernel(start: wp.array(dtype=Any), x: wp.array(dtype=Any), inverse_dt: Any, v: wp.array(dtype=Any)):
    """v = (x − x_n) / dt: the implicit step's velocity."""
    i = wp.tid()
    v[i] = inverse_dt * (x[i] - start[i])


@wp.kernel
def reference_ramp_kernel(start: wp.array(dtype=Any), end: wp.array(dtype=Any), fraction: Any, out: wp.array(dtype=Any)):
    """out = start + fraction (end - start): the concentration the active reference follows within a chemistry step."""
    i = wp.tid()
    out[i] = start[i] + fraction * (end[i] - start[i])


@wp.kernel
def first_moment_kernel(mass: wp.array(dtype=Any), x: wp.array(dtype=Any), worlds: int, threads: int,
                        moment: wp.array(dtype=Any)):  # fmt: skip
    """moment[w] += Σ M_I x_I over world w (zeroed by the caller; launched on whole blocks, as rigid_sums_kernel)."""
    vertices = x.shape[0] // worlds
    w = wp.tid() // threads
    r = type(x[0])()
    for i in range(w * vertices + wp.tid() - w * threads, (w + 1) * vertices, threads):
        r += mass[i] * x[i]
    block_add(moment, w, r)


@wp.kernel
def trace_row_kernel(
    c: wp.array(dtype=Any), x: wp.array(dtype=Any), origin: wp.array(dtype=wp.int32), moment: wp.array(dtype=Any),
    inverse_total_mass: wp.array(dtype=Any), row: wp.array(dtype=wp.int32), trace: wp.array2d(dtype=Any),
):  # fmt: skip
    """One thread per world w: trace[row[w], 7w..7w+6] = [c_origin, centre of mass (3), x_origin (3)]
    (origin[w] a vertex of world w), then row[w] += 1. Rows past the buffer (steps advanced beyond
    one frame's) are counted, not written."""
    w = wp.tid()
    k = row[w]
    row[w] = k + 1
    if k >= trace.shape[0]:
        return
    centre = inverse_total_mass[w] * moment[w]
    o = origin[w]
    trace[k, 7 * w] = c[o]
    for j in range(3):
        trace[k, 7 * w + 1 + j] = centre[j]
        trace[k, 7 * w + 4 + j] = x[o][j]


@wp.kernel
def speed_runaway_kernel(v: wp.array(dtype=Any), limit: Any, worlds: int, flag: wp.array(dtype=wp.int32)):
    """flag[w] = 1 where |v_I| > limit or v_I is NaN/Inf in world w (NaN fails every comparison)."""
    i = wp.tid()
    if not (wp.length(v[i]) <= limit):
        flag[i // (v.shape[0] // worlds)] = 1


declare_overloads(rigid_sums_kernel, forces="vec3[]", mass="scalar[]", x="vec3[]", v="vec3[]", sums="vec3[]",
                  second_moment="mat33[]")  # fmt: skip
declare_overloads(rigid_correction_kernel, sums="vec3[]", second_moment="mat33[]", inverse_total_mass="scalar[]",
                  correction="vec3[]")  # fmt: skip
declare_overloads(symplectic_euler_kernel, forces="vec3[]", inverse_mass="scalar[]", rigid="vec3[]", damping="scalar",
                  gravity="vec3", dt="scalar", x="vec3[]", v="vec3[]")  # fmt: skip
declare_overloads(overdamped_euler_kernel, forces="vec3[]", inverse_mass="scalar[]", rigid="vec3[]",
                  inverse_drag="scalar", gravity="vec3", dt="scalar", x="vec3[]", v="vec3[]")  # fmt: skip
declare_overloads(implicit_anchor_kernel, start="vec3[]", v="vec3[]", predictor="vec3[]", drift="vec3", dt="scalar",
                  anchors="vec3[]")
declare_overloads(shell_velocity_kernel, start="vec3[]", x="vec3[]", inverse_dt="scalar", v="vec3[]", predictor="vec3[]",
                  out="vec3[]")
declare_overloads(extrapolate_kernel, x="vec3[]", v="vec3[]", dt="scalar", out="vec3[]")
declare_overloads(step_velocity_kernel, start="vec3[]", x="vec3[]", inverse_dt="scalar", v="vec3[]")
declare_overloads(reference_ramp_kernel, start="scalar[]", end="scalar[]", fraction="scalar", out="scalar[]")
declare_overloads(first_moment_kernel, mass="scalar[]", x="vec3[]", moment="vec3[]")
declare_overloads(trace_row_kernel, c="scalar[]", x="vec3[]", moment="vec3[]", inverse_total_mass="scalar[]",
                  trace="scalar[,]")  # fmt: skip
declare_overloads(speed_runaway_kernel, v="vec3[]", limit="scalar")


# ---------------------------------------------------------------- launchers


@one_device
def eval_rigid_correction(forces: wp.array, mass: wp.array, x: wp.array, v: wp.array, with_momentum: bool, worlds: int,
                          threads: int, inverse_total_mass: wp.array, sums: wp.array, second_moment: wp.array,
                          rigid: wp.array) -> None:  # fmt: skip
    """rigid (5 rows per world): the rigid-body acceleration that removes the net force and torque of
    `forces` (their round-off), and with_momentum the rigid velocity of the same momentum and angular
    momentum; `threads` per world."""
    device = x.device
    wp.launch(rigid_sums_kernel, dim=threads * worlds, inputs=[forces, mass, x, v, int(with_momentum), worlds, threads],
              outputs=[sums, second_moment], block_dim=REDUCTION_BLOCK, device=device)  # fmt: skip
    wp.launch(rigid_correction_kernel, dim=worlds, inputs=[sums, second_moment, inverse_total_mass], outputs=[rigid],
              device=device)  # fmt: skip


def integrate_symplectic_euler(forces, inverse_mass, rigid, damping: float, gravity, dt: float, worlds: int, x, v,
                               move: bool = True) -> None:  # fmt: skip
    """v += dt (F/M + g - rigid - η (v - v_rigid)) (g the gravity vector), then (`move`) x += dt v."""
    s = scalar_of(inverse_mass)
    g = wp.types.vector(3, s)(*gravity)
    wp.launch(symplectic_euler_kernel, dim=len(x), inputs=[forces, inverse_mass, rigid, s(damping), g, s(dt), worlds,
                                                           int(move)], outputs=[x, v], device=x.device)  # fmt: skip


def integrate_overdamped_euler(forces, inverse_mass, rigid, inverse_drag: float, gravity, dt: float, worlds: int, x, v,
                               move: bool = True) -> None:  # fmt: skip
    """v = (F/M + g - rigid) / ζ (g the gravity vector), then (`move`) x += dt v."""
    s = scalar_of(inverse_mass)
    g = wp.types.vector(3, s)(*gravity)
    wp.launch(overdamped_euler_kernel, dim=len(x), inputs=[forces, inverse_mass, rigid, s(inverse_drag), g, s(dt),
                                                           worlds, int(move)], outputs=[x, v], device=x.device)  # fmt: skip


@one_device
def eval_shell_velocity(start, x, dt: float, v, predictor, out) -> None:
    """out = (x − x_n)/dt − (v − v*) (`shell_velocity_kernel`)."""
    s = scalar_of(out)
    wp.launch(shell_velocity_kernel, dim=len(out), inputs=[start, x, s(1.0 / dt), v, predictor], outputs=[out],
              device=out.device)


@one_device
def eval_implicit_anchors(start, v, predictor, drift, dt: float, anchors) -> None:
    """anchors = x_n + dt (v − v* + drift) (drift = g/ζ, a vector)."""
    s = scalar_of(anchors)
    wp.launch(implicit_anchor_kernel, dim=len(anchors), inputs=[start, v, predictor, wp.types.vector(3, s)(*drift),
                                                                s(dt)], outputs=[anchors], device=anchors.device)


@one_device
def eval_extrapolate(x, v, dt: float, out) -> None:
    """out = x + dt v."""
    wp.launch(extrapolate_kernel, dim=len(out), inputs=[x, v, scalar_of(out)(dt)], outputs=[out], device=out.device)


@one_device
def eval_step_velocity(start, x, dt: float, v) -> None:
    """v = (x − x_n) / dt."""
    wp.launch(step_velocity_kernel, dim=len(v), inputs=[start, x, scalar_of(v)(1.0 / dt)], outputs=[v], device=v.device)


@one_device
def eval_reference_ramp(start: wp.array, end: wp.array, fraction: float, out: wp.array) -> None:
    """out = start + fraction (end - start)."""
    wp.launch(reference_ramp_kernel, dim=len(out), inputs=[start, end, scalar_of(out)(fraction)], outputs=[out],
              device=out.device)  # fmt: skip


@one_device
def eval_trace_row(mass, x, c, origin: wp.array, worlds: int, threads: int, inverse_total_mass: wp.array, moment, row,
                   trace) -> None:  # fmt: skip
    """trace[row[w], 7w..] = [c_origin, centre of mass, x_origin] of every world w, row += 1 (device only)."""
    moment.zero_()
    wp.launch(first_moment_kernel, dim=threads * worlds, inputs=[mass, x, worlds, threads], outputs=[moment],
              block_dim=REDUCTION_BLOCK, device=x.device)  # fmt: skip
    wp.launch(trace_row_kernel, dim=worlds, inputs=[c, x, origin, moment, inverse_total_mass], outputs=[row, trace],
              device=x.device)  # fmt: skip


@one_device
def eval_speed_runaway(v: wp.array, limit: float, worlds: int, flag: wp.array) -> None:
    """flag[w] = 1 where some |v_I| of world w passed `limit` or is NaN/Inf."""
    wp.launch(speed_runaway_kernel, dim=len(v), inputs=[v, scalar_of(v)(limit), worlds], outputs=[flag], device=v.device)
