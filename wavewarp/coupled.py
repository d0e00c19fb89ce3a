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
from .dynamics import ShellDynamics
from .kernels.dynamics import eval_reference_ramp
from .relax import NEWTON_STEPS, ROUND_OFF_SLACK, RelaxationError, checked_method, relax
from .runner import GuardedRunner
from .shell import Shell
from .state import State
from .waves import TimeStepError, _Stepper


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
    `overdamped=True` accepts a relaxation that spends its `max_iterations` or whose line search
    finds no lower energy (the paper's overdamped update: near a buckling instability the shell
    lags its reference instead of stopping the run); such steps are counted in `unconverged`.
    `method` and `max_iterations`, `newton_steps`: Shell.relax's ("auto": CG, then a Newton finish
    where CG spends its budget; counted in `newton_finishes`). The positions join the wave's state.
    """

    def __init__(self, shell: Shell, wave: _Stepper, *, sensitive: bool = True, chemistry_steps: int = 1, tol=None,
                 x0=None, max_iterations: int = 20000, overdamped: bool = False, method: str = "auto",
                 newton_steps: int = NEWTON_STEPS):  # fmt: skip
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
        self.newton_finishes = 0  # relaxations that Newton steps finished
        self.overdamped = bool(overdamped)
        self.unconverged = 0  # overdamped relaxations that used their whole iteration budget
        x0 = shell.mesh.vertices if x0 is None else np.asarray(x0, dtype=np.float64)
        wave.state.x = wp.array(x0.astype(shell._real), dtype=shell.vec3, device=shell.device)
        self.relax_iterations = []  # per relaxation since construction or `restore_counters`
        self.earlier_relaxations = (0, 0)  # (count, iterations) before a resume
        self.round_off_stops = 0  # relaxations accepted at the round-off floor, within ROUND_OFF_SLACK × tol
        self._equilibrate(initial=True)

    state = property(lambda self: self.wave.state)
    time = property(lambda self: self.wave.time)

    def positions(self) -> np.ndarray:
        """(V, 3) control positions of the current equilibrium."""
        return self.state.numpy("x")

    def _equilibrate(self, initial: bool = False) -> None:
        x = self.state.x
        self.shell.update_reference(self.state.c)
        try:
            relax(self.shell, x, self.tol, self.max_iterations, out=x, method=self.method,
                  newton_steps=self.newton_steps)  # device to device
        except RelaxationError as error:
            if error.round_off and error.residual <= ROUND_OFF_SLACK * self.tol:
                self.round_off_stops += 1  # the dtype's round-off floor just above tol (sharp corners, float32)
            elif self.overdamped:
                # overdamped: the shell lags its reference (budget spent, or no lower energy found at a
                # sharp fold); the next step goes on from here
                self.unconverged += 1
            else:
                raise
            x.assign(error.x.astype(self.shell._real))
        self.relax_iterations.append(len(self.shell.relax_history) - 1)
        self.newton_finishes += self.shell.newton_steps > 0
        if self.sensitive and initial:
            self.operator.update(x)
        elif self.sensitive:
            self.wave.move_surface(x)

    def counters(self) -> dict:
        """The run's bookkeeping so far, as whole numbers: relaxations and their CG iterations, the
        unconverged, Newton-finished and round-off relaxations (stored per frame, for a resume)."""
        count, iterations = self.earlier_relaxations
        return {"relaxations": count + len(self.relax_iterations),
                "relax_iterations": iterations + int(np.sum(self.relax_iterations, dtype=np.int64)),
                "unconverged_relaxations": self.unconverged, "newton_finishes": self.newton_finishes,
                "round_off_relaxations": self.round_off_stops}  # fmt: skip

    def restore_counters(self, counters: dict) -> None:
        """Continue the bookkeeping of `counters()` (a resumed run's)."""
        self.relax_iterations = []
        self.earlier_relaxations = (int(counters["relaxations"]), int(counters["relax_iterations"]))
        self.unconverged = int(counters["unconverged_relaxations"])
        self.newton_finishes = int(counters["newton_finishes"])
        self.round_off_stops = int(counters["round_off_relaxations"])

    def relax_iterations_mean(self) -> float:
        """CG iterations per relaxation over the whole run."""
        counters = self.counters()
        return counters["relax_iterations"] / counters["relaxations"]

    def restore(self, x) -> None:
        """Set the equilibrium positions (resuming a run); the wave's operator follows if sensitive."""
        self.state.set("x", x)
        if self.sensitive:
            self.operator.update(self.state.x)

    def step(self):
        """Advance the wave `chemistry_steps` steps, then relax the shell to the new reference; returns self."""
        self.wave.advance(self.chemistry_steps)
        self._equilibrate()
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
    (one captured graph per chunk size). After each chunk the flags are read (NaN/Inf or runaway
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
        modules = (kernels.laplace, kernels.waves, kernels.shell, kernels.contact, kernels.dynamics, kernels.limit_surface,
                   kernels.reduce)  # fmt: skip
        self.runner = GuardedRunner(self._step, protected=self._protected, check=self._check,
                                    reset=wave.solver.reset_checks, restore=self._restore, device=self.shell.device,
                                    modules=modules, capture=dynamics.capture and wave.capture,
                                    check_every=check_every)  # fmt: skip
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
