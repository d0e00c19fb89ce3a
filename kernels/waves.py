"""Time-step kernels of the chemical waves (docs/theory/chemistry.md): one per physical term, per vertex.

Telegraph `c_tt + α c_t = γ² Δ c` (leapfrog with centred damping), FitzHugh–Nagumo
`c_t = γ² Δ c + c(1-c)(c-ν) - w`, `w_t = ε (c - κ w)` (explicit Euler, and IMEX Euler whose
implicit diffusion is solved by the Jacobi-preconditioned conjugate gradients below).
Here `acceleration` is the diffusion term's `M̃⁻¹ K c` (wavewarp/waves.py builds it), so the
kernels below see only per-vertex numbers. One int32 flag per stepper and world, read once per chunk
(docs/theory/scenes.md), says what failed: RUNAWAY (NaN/Inf or past the limit) or FLIP_FLOP (FHN's bounded
period-2 oscillation past its time-step bound). The CG's dot products (kernels/laplace.py `dot_kernel`)
sum interleaved strides per thread and add the partial sums atomically: no host round-trips,
graph-capturable.
"""

from typing import Any

import warp as wp

from . import declare_overloads, one_device, scalar_of

RUNAWAY = wp.constant(1)  # flag codes; a later RUNAWAY overwrites FLIP_FLOP
FLIP_FLOP = wp.constant(2)


@wp.kernel
def telegraph_kernel(acceleration: wp.array(dtype=Any), gamma2: Any, damping: Any, dt: Any, c: wp.array(dtype=Any), v: wp.array(dtype=Any)):
    """v^{n+½} = [(1 - αdt/2) v^{n-½} - dt γ² M̃⁻¹Kc^n] / (1 + αdt/2);  c^{n+1} = c^n + dt v^{n+½}.

    `damping` is αdt/2. Stable while dt < 2 / (γ sqrt(λ_max(M̃⁻¹K))) (docs/theory/chemistry.md).
    """
    i = wp.tid()
    one = type(dt)(1.0)
    velocity = ((one - damping) * v[i] - dt * gamma2 * acceleration[i]) / (one + damping)
    v[i] = velocity
    c[i] = c[i] + dt * velocity


@wp.kernel
def telegraph_recentre_kernel(acceleration: wp.array(dtype=Any), gamma2: Any, alpha: Any, shift: Any,
                              v: wp.array(dtype=Any)):  # fmt: skip
    """v ← v + shift (-γ² M̃⁻¹Kc^n - α v): the half-step velocity moved from t_n - dt₀/2 to
    t_n - dt₁/2 when the step changes from dt₀ to dt₁ (shift = (dt₀ - dt₁)/2)."""
    i = wp.tid()
    v[i] = v[i] + shift * (-gamma2 * acceleration[i] - alpha * v[i])


@wp.func
def fhn_reaction(c: Any, nu: Any):
    """c (1 - c)(c - ν) (docs/theory/chemistry.md, evaluated on control values)."""
    return c * (type(c)(1.0) - c) * (c - nu)


@wp.kernel
def fhn_explicit_kernel(
    acceleration: wp.array(dtype=Any), mass: wp.array(dtype=Any), gamma2: Any, nu: Any, kappa: Any, epsilon: Any,
    dt: Any, c: wp.array(dtype=Any), w: wp.array(dtype=Any), produced: wp.array(dtype=Any),
):  # fmt: skip
    """Explicit Euler: c += dt (-γ² M̃⁻¹Kc + f(c) - w);  w += dt ε (c - κ w), both from step n.
    `produced` gains the amount the reaction adds, dt M (f(c) - w) (diffusion adds none: 1ᵀK = 0)."""
    i = wp.tid()
    ci = c[i]
    wi = w[i]
    reaction = fhn_reaction(ci, nu) - wi
    c[i] = ci + dt * (reaction - gamma2 * acceleration[i])
    w[i] = wi + dt * epsilon * (ci - kappa * wi)
    produced[i] = produced[i] + dt * mass[i] * reaction


@wp.kernel
def fhn_heun_predictor_kernel(
    acceleration: wp.array(dtype=Any), mass: wp.array(dtype=Any), gamma2: Any, nu: Any, kappa: Any, epsilon: Any,
    dt: Any, c: wp.array(dtype=Any), w: wp.array(dtype=Any), c_stage: wp.array(dtype=Any),
    w_stage: wp.array(dtype=Any), rate_c: wp.array(dtype=Any), rate_w: wp.array(dtype=Any),
    produced: wp.array(dtype=Any),
):
    """Heun's first stage: the rates at step n (as `fhn_explicit_kernel`) and the Euler predictor c̃ = c + dt ċ,
    w̃ = w + dt ẇ; `produced` gains half the step's Euler amount, dt/2 M (f(c) - w)."""
    i = wp.tid()
    ci = c[i]
    wi = w[i]
    reaction = fhn_reaction(ci, nu) - wi
    rc = reaction - gamma2 * acceleration[i]
    rw = epsilon * (ci - kappa * wi)
    rate_c[i] = rc
    rate_w[i] = rw
    c_stage[i] = ci + dt * rc
    w_stage[i] = wi + dt * rw
    produced[i] = produced[i] + type(dt)(0.5) * dt * mass[i] * reaction


@wp.kernel
def fhn_heun_corrector_kernel(
    acceleration: wp.array(dtype=Any), mass: wp.array(dtype=Any), gamma2: Any, nu: Any, kappa: Any, epsilon: Any,
    dt: Any, c_stage: wp.array(dtype=Any), w_stage: wp.array(dtype=Any), rate_c: wp.array(dtype=Any),
    rate_w: wp.array(dtype=Any), c: wp.array(dtype=Any), w: wp.array(dtype=Any), produced: wp.array(dtype=Any),
):
    """Heun's second stage: c += dt/2 (ċ(n) + ċ(c̃, w̃)), w likewise (`acceleration` = M̃⁻¹K c̃); `produced` gains
    dt/2 M (f(c̃) - w̃)."""
    i = wp.tid()
    half = type(dt)(0.5) * dt
    cs = c_stage[i]
    ws = w_stage[i]
    reaction = fhn_reaction(cs, nu) - ws
    c[i] = c[i] + half * (rate_c[i] + reaction - gamma2 * acceleration[i])
    w[i] = w[i] + half * (rate_w[i] + epsilon * (cs - kappa * ws))
    produced[i] = produced[i] + half * mass[i] * reaction


@wp.kernel
def fhn_imex_rhs_kernel(c: wp.array(dtype=Any), w: wp.array(dtype=Any), mass: wp.array(dtype=Any), nu: Any, dt: Any,
                        rhs: wp.array(dtype=Any), produced: wp.array(dtype=Any)):  # fmt: skip
    """Right-hand side of (M + dt γ² K) c^{n+1} = M (c^n + dt (f(c^n) - w^n)); `produced` gains dt M (f - w)."""
    i = wp.tid()
    ci = c[i]
    source = dt * mass[i] * (fhn_reaction(ci, nu) - w[i])
    rhs[i] = mass[i] * ci + source
    produced[i] = produced[i] + source


@wp.kernel
def fhn_inhibitor_kernel(c: wp.array(dtype=Any), epsilon: Any, kappa: Any, dt: Any, w: wp.array(dtype=Any)):
    """Implicit in w: w^{n+1} = (w^n + dt ε c^{n+1}) / (1 + dt ε κ) (unconditionally stable)."""
    i = wp.tid()
    w[i] = (w[i] + dt * epsilon * c[i]) / (type(dt)(1.0) + dt * epsilon * kappa)


@wp.kernel
def transport_kernel(old_mass: wp.array(dtype=Any), mass: wp.array(dtype=Any), values: wp.array(dtype=Any)):
    """Conservative transport across a surface move: each vertex keeps its amount M_I c_I, so
    c_I ← c_I M_I(old) / M_I(new) (an amount per unit current area; docs/theory/chemistry.md, docs/theory/chemistry.md)."""
    i = wp.tid()
    values[i] = values[i] * (old_mass[i] / mass[i])


@wp.kernel
def first_crossing_kernel(c: wp.array(dtype=Any), level: Any, step: wp.array(dtype=wp.int32),
                          first_step: wp.array(dtype=wp.int32)):  # fmt: skip
    """first_step[i] = step[0] at the first step where c_i reaches `level` (-1 until then): the
    first front's arrival at each vertex, recorded inside the captured steps."""
    i = wp.tid()
    if first_step[i] < 0 and c[i] >= level:
        first_step[i] = step[0]


@wp.kernel
def count_step_kernel(step: wp.array(dtype=wp.int32)):
    step[0] = step[0] + 1


@wp.kernel
def runaway_kernel(values: wp.array(dtype=Any), limit: Any, flag: wp.array(dtype=wp.int32)):
    """flag[w] = RUNAWAY where |value| > limit or value is NaN/Inf in world w (one flag per world; NaN
    fails every comparison)."""
    i = wp.tid()
    if not (wp.abs(values[i]) <= limit):
        flag[i // (values.shape[0] // flag.shape[0])] = RUNAWAY


@wp.kernel
def flip_kernel(
    c: wp.array(dtype=Any), floor: Any, hold: Any, steps: int,
    previous: wp.array(dtype=Any), increment: wp.array(dtype=Any), earlier: wp.array(dtype=Any),
    streak: wp.array(dtype=wp.int32), flag: wp.array(dtype=wp.int32),
):  # fmt: skip
    """Period-2 flip-flop detector, after each step (docs/theory/scenes.md): d = c^{n+1} - c^n counts when it
    flips sign against d^n, |d| > floor (not round-off) and |d| >= hold |d^{n-1}| (not a decaying
    transient); `steps` counts in a row set the world's flag = FLIP_FLOP. Keeps c^{n+1}, d, d^n for the next step."""
    i = wp.tid()
    ci = c[i]
    d = ci - previous[i]
    last = increment[i]
    flipped = d * last < type(d)(0.0) and wp.abs(d) > floor and wp.abs(d) >= hold * wp.abs(earlier[i])
    count = wp.where(flipped, streak[i] + 1, 0)
    if count >= steps:
        flag[i // (c.shape[0] // flag.shape[0])] = FLIP_FLOP
    streak[i] = count
    previous[i] = ci
    earlier[i] = last
    increment[i] = d


# ---------------------------------------------------------------- linear algebra on the device


@wp.kernel
def shifted_operator_kernel(x: wp.array(dtype=Any), Kx: wp.array(dtype=Any), mass: wp.array(dtype=Any), shift: Any, out: wp.array(dtype=Any)):
    """out = (M + shift K) x, with Kx = K x given."""
    i = wp.tid()
    out[i] = mass[i] * x[i] + shift * Kx[i]


@wp.kernel
def inverse_diagonal_kernel(mass: wp.array(dtype=Any), K_diagonal: wp.array(dtype=Any), shift: Any, out: wp.array(dtype=Any)):
    """Jacobi preconditioner: out = 1 / (M + shift diag K)."""
    i = wp.tid()
    out[i] = type(shift)(1.0) / (mass[i] + shift * K_diagonal[i])


@wp.kernel
def cg_start_kernel(b: wp.array(dtype=Any), Ax: wp.array(dtype=Any), inverse_diagonal: wp.array(dtype=Any),
                    r: wp.array(dtype=Any), z: wp.array(dtype=Any), p: wp.array(dtype=Any)):  # fmt: skip
    """r = b - A x, z = P r, p = z."""
    i = wp.tid()
    ri = b[i] - Ax[i]
    zi = inverse_diagonal[i] * ri
    r[i] = ri
    z[i] = zi
    p[i] = zi


@wp.kernel
def cg_step_kernel(p: wp.array(dtype=Any), Ap: wp.array(dtype=Any), inverse_diagonal: wp.array(dtype=Any),
                   rz: wp.array(dtype=Any), pAp: wp.array(dtype=Any),
                   x: wp.array(dtype=Any), r: wp.array(dtype=Any), z: wp.array(dtype=Any)):  # fmt: skip
    """x += α p, r -= α A p, z = P r with α = r·z / p·Ap."""
    i = wp.tid()
    alpha = rz[0] / pAp[0]
    x[i] = x[i] + alpha * p[i]
    ri = r[i] - alpha * Ap[i]
    r[i] = ri
    z[i] = inverse_diagonal[i] * ri


@wp.kernel
def cg_direction_kernel(z: wp.array(dtype=Any), rz: wp.array(dtype=Any), rz_new: wp.array(dtype=Any), p: wp.array(dtype=Any)):
    """p = z + (r·z_new / r·z_old) p."""
    i = wp.tid()
    p[i] = z[i] + (rz_new[0] / rz[0]) * p[i]


@wp.kernel
def cg_condition_kernel(rz_new: wp.array(dtype=Any), rz: wp.array(dtype=Any), rz_stop: wp.array(dtype=Any),
                        iteration: wp.array(dtype=wp.int32), max_iterations: int, condition: wp.array(dtype=wp.int32)):  # fmt: skip
    """Go on while r·P r > tol² b·P b and iterations remain; rz ← rz_new for the next step."""
    iteration[0] = iteration[0] + 1
    rz[0] = rz_new[0]
    condition[0] = wp.where(rz_new[0] > rz_stop[0] and iteration[0] < max_iterations, 1, 0)


@wp.kernel
def cg_stop_kernel(rz: wp.array(dtype=Any), bz: wp.array(dtype=Any), tol2: Any, rz_stop: wp.array(dtype=Any),
                   iteration: wp.array(dtype=wp.int32), condition: wp.array(dtype=wp.int32)):  # fmt: skip
    """Threshold tol² b·P b; the loop runs unless r·P r is already below it."""
    rz_stop[0] = tol2 * bz[0]
    iteration[0] = 0
    condition[0] = wp.where(rz[0] > rz_stop[0], 1, 0)


@wp.kernel
def cg_failed_kernel(rz: wp.array(dtype=Any), rz_stop: wp.array(dtype=Any), flag: wp.array(dtype=wp.int32)):
    if not (rz[0] <= rz_stop[0]):
        flag[0] = 1


_S = "scalar[]"
declare_overloads(telegraph_kernel, acceleration=_S, gamma2="scalar", damping="scalar", dt="scalar", c=_S, v=_S)
declare_overloads(fhn_explicit_kernel, acceleration=_S, mass=_S, gamma2="scalar", nu="scalar", kappa="scalar",
                  epsilon="scalar", dt="scalar", c=_S, w=_S, produced=_S)  # fmt: skip
declare_overloads(fhn_heun_predictor_kernel, acceleration=_S, mass=_S, gamma2="scalar", nu="scalar", kappa="scalar",
                  epsilon="scalar", dt="scalar", c=_S, w=_S, c_stage=_S, w_stage=_S, rate_c=_S, rate_w=_S, produced=_S)
declare_overloads(fhn_heun_corrector_kernel, acceleration=_S, mass=_S, gamma2="scalar", nu="scalar", kappa="scalar",
                  epsilon="scalar", dt="scalar", c_stage=_S, w_stage=_S, rate_c=_S, rate_w=_S, c=_S, w=_S, produced=_S)
declare_overloads(fhn_imex_rhs_kernel, c=_S, w=_S, mass=_S, nu="scalar", dt="scalar", rhs=_S, produced=_S)
declare_overloads(transport_kernel, old_mass=_S, mass=_S, values=_S)
declare_overloads(first_crossing_kernel, c=_S, level="scalar")
declare_overloads(fhn_inhibitor_kernel, c=_S, epsilon="scalar", kappa="scalar", dt="scalar", w=_S)
declare_overloads(runaway_kernel, values=_S, limit="scalar")
declare_overloads(flip_kernel, c=_S, floor="scalar", hold="scalar", previous=_S, increment=_S, earlier=_S)
declare_overloads(shifted_operator_kernel, x=_S, Kx=_S, mass=_S, shift="scalar", out=_S)
declare_overloads(inverse_diagonal_kernel, mass=_S, K_diagonal=_S, shift="scalar", out=_S)
declare_overloads(cg_start_kernel, b=_S, Ax=_S, inverse_diagonal=_S, r=_S, z=_S, p=_S)
declare_overloads(cg_step_kernel, p=_S, Ap=_S, inverse_diagonal=_S, rz=_S, pAp=_S, x=_S, r=_S, z=_S)
declare_overloads(cg_direction_kernel, z=_S, rz=_S, rz_new=_S, p=_S)
declare_overloads(cg_condition_kernel, rz_new=_S, rz=_S, rz_stop=_S)
declare_overloads(cg_stop_kernel, rz=_S, bz=_S, tol2="scalar", rz_stop=_S)
declare_overloads(cg_failed_kernel, rz=_S, rz_stop=_S)
declare_overloads(telegraph_recentre_kernel, acceleration="scalar[]", gamma2="scalar", alpha="scalar", shift="scalar",
                  v="scalar[]")  # fmt: skip


# ---------------------------------------------------------------- launchers


@one_device
def eval_telegraph(acceleration: wp.array, gamma: float, alpha: float, dt: float, c: wp.array, v: wp.array) -> None:
    """One leapfrog step with centred damping (`telegraph_kernel`)."""
    s = scalar_of(c)
    wp.launch(telegraph_kernel, dim=len(c), inputs=[acceleration, s(gamma**2), s(0.5 * alpha * dt), s(dt)],
              outputs=[c, v], device=c.device)  # fmt: skip


@one_device
def eval_telegraph_recentre(acceleration: wp.array, gamma: float, alpha: float, old: float, new: float, v: wp.array):
    """The half-step velocity moved from t_n - old/2 to t_n - new/2 (`telegraph_recentre_kernel`)."""
    s = scalar_of(v)
    wp.launch(telegraph_recentre_kernel, dim=len(v), inputs=[acceleration, s(gamma**2), s(alpha), s(0.5 * (old - new))],
              outputs=[v], device=v.device)  # fmt: skip


@one_device
def eval_fhn_explicit(acceleration, mass, gamma: float, nu: float, kappa: float, epsilon: float, dt: float, c, w,
                      produced) -> None:  # fmt: skip
    """One explicit FitzHugh–Nagumo step (`fhn_explicit_kernel`)."""
    s = scalar_of(c)
    wp.launch(fhn_explicit_kernel, dim=len(c),
              inputs=[acceleration, mass, s(gamma**2), s(nu), s(kappa), s(epsilon), s(dt)], outputs=[c, w, produced],
              device=c.device)  # fmt: skip


@one_device
def eval_fhn_heun_predictor(acceleration, mass, gamma: float, nu: float, kappa: float, epsilon: float, dt: float, c, w,
                            c_stage, w_stage, rate_c, rate_w, produced) -> None:
    """Heun's first stage of a FitzHugh–Nagumo step (`fhn_heun_predictor_kernel`)."""
    s = scalar_of(c)
    wp.launch(fhn_heun_predictor_kernel, dim=len(c),
              inputs=[acceleration, mass, s(gamma**2), s(nu), s(kappa), s(epsilon), s(dt), c, w],
              outputs=[c_stage, w_stage, rate_c, rate_w, produced], device=c.device)


@one_device
def eval_fhn_heun_corrector(acceleration, mass, gamma: float, nu: float, kappa: float, epsilon: float, dt: float,
                            c_stage, w_stage, rate_c, rate_w, c, w, produced) -> None:
    """Heun's second stage of a FitzHugh–Nagumo step (`fhn_heun_corrector_kernel`)."""
    s = scalar_of(c)
    wp.launch(fhn_heun_corrector_kernel, dim=len(c),
              inputs=[acceleration, mass, s(gamma**2), s(nu), s(kappa), s(epsilon), s(dt), c_stage, w_stage, rate_c,
                      rate_w],
              outputs=[c, w, produced], device=c.device)


@one_device
def eval_fhn_imex_rhs(c, w, mass, nu: float, dt: float, rhs, produced) -> None:
    """The IMEX step's right-hand side M (c + dt (f(c) - w)) (`fhn_imex_rhs_kernel`)."""
    s = scalar_of(c)
    wp.launch(fhn_imex_rhs_kernel, dim=len(c), inputs=[c, w, mass, s(nu), s(dt)], outputs=[rhs, produced], device=c.device)


@one_device
def eval_fhn_inhibitor(c, epsilon: float, kappa: float, dt: float, w) -> None:
    """The inhibitor implicit in w (`fhn_inhibitor_kernel`)."""
    s = scalar_of(c)
    wp.launch(fhn_inhibitor_kernel, dim=len(c), inputs=[c, s(epsilon), s(kappa), s(dt)], outputs=[w], device=c.device)


@one_device
def eval_flip(c, floor: float, hold: float, steps: int, previous, increment, earlier, streak, flag) -> None:
    """The period-2 flip-flop detector after a step (`flip_kernel`)."""
    s = scalar_of(c)
    wp.launch(flip_kernel, dim=len(c), inputs=[c, s(floor), s(hold), steps],
              outputs=[previous, increment, earlier, streak, flag], device=c.device)  # fmt: skip


@one_device
def eval_transport(old_mass, mass, values) -> None:
    """Conservative transport of one array of amounts per unit area across a surface move (`transport_kernel`)."""
    wp.launch(transport_kernel, dim=len(values), inputs=[old_mass, mass], outputs=[values], device=values.device)


@one_device
def eval_runaway(values, limit: float, flag) -> None:
    """flag = RUNAWAY where |value| > limit or a value is NaN/Inf (`runaway_kernel`)."""
    wp.launch(runaway_kernel, dim=len(values), inputs=[values, scalar_of(values)(limit)], outputs=[flag],
              device=values.device)  # fmt: skip
