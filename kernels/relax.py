"""Kernels of the device-resident nonlinear conjugate-gradient relaxation (docs/theory/shell.md).

One loop pass evaluates one trial point x + α d; `line_search_kernel` decides from it (accept,
or a new step length), and the CG update runs only after an accepted step (`flags[ACCEPTED]`).
Scalar state lives in `search` (float64) and `flags` (int32), so the whole relaxation is one
`wp.capture_while` loop with no host round-trip.
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
    """s = P F, d = s; sums[FS_SUM] += F·s, largest = max |F| (both zeroed by the caller)."""
    i = wp.tid()
    f = forces[i]
    si = inverse_stiffness[i] * f
    s[i] = si
    direction[i] = si
    wp.atomic_add(sums, FS_SUM, wp.dot(f, si))
    wp.atomic_max(largest, 0, wp.length(f))


@wp.kernel
def start_search_kernel(energy: wp.array(dtype=wp.float64), sums: wp.array(dtype=Any), largest: wp.array(dtype=Any),
                        search: wp.array(dtype=wp.float64),
                        flags: wp.array(dtype=wp.int32), history: wp.array(dtype=wp.float64),
                        condition: wp.array(dtype=wp.int32)):  # fmt: skip
    """First step length 1 along d = s; stop at once if x is already in equilibrium."""
    fs = wp.float64(sums[FS_SUM])
    search[ENERGY] = energy[0]
    search[FS] = fs
    search[SLOPE] = -fs
    search[ALPHA] = wp.float64(1.0)
    search[CANDIDATE] = wp.float64(1.0)
    search[RESIDUAL] = wp.float64(largest[0]) / search[FORCE_SCALE]
    search[BEST_RESIDUAL] = search[RESIDUAL]
    flags[PROBING] = 1
    flags[STALLED] = 0
    flags[TRIES] = 0
    flags[ITERATION] = 0
    flags[RESTART] = 0
    flags[MOVED] = 0
    history[0] = energy[0]
    converged = search[RESIDUAL] <= search[TOL]
    flags[STATUS] = wp.where(converged, CONVERGED, RUNNING)
    condition[0] = wp.where(converged, 0, 1)


@wp.kernel
def trial_kernel(x: wp.array(dtype=Any), direction: wp.array(dtype=Any), search: wp.array(dtype=wp.float64),
                 trial: wp.array(dtype=Any), dot: wp.array(dtype=Any), flags: wp.array(dtype=wp.int32)):  # fmt: skip
    """trial = x + α d at the candidate α; flags[MOVED] = 1 unless x + α d rounds to x everywhere
    (zeroed by the line search); zeroes the slope accumulator and the trial's skin flag."""
    i = wp.tid()
    if i == 0:
        dot[0] = type(dot[0])(0.0)
        flags[OUTSIDE_SKIN] = 0
    xi = x[i]
    ti = xi + type(xi[0])(search[CANDIDATE]) * direction[i]
    trial[i] = ti
    if ti[0] != xi[0] or ti[1] != xi[1] or ti[2] != xi[2]:
        flags[MOVED] = 1


@wp.kernel
def slope_kernel(forces: wp.array(dtype=Any), direction: wp.array(dtype=Any), dot: wp.array(dtype=Any)):
    """dot[0] += F(x + α d)·d = -dE/dα."""
    i = wp.tid()
    wp.atomic_add(dot, 0, wp.dot(forces[i], direction[i]))


@wp.kernel
def line_search_kernel(trial_energy: wp.array(dtype=wp.float64), dot: wp.array(dtype=Any),
                       search: wp.array(dtype=wp.float64), flags: wp.array(dtype=wp.int32),
                       condition: wp.array(dtype=wp.int32)):  # fmt: skip
    """Decide on the trial point (docs/theory/shell.md#relaxation).

    The probe at the previous step length gives a secant estimate of dE/dα = 0 (at most 4×); then
    backtracking by halves. Accept under Armijo's condition, or, where the energy change is below
    round-off (float32 near equilibrium), when E stays within round-off and the slope flattens or
    still descends (negative curvature near a buckling instability). A step that rounds to x is
    no step, and so is one that leaves the self-contact search's skin (flags[FAR_TRIAL]). After
    MAX_TRIES halvings the search has found no lower energy: the loop stops (NO_DESCENT, the
    dtype's round-off floor).
    """
    moved = flags[MOVED] == 1 and flags[FAR_TRIAL] == 0
    flags[MOVED] = 0
    flags[FAR_TRIAL] = 0
    e = trial_energy[0]
    slope_new = -wp.float64(dot[0])
    e0 = search[ENERGY]
    slope = search[SLOPE]
    candidate = search[CANDIDATE]
    flags[ACCEPTED] = 0
    flags[RESTART] = 0
    if flags[PROBING] == 1:
        flags[PROBING] = 0
        flags[TRIES] = 0
        secant = wp.float64(4.0) * candidate
        if slope_new > slope:
            secant = wp.min(candidate * slope / (slope - slope_new), secant)
        if secant != candidate:
            search[CANDIDATE] = secant
            return
    tolerance = search[NOISE] * wp.max(wp.abs(e0), wp.float64(1e-300))
    armijo = e <= e0 + wp.float64(ARMIJO) * candidate * slope
    flat = e <= e0 + tolerance and (wp.abs(slope_new) < wp.abs(slope) or slope_new <= wp.float64(0.0))
    if moved and (armijo or flat):
        flags[ACCEPTED] = 1
        search[ENERGY] = e
        search[ALPHA] = candidate
        return
    flags[TRIES] = flags[TRIES] + 1
    if flags[TRIES] >= MAX_TRIES:
        flags[STATUS] = NO_DESCENT
        condition[0] = 0
        return
    search[CANDIDATE] = wp.float64(0.5) * candidate


@wp.kernel
def accept_kernel(flags: wp.array(dtype=wp.int32), trial: wp.array(dtype=Any), trial_forces: wp.array(dtype=Any),
                  inverse_stiffness: wp.array(dtype=Any), x: wp.array(dtype=Any), forces: wp.array(dtype=Any),
                  s: wp.array(dtype=Any), s_old: wp.array(dtype=Any), sums: wp.array(dtype=Any),
                  largest: wp.array(dtype=Any)):  # fmt: skip
    """After an accepted step: x, F ← the trial's; s_old ← s; s = P F;
    sums += [F·s, F·(s − s_old), -], largest = max |F| (both zeroed by the caller)."""
    if flags[ACCEPTED] == 0:
        return
    i = wp.tid()
    f = trial_forces[i]
    x[i] = trial[i]
    forces[i] = f
    previous = s[i]
    si = inverse_stiffness[i] * f
    s_old[i] = previous
    s[i] = si
    wp.atomic_add(sums, FS_SUM, wp.dot(f, si))
    wp.atomic_add(sums, FDS_SUM, wp.dot(f, si - previous))
    wp.atomic_max(largest, 0, wp.length(f))


@wp.kernel
def beta_kernel(flags: wp.array(dtype=wp.int32), sums: wp.array(dtype=Any), search: wp.array(dtype=wp.float64)):
    """Polak–Ribière+: β = max(0, F·(s − s_old) / F_old·s_old)."""
    if flags[ACCEPTED] == 0:
        return
    fs_old = search[FS]
    beta = wp.float64(0.0)
    if fs_old > wp.float64(0.0):
        beta = wp.max(wp.float64(0.0), wp.float64(sums[FDS_SUM]) / fs_old)
    search[BETA] = beta
    search[FS] = wp.float64(sums[FS_SUM])


@wp.kernel
def direction_kernel(flags: wp.array(dtype=wp.int32), s: wp.array(dtype=Any), forces: wp.array(dtype=Any),
                     search: wp.array(dtype=wp.float64), direction: wp.array(dtype=Any), sums: wp.array(dtype=Any)):  # fmt: skip
    """d = s + β d; sums[FD_SUM] += F·d (zeroed by the caller)."""
    if flags[ACCEPTED] == 0:
        return
    i = wp.tid()
    si = s[i]
    d = si + type(si[0])(search[BETA]) * direction[i]
    direction[i] = d
    wp.atomic_add(sums, FD_SUM, wp.dot(forces[i], d))


@wp.kernel
def iteration_kernel(flags: wp.array(dtype=wp.int32), sums: wp.array(dtype=Any), largest: wp.array(dtype=Any),
                     search: wp.array(dtype=wp.float64),
                     history: wp.array(dtype=wp.float64), condition: wp.array(dtype=wp.int32)):  # fmt: skip
    """Close an accepted iteration: restart along s if d does not descend; record E; stop when
    max |F| ≤ tol · Y h ℓ̄, when the iteration budget is spent, or when MAX_STALLED steps in a
    row lowered neither E nor max |F| (steps within round-off that go nowhere: NO_DESCENT), or
    when x has left a quarter of the self-contact search's skin (STALE). The next probe is at the last α."""
    if flags[ACCEPTED] == 0:
        return
    fd = wp.float64(sums[FD_SUM])
    if fd <= wp.float64(0.0):
        flags[RESTART] = 1
        fd = search[FS]  # d = s: F·d = F·s
    iteration = flags[ITERATION] + 1
    flags[ITERATION] = iteration
    history[iteration] = search[ENERGY]
    search[SLOPE] = -fd
    search[CANDIDATE] = search[ALPHA]
    flags[PROBING] = 1
    residual = wp.float64(largest[0]) / search[FORCE_SCALE]
    search[RESIDUAL] = residual
    if search[ENERGY] < history[iteration - 1] or residual < search[BEST_RESIDUAL]:
        flags[STALLED] = 0
    else:
        flags[STALLED] = flags[STALLED] + 1
    search[BEST_RESIDUAL] = wp.min(search[BEST_RESIDUAL], residual)
    if residual <= search[TOL]:
        flags[STATUS] = CONVERGED
        condition[0] = 0
    elif wp.float64(iteration) >= search[MAX_ITERATIONS]:
        flags[STATUS] = BUDGET_SPENT
        condition[0] = 0
    elif flags[STALLED] >= MAX_STALLED:
        flags[STATUS] = NO_DESCENT
        condition[0] = 0
    elif flags[OUTSIDE_SKIN] == 1:
        flags[STATUS] = STALE
        condition[0] = 0


@wp.kernel
def resume_kernel(flags: wp.array(dtype=wp.int32), condition: wp.array(dtype=wp.int32)):
    """Go on after a STALE stop (a new self-contact search): the CG state is kept, since the old
    candidates already held every pair within the contact distance."""
    flags[STATUS] = RUNNING
    condition[0] = 1


@wp.kernel
def restart_kernel(flags: wp.array(dtype=wp.int32), s: wp.array(dtype=Any), direction: wp.array(dtype=Any)):
    """d = s where the conjugate direction does not descend."""
    if flags[ACCEPTED] == 0 or flags[RESTART] == 0:
        return
    i = wp.tid()
    direction[i] = s[i]


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
