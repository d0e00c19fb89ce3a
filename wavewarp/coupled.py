"""Couplings (docs/theory/scenes.md): chemistry drives the shell, the shell steers the wave.

`QuasiStatic` (oocytes, wave guides, buckling) relaxes the shell after each chemistry step;
`Walking` (the walkers) advances inertial shell dynamics between chemistry steps. Both only
sequence public calls of the chemistry stepper (its solver and state), the shell and the
mechanics; the state they advance is `state` (x with the wave's c and c_t or w).

One `QuasiStatic.step()`:
1. the wave advances `chemistry_steps` steps on the device (its own stability guard);
2. the shell's active reference ā, b̄ follows the new control concentrations (device to device);
3. `relax` finds the new quasi-static equilibrium, warm-started from the last one (one captured
   device loop, positions device to device: wavewarp/relax.py);
4. deformation-sensitive runs move the wave to the new surface (`move_surface`: the chemical is
   carried by the material, conservatively by default), which makes the wave re-check its time
   step; the insensitive twin keeps the rest surface. The equilibrium at t = 0 only places the
   operator: the initial values are the concentrations on that surface.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from . import kernels
from .checks import count
from .drag import Drag
from .dynamics import ShellDynamics
from .kernels.dynamics import eval_reference_ramp
from .relax import NEWTON_STEPS, ROUND_OFF_SLACK, RelaxationError, checked_method, relax
from .runner import GuardedRunner, world_shares
from .shell import Shell
from .state import FIELDS, State
from .waves import BlowUpError, TimeStepError, _Stepper

COUPLINGS = ("quasi-static", "overdamped")  # the quasi-static scenes' mechanical update (docs/theory/transport.md)
GRAPH_SUBSTEPS = 256  # mechanics steps per captured graph of the walkers' coupled steps
# conservative transport: past this area ratio no equilibrium holds the chemical a contraction concentrates
FOLD_AREA_RATIO = math.exp(-1.0)


class FoldError(BlowUpError):
    """A conservative chemical contracted its shell past the fold (a vertex's area below 1/e of its rest value):
    no equilibrium holds the chemical the contraction concentrates (docs/theory/transport.md)."""


def _check_pair(shell: Shell, wave: _Stepper) -> None:
    if not isinstance(wave, _Stepper):
        raise ValueError(f"wave must be a Telegraph or FitzHughNagumo stepper, got {type(wave).__name__}")
    op = wave.operator
    if op.mesh is not shell.mesh and not np.array_equal(op.mesh.triangles, shell.mesh.triangles):
        raise ValueError("the shell and the wave's operator must share one mesh")
    if op.device != shell.device or op.scalar != shell.scalar:
        raise ValueError(f"the shell ({shell.device}, {shell.scalar.__name__}) and the wave ({op.device}, "
                         f"{op.scalar.__name__}) must share device and dtype")  # fmt: skip


class QuasiStatic:
    """Couple `wave` (a Telegraph or FitzHughNagumo on `wave.operator`) to `shell`.

    `sensitive=True`: the wave runs on the current (deformed) surface; False: on the rest
    surface (the deformation-insensitive twin). `tol`: the relaxation tolerance (Shell.relax).
    `accept_unconverged=True` accepts a relaxation that spends its `max_iterations` or whose line search
    finds no lower energy (a lagging shell: near a buckling instability the shell
    lags its reference instead of stopping the run); such steps are counted in `unconverged`.
    `method` and `max_iterations`, `newton_steps`: Shell.relax's ("auto": CG, then a Newton finish
    where CG spends its budget; counted in `newton_finishes`). The positions join the wave's state.

    `drag` ζ > 0 makes each step overdamped instead of quasi-static: the shell moves by a backward-Euler step
    of ζ ṗ = f over the step's interval (a `Drag` term in its relaxation, wavewarp/drag.py), relaxing towards
    equilibrium at a finite rate; ζ → 0 is the quasi-static coupling. The equilibrium at t = 0 has no drag.

    Batched worlds (`Mesh.union`): every world relaxes in the same launches (nonlinear CG, one line
    search and convergence test per world). A world whose wave blows up, whose surface lowers the
    stability bound below the fixed dt, or whose relaxation fails is stopped alone: `stopped` maps it
    to its error, `frozen(w)` holds its state at the start of the step it failed in, and its share of
    the live state is parked at rest (x the rest shape, no chemical: it stays put at no cost and
    cannot lower the bound); the step is then taken again for the others. The run raises only once
    every world has stopped.
    """

    TALLIES = ("relaxations", "relax_iterations", "unconverged_relaxations", "newton_finishes", "round_off_relaxations")

    def __init__(self, shell: Shell, wave: _Stepper, *, sensitive: bool = True, chemistry_steps: int = 1, tol=None,
                 x0=None, max_iterations: int = 20000, accept_unconverged: bool = False, method: str = "auto",
                 newton_steps: int = NEWTON_STEPS, drag: float = 0.0):  # fmt: skip
        if not isinstance(shell, Shell):
            raise ValueError(f"shell must be a wavewarp.Shell, got {type(shell).__name__}")
        _check_pair(shell, wave)
        self.shell, self.wave, self.operator = shell, wave, wave.operator
        self.sensitive = bool(sensitive)
        self.chemistry_steps = count("chemistry_steps", chemistry_steps, 1)
        if tol is None:
            tol = 1e-5 if shell.scalar == wp.float32 else 1e-9
        self.tol = float(tol)
        self.max_iterations = count("max_iterations", max_iterations, 1)
        self.method, self.newton_steps = checked_method(method), count("newton_steps", newton_steps, 1)
        self.accept_unconverged = bool(accept_unconverged)
        self.worlds = shell.worlds
        self.tallies = {name: np.zeros(self.worlds, dtype=np.int64) for name in self.TALLIES}
        self.relax_iterations = []  # CG iterations per relaxation (one world; a batch: an array per relaxation)
        self.stopped = {}  # batched worlds: world -> the error that stopped it
        self._frozen = {}  # world -> its state arrays' share at the start of the step it failed in
        self._step_start = None  # batched worlds: the state at the start of the current step
        self.rest_mass = self.operator.mass()  # the fold's reference (the operator is on the rest surface here)
        x0 = shell.mesh.vertices if x0 is None else np.asarray(x0, dtype=np.float64)
        wave.state.x = wp.array(x0.astype(shell._real), dtype=shell.vec3, device=shell.device)
        self.drag = None
        self._equilibrate(initial=True, start=self._start_of_step())  # quasi-static (with its Newton finish)
        if np.any(drag):  # one ζ, or one per batched world: the steps after it are overdamped
            self.drag = Drag(shell, drag=drag)
            shell.terms = (*shell.terms, self.drag)

    state = property(lambda self: self.wave.state)
    time = property(lambda self: self.wave.time)
    unconverged = property(lambda self: int(self.tallies["unconverged_relaxations"][0]))
    newton_finishes = property(lambda self: int(self.tallies["newton_finishes"][0]))
    round_off_stops = property(lambda self: int(self.tallies["round_off_relaxations"][0]))

    def positions(self) -> np.ndarray:
        """(V, 3) control positions of the current equilibrium."""
        return self.state.numpy("x")

    def _start_of_step(self):
        """Batched worlds: copies of the state arrays (allocated once), where a world that fails in this
        step stops."""
        if self.worlds == 1:
            return None
        arrays = self.state.arrays()
        if self._step_start is None or [c.shape for c in self._step_start] != [a.shape for a in arrays]:
            self._step_start = [wp.empty_like(a) for a in arrays]
        for copy, array in zip(self._step_start, arrays):
            wp.copy(copy, array)
        return self._step_start

    def _equilibrate(self, initial: bool = False, start=None) -> None:
        x, shell = self.state.x, self.shell
        shell.update_reference(self.state.c)
        if self.drag is not None:
            self.drag.set_interval(self.chemistry_steps * self.wave.dt)
        for term in shell.terms:  # a load step starts where the last equilibrium left the shell (RestingGround)
            term.begin_step(x)
        running = np.array([w not in self.stopped for w in range(self.worlds)])
        failed = []
        try:
            relax(shell, x, self.tol, self.max_iterations, out=x, method=self.method,
                  newton_steps=self.newton_steps)  # device to device
        except RelaxationError as error:
            for w, (residual, round_off) in error.failures.items():
                finite = math.isfinite(residual)  # not finite positions: no lag accepts them
                if finite and round_off and residual <= ROUND_OFF_SLACK * self.tol:
                    self.tallies["round_off_relaxations"][w] += 1  # the dtype's floor just above tol (float32)
                elif finite and self.accept_unconverged:
                    # the shell lags its reference (budget spent, or no lower energy found at a
                    # sharp fold); the next step goes on from here
                    self.tallies["unconverged_relaxations"][w] += 1
                elif self.worlds == 1:
                    raise
                else:
                    failed.append(w)
            x.assign(error.x.astype(shell._real))
            relaxation_error = error
        histories = shell.relax_history if self.worlds > 1 else [shell.relax_history]
        iterations = np.array([len(history) - 1 for history in histories])
        self.relax_iterations.append(iterations if self.worlds > 1 else int(iterations[0]))
        self.tallies["relaxations"] += running
        self.tallies["relax_iterations"] += np.where(running, iterations, 0)
        self.tallies["newton_finishes"][0] += shell.newton_steps > 0
        if failed:
            self._stop(failed, relaxation_error, start)
        if self.sensitive and initial:
            self.operator.update(x)
        elif self.sensitive:
            self.wave.move_surface(x)
            if self.wave.transport == "conservative":
                self._check_fold(start)

    def _check_fold(self, start) -> None:
        """Stop a conservative run (a batch: each world apart) whose shell contracted past the fold."""
        ratio = (self.operator.mass() / self.rest_mass).reshape(self.worlds, -1)
        past = [w for w in np.flatnonzero(ratio.min(axis=1) < FOLD_AREA_RATIO) if int(w) not in self.stopped]
        if not past:
            return
        w = int(past[0])
        vertex = int(np.argmin(ratio[w]))
        where = "" if self.worlds == 1 else f"world {w}: "
        error = FoldError(
            f"{where}at t = {self.time:.4g} the shell contracted past the fold of conservative transport: vertex "
            f"{vertex}'s area is {ratio[w, vertex]:.3f} of its rest value, below 1/e, where no equilibrium holds the "
            "chemical a contraction concentrates (docs/theory/transport.md); end the run before (--set t_end) or "
            "take --set transport=material", self.time, self.wave.steps)
        if self.worlds == 1:
            raise error
        self._stop([int(w) for w in past], error, start)

    def _stop(self, worlds, error: Exception, start) -> None:
        """Stop `worlds` (batched): their state at the step's start is kept, their live share parked at
        rest. Raises `error` once every world has stopped."""
        rest = self.shell.mesh.vertices.astype(self.shell._real)
        n = self.shell.mesh.vertices_per_world
        for w in worlds:
            self.stopped[w] = error
            self._frozen[w] = world_shares(start, w, self.worlds)
            for array in self.state.arrays():
                size = len(array) // self.worlds
                array[w * size:(w + 1) * size].zero_()
            share = wp.array(rest[w * n:(w + 1) * n], dtype=self.shell.vec3, device=self.shell.device)
            wp.copy(self.state.x, share, dest_offset=w * n)
        if len(self.stopped) == self.worlds:
            raise error

    def frozen(self, w: int) -> dict | None:
        """A stopped world's state arrays (NumPy, by State field and history name) at the start of the
        step it failed in; None while it runs."""
        if w not in self._frozen:
            return None
        names = [name for name in FIELDS if getattr(self.state, name) is not None] + list(self.state.history)
        return {name: share.numpy() for name, share in zip(names, self._frozen[w])}

    def counters(self, world: int = 0) -> dict:
        """World `world`'s bookkeeping so far, as whole numbers: relaxations and their CG iterations, the
        unconverged, Newton-finished and round-off relaxations (stored per frame, for a resume)."""
        return {name: int(values[world]) for name, values in self.tallies.items()}

    def restore_counters(self, counters: dict, world: int = 0) -> None:
        """Continue world `world`'s bookkeeping of `counters(world)` (a resumed run's)."""
        self.relax_iterations = []
        for name in self.TALLIES:
            self.tallies[name][world] = int(counters[name])

    def relax_iterations_mean(self, world: int = 0) -> float:
        """CG iterations per relaxation over the whole run."""
        counters = self.counters(world)
        return counters["relax_iterations"] / counters["relaxations"]

    def restore(self, x) -> None:
        """Set the equilibrium positions (resuming a run); the wave's operator follows if sensitive."""
        self.state.set("x", x)
        if self.sensitive:
            self.operator.update(self.state.x)

    def _advance(self, start) -> None:
        """The wave's `chemistry_steps`; batched worlds: a world that blows up or whose surface lowers the
        bound below dt is stopped (found by its flag, or by each world's own bound) and the rest go on."""
        target = self.wave.steps + self.chemistry_steps
        while self.wave.steps < target:
            try:
                self.wave.advance(target - self.wave.steps)
            except (BlowUpError, TimeStepError) as error:
                if self.worlds == 1:
                    raise
                if isinstance(error, TimeStepError):  # below dt; else the lowest (within the estimate's tolerance)
                    bounds = self.wave.solver.world_stable_dts(self.worlds)
                    bounds[list(self.stopped)] = np.inf
                    failed = np.flatnonzero(bounds < self.wave.dt)
                    failed = failed if len(failed) else [int(np.argmin(bounds))]
                else:
                    failed = np.flatnonzero(self.wave.solver.flag.numpy())
                failed = [int(w) for w in failed if int(w) not in self.stopped]
                if not failed:
                    raise
                self._stop(failed, error, start)
                if self.sensitive:  # the parked worlds' rest surface: the bound anew
                    self.operator.update(self.state.x)

    def step(self):
        """Advance the wave `chemistry_steps` steps, then relax the shell to the new reference; returns self."""
        start = self._start_of_step()
        self._advance(start)
        self._equilibrate(start=start)
        return self


class Walking:
    """Couple a `wave` (FitzHughNagumo or Telegraph) to inertial shell `dynamics` (the walkers).

    One coupled step, one chemistry step dt_c:
    1. the wave's solver advances its state one step, c⁰ → c¹;
    2. the mechanics advance `substeps` steps of dt_c / substeps (the largest divisor step within
       the mechanics' bound), so both clocks stay equal; before substep k the shell's active
       reference follows c⁰ + (k/substeps)(c¹ - c⁰) (`ramp`, the default; device to device), or
       jumps to c¹ before the first (`ramp=False`: each chemistry step then kicks the shell's stiffest
       modes, docs/theory/dynamics.md#the-active-reference-ramp);
    3. deformation-sensitive runs move the wave to the new positions (the solver's `move_surface`,
       which carries the chemical with the material); the insensitive twin keeps the rest surface;
    4. `recorder()`, if given, launches device-only work (e.g. a trace row).

    `advance(steps)` runs guarded chunks of up to `check_every` coupled steps with no host round-trip
    (captured graphs of about `GRAPH_SUBSTEPS` mechanics steps, at least one coupled step: a graph's
    host memory grows with its launches, ~10 KB each on CUDA). After each chunk the flags are read (NaN/Inf or runaway
    values of c, w, v: BlowUpError; the wave's period-2 flip-flop: OscillationError; state restored
    to the chunk's start); sensitive runs then re-check the wave's stability bound on the moved
    surface (TimeStepError, state restored, if the fixed dt now exceeds it).

    Batched worlds (`Mesh.union`): a world whose flags are up is put back to the chunk's start and
    stopped there (`stopped`: world -> its error; it stays frozen while the others go on); the run
    raises only when every world has stopped, or for a failure that belongs to no one world (the moved
    surface's time-step bound).
    """

    def __init__(self, dynamics: ShellDynamics, wave: _Stepper, *, sensitive: bool = True, check_every: int = 20,
                 recorder=None, ramp: bool = True):  # fmt: skip
        if not isinstance(dynamics, ShellDynamics):
            raise ValueError(f"dynamics must be a wavewarp.ShellDynamics, got {type(dynamics).__name__}")
        _check_pair(dynamics.shell, wave)
        self.dynamics, self.wave, self.shell, self.operator = dynamics, wave, dynamics.shell, wave.operator
        self.sensitive = bool(sensitive)
        self.recorder = recorder
        if not wave.fixed_dt:  # an automatic dt follows the moving surface: the clocks would part
            raise ValueError("Walking needs a wave with a fixed dt (the mechanics step divides it)")
        self.substeps = math.ceil(wave.dt / dynamics.dt * (1 - 1e-12))
        dynamics.set_time_step(wave.dt / self.substeps, dynamics.omega_max)
        self.ramp = bool(ramp) and self.substeps > 1  # one substep: the ramp's only value is c¹
        self.shell.update_reference(wave.c)
        self._c_start, self._c_ramp = wp.empty_like(wave.c), wp.empty_like(wave.c)
        modules = (kernels.laplace, kernels.waves, *dynamics.runner.modules)
        self.runner = GuardedRunner(self._step, protected=self._protected, check=self._check,
                                    reset=self._reset_checks, restore=self._restore, device=self.shell.device,
                                    modules=modules, capture=dynamics.capture and wave.capture,
                                    check_every=check_every, graph_steps=max(1, GRAPH_SUBSTEPS // self.substeps))  # fmt: skip
        self.shell.listen(self.notify_model_changed)
        self.stopped = {}  # batched worlds: world -> the error that stopped it
        self._frozen = {}  # world -> its protected arrays' share when it stopped

    time = property(lambda self: self.wave.time)
    check_every = property(lambda self: self.runner.check_every)

    @property
    def state(self) -> State:
        """The coupled state: the shell's x, v with the wave's c, w (or c_t) and history, at the wave's time."""
        w, d = self.wave.state, self.dynamics.state
        return State(x=d.x, v=d.v, c=w.c, rate=w.rate, w=w.w, history=w.history, time=w.time, steps=w.steps)

    def notify_model_changed(self) -> None:
        """The shell's V̄ or terms changed: the captured steps are captured anew."""
        self.runner.invalidate()

    def _reset_checks(self) -> None:
        self.wave.solver.reset_checks()
        self.dynamics.solver.reset_checks()

    def _protected(self) -> list:
        return self.wave.state.arrays() + [self.dynamics.state.x, self.dynamics.state.v]

    def _step(self) -> None:
        wave, dynamics = self.wave, self.dynamics
        if self.ramp:
            wp.copy(self._c_start, wave.c)
        wave.solver.step(wave.state, wave.state, wave.dt)
        if not self.ramp:
            self.shell.update_reference(wave.c)
        for k in range(1, self.substeps + 1):
            if self.ramp:
                eval_reference_ramp(self._c_start, wave.c, k / self.substeps, self._c_ramp)
                self.shell.update_reference(self._c_ramp)
            dynamics.solver.step(dynamics.state, dynamics.state, dynamics.dt)
        if self.sensitive:
            wave.solver.move_surface(wave.state, dynamics.state.x)
        if self.recorder is not None:
            self.recorder()

    def _check(self, chunk: int):
        wave, dynamics = self.wave, self.dynamics
        failure = wave.chunk_error(chunk, wave.solver.launch_checks(wave.state, wave.blowup_limit),
                                   f" coupled to the {dynamics.scheme}")  # fmt: skip
        if failure is None:
            failure = dynamics.runaway(dynamics.time, chunk * wave.dt)
        if failure is not None and self.shell.worlds > 1:
            failure = self._stop_worlds(failure)
        if failure is None and self.sensitive:
            self.operator.moved_on_device()  # a graph replay moved the surface without a new `version`
            try:
                wave.refresh()  # the surface moved: λ_max on the new surface, against the fixed dt
            except TimeStepError as error:
                failure = error
        return failure

    def _stop_worlds(self, failure):
        """Batched worlds: stop (freeze at the chunk's start) every world whose flags are up; `failure`
        (the first world's error, its message naming the batch) is raised only once every world stopped."""
        worlds, dynamics = self.shell.worlds, self.dynamics
        dynamics.solver.launch_checks(dynamics.state, dynamics.speed_limit)  # its flags this chunk, too
        up = self.wave.solver.flag.numpy() | dynamics.solver.flag.numpy()
        for w in np.flatnonzero(up):
            if int(w) not in self.stopped:
                self.stopped[int(w)] = failure
                self._frozen[int(w)] = self.runner.world_backup(int(w), worlds)
        if len(self.stopped) == worlds:
            return failure
        for w, copies in self._frozen.items():
            self.runner.put_world(copies, w, worlds)
        self._restore()
        return None

    def _restore(self) -> None:
        self.shell.update_reference(self.wave.c)
        if self.sensitive:
            self.operator.update(self.dynamics.state.x)

    def advance(self, steps: int = 1):
        """Advance `steps` coupled steps on the device; returns self."""
        wave, dynamics = self.wave, self.dynamics
        wave.refresh()

        def done(chunk):
            wave.steps += chunk
            wave.time += chunk * wave.dt
            dynamics.steps += chunk * self.substeps
            dynamics.time += chunk * self.substeps * dynamics.dt

        self.runner.run(steps, done)
        return self

    def step(self):
        """One coupled step (chemistry and the mechanics over it); returns self."""
        return self.advance(1)
