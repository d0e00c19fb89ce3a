"""Kernels of the device-resident nonlinear conjugate-gradient relaxation (docs/theory/shell.md).

One loop pass evaluates one trial point x + α d; `line_search_kernel` decides from it (accept,
or a new step length), and the CG update runs only after an accepted step (`flags[ACCEPTED]`).
Scalar state lives in `search` (float64) and `flags` (int32), so the whole relaxation is one
`wp.capture_while` loop with no host round-trip.

Batched worlds (`Mesh.union`): every world has its own line search and convergence — `search`,
`flags`, `sums` hold one block per world (SEARCH_SIZE, FLAGS_SIZE, 3 entries), `largest`, `dot`
and the energies one entry per world, `history` one column block per world; a vertex's world is
its index // (vertices / worlds). A world that stopped is left alone; `continue_kernel` keeps the
loop going while any world runs.
"""

from typing import Any

import warp as wp

from . import declare_overloads

# search[...] (float64)
ENERGY, ALPHA, CANDIDATE, SLOPE, FS, BETA, RESIDUAL, BEST_RESIDUAL, TOL, MAX_ITERATIONS, FORCE_SCALE, NOISE = range(12)
SEARCH_SIZE = 12
# flags[...] (int32)
ACCEPTED, PROBING, TRIES, ITERATION, STATUS, RESTART, MOVED, STALLED, FAR_TRIAL, OUTSIDE_SKIN = range(10)
FLAGS_SIZE = 10
# flags[STATUS]; STALE: x left a quarter of the self-contact search's skin, the caller searches again and goes on
RUNNING, CONVERGED, BUDGET_SPENT, NO_DESCENT, STALE = range(5)
# sums[...] (the shell's scalar): F·s, F·(s − s_old), F·d; max |F| in an array of its own (`largest`:
# Warp's deterministic mode compiles atomic adds and maxima only on separate arrays)
FS_SUM, FDS_SUM, FD_SUM = range(3)

ARMIJO = 1e-4
MAX_TRIES = 40  # halvings of the step before the search gives up (round-off floor)
MAX_STALLED = 40  # accepted steps in a row that lower neither E nor max |F| (round-off floor)


@wp.kernel
def start_kernel(forces: wp.array(dtype=Any), inverse_stiffness: wp.array(dtype=Any), s: wp.array(dtype=Any),
                 direction: wp.array(dtype=Any), sums: wp.array(dtype=Any), largest: wp.array(dtype=Any)):  # fmt: skip
    """s = P F, d = s; sums[FS_SUM] += F·s, largest = max |F| in the vertex's world (both zeroed by the caller)."""
    i = wp.tid()
    w = i // (forces.shape[0] // largest.shape[0])
    f = forces[i]
    si = inverse_stiffness[i] * f
    s[i] = si
    direction[i] = si
    wp.atomic_add(sums, 3 * w + FS_SUM, wp.dot(f, si))
    wp.atomic_max(largest, w, wp.length(f))


@wp.kernel
def start_search_kernel(energy: wp.array(dtype=wp.float64), sums: wp.array(dtype=Any), largest: wp.array(dtype=Any),
                        search: wp.array(dtype=wp.float64),
                        flags: wp.array(dtype=wp.int32), history: wp.array(dtype=wp.float64)):  # fmt: skip
    """One thread per world: first step length 1 along d = s; the world stops at once if x is
    already in equilibrium, or (NO_DESCENT, residual infinite) if its energy is not finite (NaN
    positions: max |F| skips NaN and would read as converged)."""
    w = wp.tid()
    b, f = w * SEARCH_SIZE, w * FLAGS_SIZE
    fs = wp.float64(sums[3 * w + FS_SUM])
    search[b + ENERGY] = energy[w]
    search[b + FS] = fs
    search[b + SLOPE] = -fs
    search[b + ALPHA] = wp.float64(1.0)
    search[b + CANDIDATE] = wp.float64(1.0)
    search[b + RESIDUAL] = wp.float64(largest[w]) / search[b + FORCE_SCALE]
    search[b + BEST_RESIDUAL] = search[b + RESIDUAL]
    flags[f + PROBING] = 1
    flags[f + STALLED] = 0
    flags[f + TRIES] = 0
    flags[f + ITERATION] = 0
    flags[f + RESTART] = 0
    flags[f + MOVED] = 0
    history[w * (history.shape[0] // largest.shape[0])] = energy[w]
    converged = search[b + RESIDUAL] <= search[b + TOL]
    flags[f + STATUS] = wp.where(converged, CONVERGED, RUNNING)
    if not wp.isfinite(energy[w]):
        search[b + RESIDUAL] = wp.float64(wp.inf)
        flags[f + STATUS] = NO_DESCENT


@wp.kernel
def continue_kernel(flags: wp.array(dtype=wp.int32), condition: wp.array(dtype=wp.int32)):
    """Single thread: the loop goes on while some world runs."""
    running = int(0)
    for w in range(flags.shape[0] // FLAGS_SIZE):
        if flags[w * FLAGS_SIZE + STATUS] == RUNNING:
            running = 1
    condition[0] = running


@wp.kernel
def trial_kernel(x: wp.array(dtype=Any), direction: wp.array(dtype=Any), search: wp.array(dtype=wp.float64),
                 trial: wp.array(dtype=Any), dot: wp.array(dtype=Any), flags: wp.array(dtype=wp.int32)):  # fmt: skip
    """trial = x + α d at the world's candidate α; flags[MOVED] = 1 unless x + α d rounds to x
    everywhere in the world (zeroed by the line search); zeroes the world's slope accumulator and
    the trial's skin flag."""
    i = wp.tid()
    n = x.shape[0] // dot.shape[0]
    w = i // n
    if i == w * n:
        dot[w] = type(dot[0])(0.0)
        flags[w * FLAGS_SIZE + OUTSIDE_SKIN] = 0
    xi = x[i]
    ti = xi + type(xi[0])(search[w * SEARCH_SIZE + CANDIDATE]) * direction[i]
    trial[i] = ti
    if ti[0] != xi[0] or ti[1] != xi[1] or ti[2] != xi[2]:
        flags[w * FLAGS_SIZE + MOVED] = 1


@wp.kernel
def slope_kernel(forces: wp.array(dtype=Any), direction: wp.array(dtype=Any), dot: wp.array(dtype=Any)):
    """dot[w] += F(x + α d)·d = -dE/dα of the vertex's world w."""
    i = wp.tid()
    wp.atomic_add(dot, i // (forces.shape[0] // dot.shape[0]), wp.dot(forces[i], direction[i]))


@wp.kernel
def line_search_kernel(trial_energy: wp.array(dtype=wp.float64), dot: wp.array(dtype=Any),
                       search: wp.array(dtype=wp.float64), flags: wp.array(dtype=wp.int32)):  # fmt: skip
    """One thread per world: decide on its trial point (docs/theory/shell.md#relaxation).

    The probe at the previous step length gives a secant estimate of dE/dα = 0 (at most 4×); then
    backtracking by halves. Accept under Armijo's condition, or, where the energy change is below
    round-off (float32 near equilibrium), when E stays within round-off and the slope flattens or
    still descends (negative curvature near a buckling instability). A step that rounds to x is
    no step, and so is one that leaves the self-contact search's skin (flags[FAR_TRIAL]). After
    MAX_TRIES halvings the search has found no lower energy: the world stops (NO_DESCENT, the
    dtype's round-off floor). A world that stopped accepts nothing.
    """
    w = wp.tid()
    b, f = w * SEARCH_SIZE, w * FLAGS_SIZE
    flags[f + ACCEPTED] = 0
    if flags[f + STATUS] != RUNNING:
        return
    moved = flags[f + MOVED] == 1 and flags[f + FAR_TRIAL] == 0
    flags[f + MOVED] = 0
    flags[f + FAR_TRIAL] = 0
    e = trial_energy[w]
    slope_new = -wp.float64(dot[w])
    e0 = search[b + ENERGY]
    slope = search[b + SLOPE]
    candidate = search[b + CANDIDATE]
    flags[f + RESTART] = 0
    if flags[f + PROBING] == 1:
        flags[f + PROBING] = 0
        flags[f + TRIES] = 0
        secant = wp.float64(4.0) * candidate
        if slope_new > slope:
            secant = wp.min(candidate * slope / (slope - slope_new), secant)
        if secant != candidate:
            search[b + CANDIDATE] = secant
            return
    tolerance = search[b + NOISE] * wp.max(wp.abs(e0), wp.float64(1e-300))
    armijo = e <= e0 + wp.float64(ARMIJO) * candidate * slope
    flat = e <= e0 + tolerance and (wp.abs(slope_new) < wp.abs(slope) or slope_new <= wp.float64(0.0))
    if moved and (armijo or flat):
        flags[f + ACCEPTED] = 1
        search[b + ENERGY] = e
        search[b + ALPHA] = candidate
        return
    flags[f + TRIES] = flags[f + TRIES] + 1
    if flags[f + TRIES] >= MAX_TRIES:
        flags[f + STATUS] = NO_DESCENT
        return
    search[b + CANDIDATE] = wp.float64(0.5) * candidate


@wp.kernel
def accept_kernel(flags: wp.array(dtype=wp.int32), trial: wp.array(dtype=Any), trial_forces: wp.array(dtype=Any),
                  inverse_stiffness: wp.array(dtype=Any), x: wp.array(dtype=Any), forces: wp.array(dtype=Any),
                  s: wp.array(dtype=Any), s_old: wp.array(dtype=Any), sums: wp.array(dtype=Any),
                  largest: wp.array(dtype=Any)):  # fmt: skip
    """After an accepted step of the vertex's world w: x, F ← the trial's; s_old ← s; s = P F;
    sums[w] += [F·s, F·(s − s_old), -], largest[w] = max |F| (both zeroed by the caller)."""
    i = wp.tid()
    w = i // (x.shape[0] // largest.shape[0])
    if flags[w * FLAGS_SIZE + ACCEPTED] == 0:
        return
    f = trial_forces[i]
    x[i] = trial[i]
    forces[i] = f
    previous = s[i]
    si = inverse_stiffness[i] * f
    s_old[i] = previous
    s[i] = si
    wp.atomic_add(sums, 3 * w + FS_SUM, wp.dot(f, si))
    wp.atomic_add(sums, 3 * w + FDS_SUM, wp.dot(f, si - previous))
    wp.atomic_max(largest, w, wp.length(f))


@wp.kernel
def beta_kernel(flags: wp.array(dtype=wp.int32), sums: wp.array(dtype=Any), search: wp.array(dtype=wp.float64)):
    """One thread per world, Polak–Ribière+: β = max(0, F·(s − s_old) / F_old·s_old)."""
    w = wp.tid()
    b = w * SEARCH_SIZE
    if flags[w * FLAGS_SIZE + ACCEPTED] == 0:
        return
    fs_old = search[b + FS]
    beta = wp.float64(0.0)
    if fs_old > wp.float64(0.0):
        beta = wp.max(wp.float64(0.0), wp.float64(sums[3 * w + FDS_SUM]) / fs_old)
    search[b + BETA] = beta
    search[b + FS] = wp.float64(sums[3 * w + FS_SUM])


@wp.kernel
def direction_kernel(flags: wp.array(dtype=wp.int32), s: wp.array(dtype=Any), forces: wp.array(dtype=Any),
                     search: wp.array(dtype=wp.float64), direction: wp.array(dtype=Any), sums: wp.array(dtype=Any)):  # fmt: skip
    """d = s + β d; sums[FD_SUM] += F·d in the vertex's world (zeroed by the caller)."""
    i = wp.tid()
    w = i // (s.shape[0] // (flags.shape[0] // FLAGS_SIZE))
    if flags[w * FLAGS_SIZE + ACCEPTED] == 0:
        return
    si = s[i]
    d = si + type(si[0])(search[w * SEARCH_SIZE + BETA]) * direction[i]
    direction[i] = d
    wp.atomic_add(sums, 3 * w + FD_SUM, wp.dot(forces[i], d))


@wp.kernel
def iteration_kernel(flags: wp.array(dtype=wp.int32), sums: wp.array(dtype=Any), largest: wp.array(dtype=Any),
                     search: wp.array(dtype=wp.float64), history: wp.array(dtype=wp.float64)):  # fmt: skip
    """One thread per world: close an accepted iteration: restart along s if d does not descend; record E; stop when
    max |F| ≤ tol · Y h ℓ̄, when the iteration budget is spent, or when MAX_STALLED steps in a
    row lowered neither E nor max |F| (steps within round-off that go nowhere: NO_DESCENT), or
    when x has left a quarter of the self-contact search's skin (STALE). The next probe is at the last α."""
    w = wp.tid()
    b, f = w * SEARCH_SIZE, w * FLAGS_SIZE
    if flags[f + ACCEPTED] == 0:
        return
    fd = wp.float64(sums[3 * w + FD_SUM])
    if fd <= wp.float64(0.0):
        flags[f + RESTART] = 1
        fd = search[b + FS]  # d = s: F·d = F·s
    iteration = flags[f + ITERATION] + 1
    flags[f + ITERATION] = iteration
    row = w * (history.shape[0] // largest.shape[0]) + iteration
    history[row] = search[b + ENERGY]
    search[b + SLOPE] = -fd
    search[b + CANDIDATE] = search[b + ALPHA]
    flags[f + PROBING] = 1
    residual = wp.float64(largest[w]) / search[b + FORCE_SCALE]
    search[b + RESIDUAL] = residual
    if search[b + ENERGY] < history[row - 1] or residual < search[b + BEST_RESIDUAL]:
        flags[f + STALLED] = 0
    else:
        flags[f + STALLED] = flags[f + STALLED] + 1
    search[b + BEST_RESIDUAL] = wp.min(search[b + BEST_RESIDUAL], residual)
    if residual <= search[b + TOL]:
        flags[f + STATUS] = CONVERGED
    elif wp.float64(iteration) >= search[b + MAX_ITERATIONS]:
        flags[f + STATUS] = BUDGET_SPENT
    elif flags[f + STALLED] >= MAX_STALLED:
        flags[f + STATUS] = NO_DESCENT
    elif flags[f + OUTSIDE_SKIN] == 1:
        flags[f + STATUS] = STALE


@wp.kernel
def resume_kernel(flags: wp.array(dtype=wp.int32), condition: wp.array(dtype=wp.int32)):
    """Go on after a STALE stop (a new self-contact search; one world): the CG state is kept, since
    the old candidates already held every pair within the contact distance."""
    flags[STATUS] = RUNNING
    condition[0] = 1


@wp.kernel
def restart_kernel(flags: wp.array(dtype=wp.int32), s: wp.array(dtype=Any), direction: wp.array(dtype=Any)):
    """d = s where the conjugate direction does not descend."""
    i = wp.tid()
    f = (i // (s.shape[0] // (flags.shape[0] // FLAGS_SIZE))) * FLAGS_SIZE
    if flags[f + ACCEPTED] == 0 or flags[f + RESTART] == 0:
        return
    direction[i] = s[i]


@wp.kernel
def outcome_kernel(flags: wp.array(dtype=wp.int32), search: wp.array(dtype=wp.float64), slack: wp.float64,
                   failed: wp.array(dtype=wp.int32), counts: wp.array(dtype=wp.int32)):
    """One thread per world, after a relaxation embedded in a step: failed[w] = its status where it did not converge
    (BUDGET_SPENT, or NO_DESCENT above `slack` × tol: within it, the dtype's round-off floor is accepted); kept until
    the caller clears it; counts[2w] += its iterations, counts[2w + 1] += 1."""
    w = wp.tid()
    f, b = w * FLAGS_SIZE, w * SEARCH_SIZE
    status = flags[f + STATUS]
    floor = status == NO_DESCENT and search[b + RESIDUAL] <= slack * search[b + TOL]
    if status != CONVERGED and not floor:
        failed[w] = status
    counts[2 * w] = counts[2 * w] + flags[f + ITERATION]
    counts[2 * w + 1] = counts[2 * w + 1] + 1


_V, _S = "vec3[]", "scalar[]"
declare_overloads(start_kernel, forces=_V, inverse_stiffness=_S, s=_V, direction=_V, sums=_S, largest=_S)
declare_overloads(start_search_kernel, sums=_S, largest=_S)
declare_overloads(trial_kernel, x=_V, direction=_V, trial=_V, dot=_S)
declare_overloads(slope_kernel, forces=_V, direction=_V, dot=_S)
declare_overloads(line_search_kernel, dot=_S)
declare_overloads(accept_kernel, trial=_V, trial_forces=_V, inverse_stiffness=_S, x=_V, forces=_V, s=_V, s_old=_V,
                  sums=_S, largest=_S)  # fmt: skip
declare_overloads(beta_kernel, sums=_S)
declare_overloads(direction_kernel, s=_V, forces=_V, direction=_V, sums=_S)
declare_overloads(iteration_kernel, sums=_S, largest=_S)
declare_overloads(restart_kernel, s=_V, direction=_V)
