"""Coupled steppers (SPEC §1, §3, §5): chemistry drives the shell, the shell steers the wave.

`QuasiStatic` (oocytes, wave guides, buckling) relaxes the shell after each chemistry step;
`Walking` (the walkers) advances inertial shell dynamics between chemistry steps.

One `QuasiStatic.step()`:
1. the wave advances `chemistry_steps` steps on the device (its own stability guard);
2. the shell's active reference ā, b̄ follows the new control concentrations (device to device);
3. `relax` finds the new quasi-static equilibrium, warm-started from the last one (one captured
   device loop, positions device to device: wavewarp/relax.py);
4. deformation-sensitive runs move the wave to the new surface (`move_surface`: the chemical is
   carried by the material, conservatively by default), which makes the wave re-check its time
   step; the insensitive twin keeps the rest surface. The equilibrium at t = 0 only places the
   operator: the initial values are the concentrations on that surface.

State (positions, the wave's c and its velocity or inhibitor), model (Shell, LaplaceBeltrami)
and stepper stay apart: the coupled steppers only sequence them.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from . import kernels
from .checks import count
from .laplace import LaplaceBeltrami
from .relax import NEWTON_STEPS, ROUND_OFF_SLACK, checked_method, relax
from .device import run_steps
from .kernels.dynamics import reference_ramp_kernel
from .shell import RelaxationError, Shell
from .waves import TimeStepError, _Stepper


class QuasiStatic:
    """Couple `wave` (a Telegraph or FitzHughNagumo on `wave.operator`) to `shell`.

    `sensitive=True`: the wave runs on the current (deformed) surface; False: on the rest
    surface (the deformation-insensitive twin). `tol`: the relaxation tolerance (Shell.relax).
    `overdamped=True` accepts a relaxation that spends its `max_iterations` or whose line search
    finds no lower energy (the paper's overdamped update: near a buckling instability the shell
    lags its reference instead of stopping the run); such steps are counted in `unconverged`.
    `method` and `max_iterations`, `newton_steps`: Shell.relax's ("auto": CG, then a Newton finish
    where CG spends its budget; counted in `newton_finishes`).
    """

    def __init__(self, shell: Shell, wave: _Stepper, *, sensitive: bool = True, chemistry_steps: int = 1, tol=None,
                 x0=None, max_iterations: int = 20000, overdamped: bool = False, method: str = "auto",
                 newton_steps: int = NEWTON_STEPS):  # fmt: skip
        if not isinstance(shell, Shell):
            raise ValueError(f"shell must be a wavewarp.Shell, got {type(shell).__name__}")
        if not isinstance(wave, _Stepper):
            raise ValueError(f"wave must be a Telegraph or FitzHughNagumo stepper, got {type(wave).__name__}")
        op: LaplaceBeltrami = wave.operator
        if op.mesh is not shell.mesh and not np.array_equal(op.mesh.triangles, shell.mesh.triangles):
            raise ValueError("the shell and the wave's operator must share one mesh")
        if op.device != shell.device or op.scalar != shell.scalar:
            raise ValueError(f"the shell ({shell.device}, {shell.scalar.__name__}) and the wave ({op.device}, "
                             f"{op.scalar.__name__}) must share device and dtype")  # fmt: skip
        self.shell, self.wave, self.operator = shell, wave, op
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
        self._x = wp.array(x0.astype(shell._real), dtype=shell.vec3, device=shell.device)
        self.relax_iterations = []
        self.round_off_stops = 0  # relaxations accepted at the round-off floor, within ROUND_OFF_SLACK × tol
        self._equilibrate(initial=True)

    @property
    def time(self) -> float:
        return self.wave.time

    def positions(self) -> np.ndarray:
        """(V, 3) control positions of the current equilibrium."""
        return self._x.numpy().astype(np.float64)

    def _equilibrate(self, initial: bool = False) -> None:
        self.shell.update_reference(self.wave.c)
        try:
            relax(self.shell, self._x, self.tol, self.max_iterations, out=self._x, method=self.method,
                  newton_steps=self.newton_steps)  # device to device
        except RelaxationError as error:
            if error.round_off and error.residual <= ROUND_OFF_SLACK * self.tol:
                self.round_off_stops += 1  # the dtype's round-off floor just above tol (sharp corners, float32)
            elif self.overdamped:
                # overdamped: the shell lags its reference (budget spent, or no lower energy found at a
                # sharp fold: docs/scenes.md "Open"); the next step goes on from here
                self.unconverged += 1
            else:
                raise
            self._x.assign(error.x.astype(self.shell._real))
        self.relax_iterations.append(len(self.shell.relax_history) - 1)
        self.newton_finishes += self.shell.newton_steps > 0
        if self.sensitive and initial:
            self.operator.update(self._x)
        elif self.sensitive:
            self.wave.move_surface(self._x)

    def restore(self, x) -> None:
        """Set the equilibrium positions (resuming a run); the wave's operator follows if sensitive."""
        self._x.assign(np.asarray(x, dtype=np.float64).astype(self.shell._real))
        if self.sensitive:
            self.operator.update(self._x)

    def step(self):
        """Advance the wave `chemistry_steps` steps, then relax the shell to the new reference; returns self."""
        self.wave.advance(self.chemistry_steps)
        self._equilibrate()
        return self


class Walking:
    """Couple a `wave` (FitzHughNagumo or Telegraph) to inertial shell `dynamics` (the walkers, SPEC §3, §4).

    One coupled step, one chemistry step dt_c:
    1. the wave advances one step, c⁰ → c¹;
    2. the mechanics advance `substeps` steps of dt_c / substeps (the largest divisor step within
       the mechanics' bound), so both clocks stay equal; before substep k the shell's active
       reference follows c⁰ + (k/substeps)(c¹ - c⁰) (`ramp`, the default; device to device), or
       jumps to c¹ before the first (`ramp=False`: each chemistry step then kicks the shell's stiffest
       modes, docs/walkers.md "Reference ramp");
    4. deformation-sensitive runs move the wave to the new positions (`move_surface`, which carries
       the chemical with the material); the insensitive twin keeps the rest surface (M and K fixed);
    5. `recorder()`, if given, launches device-only work (e.g. a trace row).

    `advance(steps)` runs chunks of up to `check_every` coupled steps with no host round-trip (one
    CUDA graph per chunk size). After each chunk the flags are read (NaN/Inf or runaway values of c,
    w, v: BlowUpError; the wave's period-2 flip-flop: OscillationError; state restored to the
    chunk's start); sensitive runs then re-check the wave's stability bound on the moved surface
    (TimeStepError, state restored, if the fixed dt now exceeds it).
    """

    def __init__(self, dynamics, wave: _Stepper, *, sensitive: bool = True, check_every: int = 20, recorder=None,
                 ramp: bool = True):  # fmt: skip
        from .dynamics import ShellDynamics

        if not isinstance(dynamics, ShellDynamics):
            raise ValueError(f"dynamics must be a wavewarp.ShellDynamics, got {type(dynamics).__name__}")
        if not isinstance(wave, _Stepper):
            raise ValueError(f"wave must be a Telegraph or FitzHughNagumo stepper, got {type(wave).__name__}")
        shell, op = dynamics.shell, wave.operator
        if not np.array_equal(op.mesh.triangles, shell.mesh.triangles):
            raise ValueError("the shell and the wave's operator must share one mesh")
        if op.device != shell.device or op.scalar != shell.scalar:
            raise ValueError(f"the shell ({shell.device}, {shell.scalar.__name__}) and the wave ({op.device}, "
                             f"{op.scalar.__name__}) must share device and dtype")  # fmt: skip
        self.dynamics, self.wave, self.shell, self.operator = dynamics, wave, shell, op
        self.sensitive = bool(sensitive)
        self.check_every = count("check_every", check_every, 1)
        self.recorder = recorder
        if not wave.fixed_dt:  # an automatic dt follows the moving surface: the clocks would part
            raise ValueError("Walking needs a wave with a fixed dt (the mechanics step divides it)")
        self.substeps = math.ceil(wave.dt / dynamics.dt * (1 - 1e-12))
        dynamics.set_time_step(wave.dt / self.substeps, dynamics.omega_max)
        self.ramp = bool(ramp) and self.substeps > 1  # one substep: the ramp's only value is c¹
        self.shell.update_reference(wave.c)
        self._c_start, self._c_ramp = wp.empty_like(wave.c), wp.empty_like(wave.c)
        self._graphs = {}
        self._state = wave._state() + [dynamics.x, dynamics.v]
        self._backups = [wp.empty_like(a) for a in self._state]

    @property
    def time(self) -> float:
        return self.wave.time

    def _step(self) -> None:
        if self.ramp:
            wp.copy(self._c_start, self.wave.c)
        self.wave._step()
        if not self.ramp:
            self.shell.update_reference(self.wave.c)
        for k in range(1, self.substeps + 1):
            if self.ramp:
                wp.launch(reference_ramp_kernel, dim=len(self._c_ramp), inputs=[self._c_start, self.wave.c,
                          self.shell.scalar(k / self.substeps)], outputs=[self._c_ramp])  # fmt: skip
                self.shell.update_reference(self._c_ramp)
            self.dynamics._step()
        if self.sensitive:
            self.wave.move_surface(self.dynamics.x)
        if self.recorder is not None:
            self.recorder()

    def _restore(self) -> None:
        for backup, a in zip(self._backups, self._state):
            wp.copy(a, backup)
        self.shell.update_reference(self.wave.c)
        if self.sensitive:
            self.operator.update(self.dynamics.x)

    def advance(self, steps: int = 1):
        """Advance `steps` coupled steps on the device; returns self."""
        steps = count("steps", steps, 0)
        wave, dynamics = self.wave, self.dynamics
        wave._refresh()
        modules = (kernels.laplace, kernels.waves, kernels.shell, kernels.contact, kernels.dynamics, kernels.limit_surface,
                   kernels.reduce)  # fmt: skip
        done = 0
        while done < steps:
            chunk = min(self.check_every, steps - done)
            for backup, a in zip(self._backups, self._state):
                wp.copy(backup, a)
            wave._flag.zero_()
            run_steps(self._step, chunk, device=self.shell.device, graphs=self._graphs, modules=modules,
                      capture=dynamics.capture and wave.capture, revision=self.shell.revision)  # fmt: skip
            failure = wave._chunk_error(chunk, wave._check_chunk(), f" coupled to the {dynamics.scheme}")
            if failure is None:
                failure = dynamics.runaway(dynamics.time, chunk * wave.dt)
            if failure is None and self.sensitive:
                self.operator.moved_on_device()  # a graph replay moved the surface without a new `version`
                try:
                    wave._refresh()  # the surface moved: λ_max on the new surface, against the fixed dt
                except TimeStepError as error:
                    failure = error
            if failure is not None:
                self._restore()
                raise failure
            done += chunk
            wave.steps += chunk
            wave.time += chunk * wave.dt
            dynamics.steps += chunk * self.substeps
            dynamics.time += chunk * self.substeps * dynamics.dt
        return self

    def step(self):
        """One coupled step (chemistry and the mechanics over it); returns self."""
        return self.advance(1)
