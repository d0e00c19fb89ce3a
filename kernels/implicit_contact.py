"""The implicit ground (`Ground(solve="implicit")`, docs/theory/dynamics.md), one kernel per step of the solve,
each with its launcher: each point's contact and friction force f consistent with its own end-of-step velocity
u⁺ = u* + r f (u* without contact; r the point's response: the row sum of L M⁻¹ Lᵀ over the points in contact,
times dt, or 1/ζ overdamped), then Jacobi sweeps in which each point sees the others' forces (kernels/contact.py:
the points, their gather and spread).
"""

from dataclasses import dataclass
from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of
from .contact import ground_motion, limit_transpose_at, spread_to_control_points
from .limit_surface import basis_row
from .reduce import REDUCTION_BLOCK, block_add


@wp.kernel
def contact_indicator_kernel(p: wp.array(dtype=Any), active: wp.array(dtype=Any)):
    """active_i = (1, 0, 0) where point i is at or below the ground (z ≤ 0), else 0: the unit load on the contact set."""
    i = wp.tid()
    z = p[i][2]
    zero = type(z)(0.0)
    active[i] = type(p[i])()
    if z <= zero:
        active[i] = type(p[i])(type(z)(1.0), zero, zero)


@wp.func
def limit_inverse_mass_gather(
    load: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), ring_start: wp.array(dtype=wp.int32),
    ring: wp.array(dtype=wp.int32), centre_weight: wp.array(dtype=Any), ring_weight: wp.array(dtype=Any), i: int,
):  # fmt: skip
    """(L M⁻¹ load)_i: limit point i's velocity change per unit scale under the control-point forces `load`."""
    s = centre_weight[i] * inverse_mass[i] * load[i]
    for k in range(ring_start[i], ring_start[i + 1]):
        j = ring[k]
        s += ring_weight[i] * inverse_mass[j] * load[j]
    return s


@wp.func
def patch_inverse_mass_gather(
    load: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any), t: int, row: int,
):  # fmt: skip
    """Σ_J N_J(q) load_J / M_J over triangle t's patch at basis row `row` (quadrature point q)."""
    start = patch_start[t]
    s = basis[row, 0][0] * inverse_mass[patch_vertices[start]] * load[patch_vertices[start]]
    for k in range(1, patch_start[t + 1] - start):
        j = patch_vertices[start + k]
        s += basis[row, k][0] * inverse_mass[j] * load[j]
    return s


@wp.kernel
def limit_response_kernel(
    load: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), ring_start: wp.array(dtype=wp.int32),
    ring: wp.array(dtype=wp.int32), centre_weight: wp.array(dtype=Any), ring_weight: wp.array(dtype=Any),
    response: wp.array(dtype=Any),
):  # fmt: skip
    """response_i = Σ_J L_iJ load_J,x / M_J with load = Lᵀ(unit load on the contact set): the row sums of L M⁻¹ Lᵀ."""
    i = wp.tid()
    response[i] = limit_inverse_mass_gather(load, inverse_mass, ring_start, ring, centre_weight, ring_weight, i)[0]


@wp.kernel
def quadrature_response_kernel(
    load: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32), triangle_type: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any),
    points_per_triangle: int, response: wp.array(dtype=Any),
):  # fmt: skip
    """response_q = Σ_J N_J(q) load_J,x / M_J, load_J = Σ_{q' in contact} N_J(q') dω̄⁰_q': per unit pressure."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    response[q] = patch_inverse_mass_gather(load, inverse_mass, patch_start, patch_vertices, basis, t, row)[0]


@wp.kernel
def limit_coupled_velocity_kernel(
    load: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), scale: Any, ring_start: wp.array(dtype=wp.int32),
    ring: wp.array(dtype=wp.int32), centre_weight: wp.array(dtype=Any), ring_weight: wp.array(dtype=Any),
    predictor: wp.array(dtype=Any), response: wp.array(dtype=Any), limit_forces: wp.array(dtype=Any),
    others: wp.array(dtype=Any),
):  # fmt: skip
    """others_i = u*_i + scale (L M⁻¹ load)_i - r_i f_i with load = Lᵀ f: point i's end-of-step velocity under every
    contact force but its own (a Jacobi sweep of the coupled contact problem)."""
    i = wp.tid()
    s = limit_inverse_mass_gather(load, inverse_mass, ring_start, ring, centre_weight, ring_weight, i)
    others[i] = predictor[i] + scale * (s - response[i] * limit_forces[i])


@wp.kernel
def quadrature_coupled_velocity_kernel(
    load: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), scale: Any, patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32), triangle_type: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any),
    points_per_triangle: int, predictor: wp.array(dtype=Any), response: wp.array(dtype=Any),
    limit_forces: wp.array(dtype=Any), others: wp.array(dtype=Any),
):  # fmt: skip
    """`limit_coupled_velocity_kernel` on the quadrature points (load = Σ_q N_I(q) f_q dω̄⁰_q, f a pressure)."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    s = patch_inverse_mass_gather(load, inverse_mass, patch_start, patch_vertices, basis, t, row)
    others[q] = predictor[q] + scale * (s - response[q] * limit_forces[q])


@wp.func
def slip_speed(speed: Any, a: Any, k_f: Any):
    """The end-of-step slip speed s ≥ 0 of s + a tanh(k_f s) = speed (a = r μ F_n): Newton from s = 0,
    which climbs monotonically to the root of this concave increasing function; k_f = ∞ is Coulomb's
    law, s = max(speed - a, 0)."""
    zero = type(speed)(0.0)
    one = type(speed)(1.0)
    if wp.isinf(k_f):
        return wp.max(speed - a, zero)
    s = zero
    for _ in range(60):
        th = wp.tanh(k_f * s)
        step = (speed - s - a * th) / (one + a * k_f * (one - th * th))
        s = s + step
        if step <= type(speed)(1e-7) * speed:
            break
    return wp.min(s, speed)


@wp.func
def implicit_normal_force(z: Any, u_z: Any, r: Any, dt: Any, k: Any, beta: Any):
    """F_n = max(k z² - β' u⁺_z, 0) with u⁺_z = u*_z + r F_n and β' = β + 2k|z| dt (the penalty linearised at
    z + dt u⁺_z): F_n = max((k z² - β' u*_z) / (1 + β' r), 0) where z ≤ 0, else 0."""
    zero = type(z)(0.0)
    damping = beta - type(z)(2.0) * k * z * dt
    fn = (k * z * z - damping * u_z) / (type(z)(1.0) + damping * r)
    if z > zero or fn < zero:  # above ground, or pulling down: no contact force
        fn = zero
    return fn


@wp.func
def friction_magnitude(speed: Any, r: Any, cap: Any, k_f: Any):
    """|f_t| of a point whose tangential velocity without friction is `speed` (response r, cap μ F_n):
    μ F_n tanh(k_f s) with s its end-of-step slip speed; Coulomb (k_f = ∞): min(μ F_n, speed / r)."""
    if wp.isinf(k_f):
        return wp.min(cap, speed / r)
    return cap * wp.tanh(k_f * slip_speed(speed, r * cap, k_f))


@wp.func
def friction_slope_at_rest(r: Any, cap: Any, k_f: Any):
    """d|f_t| / d speed of `friction_magnitude` at speed 0: 1/r for Coulomb's law (a sticking point), and
    μ F_n k_f / (1 + r μ F_n k_f) for the tanh law."""
    if wp.isinf(k_f):
        return type(r)(1.0) / r
    return cap * k_f / (type(r)(1.0) + r * cap * k_f)


@wp.func
def implicit_law(z: Any, u: Any, r: Any, dt: Any, k: Any, beta: Any, mu: Any, k_f: Any, shift: Any):
    """(F_n, f) of a point at height z with velocity u without contact, response r and body velocity `shift`
    (`implicit_contact_kernel`)."""
    zero = type(z)(0.0)
    fn = implicit_normal_force(z, u[2], r, dt, k, beta)
    f = type(u)(zero, zero, fn)
    v_t = type(u)(u[0] + shift[0], u[1] + shift[1], zero)
    speed = wp.length(v_t)
    if speed > zero and fn > zero:
        f = f - (friction_magnitude(speed, r, mu * fn, k_f) / speed) * v_t
    return fn, f


@wp.kernel
def implicit_contact_kernel(
    p: wp.array(dtype=Any), u: wp.array(dtype=Any), response: wp.array(dtype=Any), scale: Any, dt: Any, k: Any,
    beta: Any, mu: Any, k_f: Any, body: wp.array(dtype=Any), normal_force: wp.array(dtype=Any),
    limit_forces: wp.array(dtype=Any),
):  # fmt: skip
    """Point i's force f with its end-of-step velocity u⁺ = u* + U + r f, r = scale × response_i and U its world's
    horizontal body velocity (`body`, one per world; zero with the drag in the lab frame;
    docs/theory/dynamics.md): the normal force of `implicit_normal_force`; friction -μ F_n tanh(k_f s) along
    u*_t + U, s = |u⁺_t| the slip speed (`slip_speed`; Coulomb for k_f = ∞: the point sticks while
    |u*_t + U| ≤ r μ F_n)."""
    i = wp.tid()
    shift = body[i // (p.shape[0] // body.shape[0])]
    fn, f = implicit_law(p[i][2], u[i], scale * response[i], dt, k, beta, mu, k_f, shift)
    normal_force[i] = fn
    limit_forces[i] = f


@wp.kernel
def limit_first_contact_kernel(
    p: wp.array(dtype=Any), u: wp.array(dtype=Any), coupling_start: wp.array(dtype=wp.int32),
    coupling_point: wp.array(dtype=wp.int32), coupling_value: wp.array(dtype=Any), scale: Any, dt: Any, k: Any,
    beta: Any, mu: Any, k_f: Any, body: wp.array(dtype=Any), response: wp.array(dtype=Any),
    normal_force: wp.array(dtype=Any), limit_forces: wp.array(dtype=Any),
):  # fmt: skip
    """The implicit contact's first pass on the limit points in one launch: a point on or below the ground gets its
    response r_i = Σ_k C_ik over the points k on or below it (C = L M⁻¹ Lᵀ, `Coupling`; the row sums of
    `limit_response_kernel`), then its law alone (`implicit_contact_kernel`). Points above the ground have no force:
    response 0."""
    i = wp.tid()
    z = p[i][2]
    r = type(z)(0.0)
    if z <= r:
        for m in range(coupling_start[i], coupling_start[i + 1]):
            if p[coupling_point[m]][2] <= type(z)(0.0):
                r += coupling_value[m]
    response[i] = r
    shift = body[i // (p.shape[0] // body.shape[0])]
    fn, f = implicit_law(z, u[i], scale * r, dt, k, beta, mu, k_f, shift)
    normal_force[i] = fn
    limit_forces[i] = f


@wp.kernel
def limit_contact_sweep_kernel(
    p: wp.array(dtype=Any), predictor: wp.array(dtype=Any), forces: wp.array(dtype=Any),
    coupling_start: wp.array(dtype=wp.int32), coupling_point: wp.array(dtype=wp.int32),
    coupling_value: wp.array(dtype=Any), response: wp.array(dtype=Any), scale: Any, dt: Any, k: Any, beta: Any,
    mu: Any, k_f: Any, body: wp.array(dtype=Any), others: wp.array(dtype=Any), normal_force: wp.array(dtype=Any),
    new_forces: wp.array(dtype=Any),
):  # fmt: skip
    """One Jacobi sweep on the limit points in one launch: others_i = u*_i + scale ((C f)_i - r_i f_i) over point i's
    row of C = L M⁻¹ Lᵀ (`limit_coupled_velocity_kernel`'s velocity, summed in another order; f is 0 off the
    ground), then the law at others_i into `new_forces` (`implicit_contact_kernel`). A point above the ground has
    no force whatever its velocity: it keeps others_i = u*_i."""
    i = wp.tid()
    z = p[i][2]
    o = predictor[i]
    if z <= type(z)(0.0):
        s = type(o)()
        for m in range(coupling_start[i], coupling_start[i + 1]):
            s += coupling_value[m] * forces[coupling_point[m]]
        o = o + scale * (s - response[i] * forces[i])
    others[i] = o
    shift = body[i // (p.shape[0] // body.shape[0])]
    fn, f = implicit_law(z, o, scale * response[i], dt, k, beta, mu, k_f, shift)
    normal_force[i] = fn
    new_forces[i] = f


@wp.kernel
def limit_contact_velocity_kernel(
    forces: wp.array(dtype=Any), ring_start: wp.array(dtype=wp.int32), ring: wp.array(dtype=wp.int32),
    centre_weight: wp.array(dtype=Any), ring_weight: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any),
    scale: Any, dt: Any, x: wp.array(dtype=Any), v: wp.array(dtype=Any),
):  # fmt: skip
    """`contact_velocity_kernel` with its load Lᵀ f formed in place (`limit_transpose_kernel`, bit for bit)."""
    i = wp.tid()
    load = type(v[i])() + limit_transpose_at(forces, ring_start, ring, centre_weight, ring_weight, i)
    vi = v[i] + (scale * inverse_mass[i]) * load
    v[i] = vi
    x[i] = x[i] + dt * vi


@wp.kernel
def body_friction_sums_kernel(
    p: wp.array(dtype=Any), u: wp.array(dtype=Any), response: wp.array(dtype=Any), weight: wp.array(dtype=Any),
    scale: Any, dt: Any, k: Any, beta: Any, mu: Any, k_f: Any, body: wp.array(dtype=Any), threads: int,
    force_sum: wp.array(dtype=Any), stiffness_sum: wp.array(dtype=Any),
):  # fmt: skip
    """Per world w (`threads` per world, thread t taking its points t, t + threads, ...): the net friction
    force_sum[w] += Σ_q a_q f_t,q of `implicit_contact_kernel`'s law at body velocity U_w, and
    stiffness_sum[w] += Σ_q a_q |f_t,q| / |y_q| (y_q = u*_q + U_w its slip velocity without friction; the
    law's slope at y = 0), the isotropic majorant of -∂(Σ a f_t)/∂U. a_q: the point's weight (1, or dω̄⁰
    for pressures)."""
    worlds = body.shape[0]
    points = p.shape[0] // worlds
    w = wp.tid() // threads
    zero = type(dt)(0.0)
    force = type(p[0])()
    stiffness = zero
    for q in range(w * points + wp.tid() - w * threads, (w + 1) * points, threads):
        r = scale * response[q]
        fn = implicit_normal_force(p[q][2], u[q][2], r, dt, k, beta)
        if fn > zero:
            y = type(p[0])(u[q][0] + body[w][0], u[q][1] + body[w][1], zero)
            speed = wp.length(y)
            if speed > zero:
                m = friction_magnitude(speed, r, mu * fn, k_f)
                force -= (weight[q] * m / speed) * y
                stiffness += weight[q] * m / speed
            else:
                stiffness += weight[q] * friction_slope_at_rest(r, mu * fn, k_f)
    block_add(force_sum, w, force)
    block_add(stiffness_sum, w, stiffness)


@wp.kernel
def body_velocity_kernel(
    force_sum: wp.array(dtype=Any), stiffness_sum: wp.array(dtype=Any), external: wp.array(dtype=Any),
    body: wp.array(dtype=Any),
):  # fmt: skip
    """One step per world w towards G(U) = Σ_q a_q f_t,q(U) + external_w = 0 (the world's net horizontal force):
    U_w += G / Σ_q a_q |f_t,q| / |y_q|, a Weiszfeld (iteratively reweighted) step, which lowers the friction's
    dissipation potential every time for a law whose |f_t| / |y| falls with |y| (Coulomb, tanh); then zeroes
    the sums for the next pass."""
    w = wp.tid()
    g = force_sum[w] + external[w]
    h = stiffness_sum[w]
    if h > type(h)(0.0):
        body[w] = body[w] + g / h
    force_sum[w] = type(g)()
    stiffness_sum[w] = type(h)(0.0)


@wp.kernel
def add_body_velocity_kernel(body: wp.array(dtype=Any), v: wp.array(dtype=Any)):
    """v_I += U_w: each control point of world w takes its world's body velocity."""
    i = wp.tid()
    v[i] = v[i] + body[i // (v.shape[0] // body.shape[0])]


@wp.kernel
def contact_velocity_kernel(
    contact: wp.array(dtype=Any), inverse_mass: wp.array(dtype=Any), scale: Any, dt: Any, x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
):  # fmt: skip
    """v_I += scale (Lᵀ f)_I / M_I (scale dt, or 1/ζ overdamped), then x_I += dt v_I."""
    i = wp.tid()
    vi = v[i] + (scale * inverse_mass[i]) * contact[i]
    v[i] = vi
    x[i] = x[i] + dt * vi


declare_overloads(contact_indicator_kernel, p="vec3[]", active="vec3[]")
declare_overloads(limit_response_kernel, load="vec3[]", inverse_mass="scalar[]", centre_weight="scalar[]",
                  ring_weight="scalar[]", response="scalar[]")  # fmt: skip
declare_overloads(quadrature_response_kernel, load="vec3[]", inverse_mass="scalar[]", basis="vec6[,]", response="scalar[]")
declare_overloads(limit_coupled_velocity_kernel, load="vec3[]", inverse_mass="scalar[]", scale="scalar",
                  centre_weight="scalar[]", ring_weight="scalar[]", predictor="vec3[]", response="scalar[]",
                  limit_forces="vec3[]", others="vec3[]")  # fmt: skip
declare_overloads(quadrature_coupled_velocity_kernel, load="vec3[]", inverse_mass="scalar[]", scale="scalar",
                  basis="vec6[,]", predictor="vec3[]", response="scalar[]", limit_forces="vec3[]", others="vec3[]")  # fmt: skip
declare_overloads(implicit_contact_kernel, p="vec3[]", u="vec3[]", response="scalar[]", scale="scalar", dt="scalar",
                  k="scalar", beta="scalar", mu="scalar", k_f="scalar", body="vec3[]", normal_force="scalar[]",
                  limit_forces="vec3[]")  # fmt: skip
declare_overloads(limit_first_contact_kernel, p="vec3[]", u="vec3[]", coupling_value="scalar[]", scale="scalar",
                  dt="scalar", k="scalar", beta="scalar", mu="scalar", k_f="scalar", body="vec3[]",
                  response="scalar[]", normal_force="scalar[]", limit_forces="vec3[]")  # fmt: skip
declare_overloads(limit_contact_sweep_kernel, p="vec3[]", predictor="vec3[]", forces="vec3[]",
                  coupling_value="scalar[]", response="scalar[]", scale="scalar", dt="scalar", k="scalar",
                  beta="scalar", mu="scalar", k_f="scalar", body="vec3[]", others="vec3[]", normal_force="scalar[]",
                  new_forces="vec3[]")  # fmt: skip
declare_overloads(limit_contact_velocity_kernel, forces="vec3[]", centre_weight="scalar[]", ring_weight="scalar[]",
                  inverse_mass="scalar[]", scale="scalar", dt="scalar", x="vec3[]", v="vec3[]")  # fmt: skip
declare_overloads(body_friction_sums_kernel, p="vec3[]", u="vec3[]", response="scalar[]", weight="scalar[]",
                  scale="scalar", dt="scalar", k="scalar", beta="scalar", mu="scalar", k_f="scalar", body="vec3[]",
                  force_sum="vec3[]", stiffness_sum="scalar[]")  # fmt: skip
declare_overloads(body_velocity_kernel, force_sum="vec3[]", stiffness_sum="scalar[]", external="vec3[]", body="vec3[]")
declare_overloads(add_body_velocity_kernel, body="vec3[]", v="vec3[]")
declare_overloads(contact_velocity_kernel, contact="vec3[]", inverse_mass="scalar[]", scale="scalar", dt="scalar",
                  x="vec3[]", v="vec3[]")  # fmt: skip


# ---------------------------------------------------------------- launchers


@dataclass
class BodyFrame:
    """Where the overdamped drag acts: one horizontal body velocity U per world (`velocity`). In the lab frame
    (`solve` False) U stays 0. In the body frame each implicit contact pass first solves U by `iterations`
    Weiszfeld steps (first pass, then each sweep) so that the world's net horizontal force — the friction
    (points weighted by `weight`) plus `external` — vanishes; every control point then moves with U on top.
    `force_sum`, `stiffness_sum`: per-world scratch; `threads` per world for their sums."""

    velocity: wp.array
    solve: bool = False
    external: wp.array | None = None
    weight: wp.array | None = None
    force_sum: wp.array | None = None
    stiffness_sum: wp.array | None = None
    threads: int = 0
    iterations: tuple = (2, 2)


@dataclass
class Coupling:
    """C = L M⁻¹ Lᵀ on the limit points as CSR on the device (`start`, `point`, `value`): the implicit contact's
    sweeps' operator, fixed by the mesh and the masses (`wavewarp.geometry.limit_coupling` forms it)."""

    start: wp.array
    point: wp.array
    value: wp.array

    @classmethod
    def of(cls, csr: tuple, scalar, device=None) -> "Coupling":
        start, point, value = csr
        with wp.ScopedDevice(device):
            return cls(wp.array(start, dtype=wp.int32), wp.array(point, dtype=wp.int32),
                       wp.array(value, dtype=scalar))  # fmt: skip

    def arrays(self) -> list:
        return [self.start, self.point, self.value]


def solve_body_velocity(body: BodyFrame, points: wp.array, u: wp.array, response: wp.array, laws: list,
                        iterations: int) -> None:  # fmt: skip
    """`iterations` Weiszfeld steps of each world's body velocity U on its net horizontal force (`body_friction_sums_kernel`,
    `body_velocity_kernel`), the points' velocities without friction `u` (plus U); `laws` those of
    `implicit_contact_kernel` (scale, dt, k, β, μ, k_f)."""
    device, worlds = points.device, len(body.velocity)
    for _ in range(iterations):
        wp.launch(body_friction_sums_kernel, dim=worlds * body.threads,
                  inputs=[points, u, response, body.weight, *laws, body.velocity, body.threads],
                  outputs=[body.force_sum, body.stiffness_sum], device=device, block_dim=REDUCTION_BLOCK)  # fmt: skip
        wp.launch(body_velocity_kernel, dim=worlds, inputs=[body.force_sum, body.stiffness_sum, body.external],
                  outputs=[body.velocity], device=device)  # fmt: skip


@one_device
def eval_implicit_ground(ground, x: wp.array, v: wp.array, inverse_mass: wp.array, scale: float, dt: float, mask,
                         patch: list, rest_area, points: wp.array, velocities: wp.array, response: wp.array,
                         others: wp.array, normal_force: wp.array, point_forces: wp.array, load: wp.array,
                         body: BodyFrame, coupling: Coupling | None = None) -> None:  # fmt: skip
    """The implicit contact step: v holds the velocities without contact (u* = L v on the ground's
    points); each point's force is solved against its own response (`implicit_contact_kernel`), then
    refined by `ground.sweeps` Jacobi sweeps in which each point sees the others' forces, then
    v += scale M⁻¹ Lᵀ f (+ U, `body`) and x += dt v. `response`, `others` and `load` are scratch. On the limit
    points in the lab frame (the scenes' default) each pass is one launch (`eval_limit_sweeps`, with `coupling`)."""
    n, s, device = len(points), scalar_of(normal_force), x.device
    point = ground.contact == "point"
    tables = [mask.ring_start, mask.ring, mask.centre_weight, mask.ring_weight] if point else list(patch)
    laws = [s(scale), s(dt), s(ground.stiffness), s(ground.damping), s(ground.friction), s(ground.sharpness)]
    ground_motion(ground, x, v, mask, patch, points, velocities)
    if point and not body.solve:
        passes = [(point_forces, load)[(ground.sweeps - s) % 2] for s in range(ground.sweeps + 1)]  # the last: f
        eval_limit_sweeps(points, velocities, coupling, laws, body.velocity, response, normal_force, passes,
                          [others] * len(passes))  # fmt: skip
        wp.launch(limit_contact_velocity_kernel, dim=len(x), inputs=[point_forces, *tables, inverse_mass, *laws[:2]],
                  outputs=[x, v], device=device)  # fmt: skip
        return
    wp.launch(contact_indicator_kernel, dim=n, inputs=[points], outputs=[point_forces], device=device)
    load.zero_()
    spread_to_control_points(ground, point_forces, mask, patch, rest_area, load)
    wp.launch(limit_response_kernel if point else quadrature_response_kernel, dim=n, inputs=[load, inverse_mass, *tables],
              outputs=[response], device=device)  # fmt: skip
    if body.solve:
        body.velocity.zero_()
        solve_body_velocity(body, points, velocities, response, laws, body.iterations[0])
    wp.launch(implicit_contact_kernel, dim=n, inputs=[points, velocities, response, *laws, body.velocity],
              outputs=[normal_force, point_forces], device=device)  # fmt: skip
    coupled = limit_coupled_velocity_kernel if point else quadrature_coupled_velocity_kernel
    for _ in range(ground.sweeps):
        load.zero_()
        spread_to_control_points(ground, point_forces, mask, patch, rest_area, load)
        wp.launch(coupled, dim=n, inputs=[load, inverse_mass, s(scale), *tables, velocities, response, point_forces],
                  outputs=[others], device=device)  # fmt: skip
        if body.solve:
            solve_body_velocity(body, points, others, response, laws, body.iterations[1])
        wp.launch(implicit_contact_kernel, dim=n, inputs=[points, others, response, *laws, body.velocity],
                  outputs=[normal_force, point_forces], device=device)  # fmt: skip
    load.zero_()
    spread_to_control_points(ground, point_forces, mask, patch, rest_area, load)
    if body.solve:
        wp.launch(add_body_velocity_kernel, dim=len(v), inputs=[body.velocity], outputs=[v], device=device)
    wp.launch(contact_velocity_kernel, dim=len(x), inputs=[load, inverse_mass, s(scale), s(dt)], outputs=[x, v],
              device=device)  # fmt: skip


@one_device
def eval_limit_sweeps(points: wp.array, velocities: wp.array, coupling: Coupling, laws: list, body: wp.array,
                      response: wp.array, normal_force: wp.array, forces: list, others: list) -> None:  # fmt: skip
    """The implicit contact's passes on the limit points (lab frame), one launch each: the first pass (responses,
    the law alone) into forces[0], then a Jacobi sweep per further entry of `forces` over the rows of `coupling`,
    sweep s reading forces[s - 1] and writing forces[s] and others[s] (the solver alternates two buffers, the
    adjoint keeps every pass)."""
    n, device = len(points), points.device
    wp.launch(limit_first_contact_kernel, dim=n, inputs=[points, velocities, *coupling.arrays(), *laws, body],
              outputs=[response, normal_force, forces[0]], device=device)  # fmt: skip
    for sweep in range(1, len(forces)):
        wp.launch(limit_contact_sweep_kernel, dim=n,
                  inputs=[points, velocities, forces[sweep - 1], *coupling.arrays(), response, *laws, body],
                  outputs=[others[sweep], normal_force, forces[sweep]], device=device)  # fmt: skip
