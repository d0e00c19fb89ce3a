"""Implicit overdamped mechanics for the walkers (docs/theory/dynamics.md, "Implicit overdamped mechanics").

The explicit mobility model (`OverdampedSolver`) steps ζ M ẋ = F(x) − M g ẑ + Lᵀ f under dt < 2ζ/ω², a bound set by
the bending stiffness (∝ ℓ⁻⁴). Here each step is backward Euler in the shell's forces, solved as a minimisation,

    x_(n+1) = argmin_x  E(x) + Σ_I ½ (ζ M_I / dt) |x_I − a_I|²,     a = x_n + dt (g/ζ + M⁻¹ Lᵀ f / ζ),

i.e. ζ M (x_(n+1) − x_n)/dt = F(x_(n+1)) − M g ẑ + Lᵀ f. The ground's force f comes first, from the implicit ground's
per-point solve (`Ground(solve="implicit")`) on the explicit predictor v* = (F(x_n)/M + g)/ζ with the drag as each
point's mobility, as the explicit solver's step computes it but with the penalty k z² taken at x_n (not linearised
over the step: a point's drag-only response would misjudge it at a large dt), and is held through the minimisation
(an operator split: first order, and its rest states are the exact equilibria). The minimisation is the shell's captured
nonlinear CG (`Relaxation`) with a `LumpedDrag` term; each world converges on its own, and a world that does not
converge raises `ImplicitStepError` after the chunk, the state restored. No stability bound: dt is the caller's.
The reverse mode (adjoint) of this step is not implemented.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .checks import count, positive
from .drag import LumpedDrag
from .dynamics import OverdampedDynamics, OverdampedSolver
from .kernels import drag as kernels_drag
from .kernels import relax as kernels_relax
from .kernels.dynamics import (
    eval_extrapolate,
    eval_implicit_anchors,
    eval_shell_velocity,
    eval_speed_runaway,
    eval_step_velocity,
)
from .kernels.implicit_contact import eval_implicit_ground
from .kernels.relax import BUDGET_SPENT
from .relax import ROUND_OFF_SLACK, Relaxation, _inverse_stiffness
from .waves import BlowUpError

# the step's relaxation: its tolerance (a residual strain, max |F| / (Y h ℓ̄), as Shell.relax) by dtype and its budget
STEP_TOL = {wp.float32: 1e-5, wp.float64: 1e-9}
STEP_ITERATIONS = 2000


class ImplicitStepError(BlowUpError):
    """The implicit step's minimisation did not converge in some world; the stepper holds the last good state."""


class ImplicitOverdampedSolver(OverdampedSolver):
    """Backward Euler of the overdamped mobility model (module docstring) on `shell`'s device and dtype.

    density ρ, drag ζ per unit mass (None: 2 η_ground, as `OverdampedSolver`), drag_frame, gravity and ground as
    `OverdampedSolver`; the ground, if any, must be implicit (`Ground(solve="implicit")`). tol (None: 1e-5 in float32,
    1e-9 in float64) and max_iterations bound each step's minimisation. ground_passes: the ground's solve and the
    minimisation taken again this many times, the ground's predictor the last solution's own velocity (a fixed-point
    iteration of the split: its first-order error falls each pass, BENCHMARKS.md). The solver adds its drag term to
    the shell's `terms`, which must be empty: a step's forces are the shell's and the drag's.
    """

    scheme = "implicit overdamped shell dynamics"

    def __init__(self, shell, *, density, tol=None, max_iterations=STEP_ITERATIONS, ground_passes=1, **options):
        ground = options.get("ground")
        if ground is not None and ground.solve != "implicit":
            raise ValueError("the implicit overdamped mechanics solve the ground implicitly: use Ground(solve='implicit') "
                             "(in a scene --set contact_solve=implicit)")
        if shell.terms or shell.self_contact is not None:
            raise ValueError("the implicit overdamped mechanics add their drag to the shell's terms: give a shell "
                             "without terms or self-contact")
        if shell.gradient == "autodiff":
            raise ValueError("the implicit overdamped mechanics need the analytic forces: build the Shell with "
                             "gradient='analytic'")
        super().__init__(shell, density=density, **options)
        self.tol = STEP_TOL[shell.scalar] if tol is None else positive("tol", tol)
        self.max_iterations = count("max_iterations", max_iterations, 1)
        self.ground_passes = count("ground_passes", ground_passes, 1)
        self.drag_term = LumpedDrag(shell)
        shell.terms = (self.drag_term,)
        self.relaxation = Relaxation(shell)
        self.relaxation.prepare(self.tol, self.max_iterations)
        self._shell_stiffness = 1.0 / _inverse_stiffness(shell)
        self.interval = None
        n = shell.mesh.n_vertices
        with wp.ScopedDevice(self.device):
            self._start = wp.zeros(n, dtype=self.vec3)
            self._predictor = wp.zeros(n, dtype=self.vec3)
            self._guess = wp.zeros(n, dtype=self.vec3)
            self.failed = wp.zeros(self.worlds, dtype=wp.int32)  # per world: a step's minimisation did not converge
            self.counts = wp.zeros(2 * self.worlds, dtype=wp.int32)  # per world: CG iterations and steps, summed
        self.drift = tuple(g / self.drag for g in self.gravity_vector)  # g/ζ

    def bound(self, omega: float) -> float:
        return math.inf

    def bound_formula(self, omega: float) -> str:
        return "none (backward Euler)"

    def set_interval(self, dt: float) -> None:
        """The drag's stiffness ζ M / dt and the minimisation's preconditioner 1/(k_shell + ζ M / dt), on the device
        (host writes: call it outside captures when dt changes; `ImplicitOverdampedDynamics.set_time_step` does)."""
        dt = positive("dt", dt)
        if dt != self.interval:
            self.interval = dt
            stiffness = self.drag * self.mass / dt
            self.drag_term.set_stiffness(stiffness)
            self.relaxation.inverse_stiffness.assign((1.0 / (self._shell_stiffness + stiffness)).astype(self._real))

    def step(self, state_in, state_out, dt: float) -> None:
        """Ground first (on the explicit predictor), then the minimisation from x_n + dt v_(n−1); v = (x_(n+1) − x_n)/dt."""
        if state_out is not state_in:
            wp.copy(state_out.x, state_in.x)
            wp.copy(state_out.v, state_in.v)
        self.set_interval(dt)
        x, v = state_out.x, state_out.v
        with wp.ScopedDevice(self.device):
            wp.copy(self._start, x)
            eval_extrapolate(x, v, dt, self._guess)  # before v becomes the predictor
            self.drag_term.begin_step(x)  # anchored at x_n the drag adds nothing to F(x_n)
            if self.ground is None:
                eval_implicit_anchors(self._start, v, v, self.drift, dt, self.drag_term.anchors)  # v − v* = 0
                self.relaxation.solve(self._guess, x, self.failed, self.counts)
            else:
                self.shell.forces_device(x, self._forces)
                self._rigid_rows(x, v, False)
                self._integrate(x, v, dt, move=False)  # v = v*, the explicit predictor
                for ground_pass in range(self.ground_passes):
                    if ground_pass:  # the predictor: the last solution's velocity less the ground's change in it
                        eval_shell_velocity(self._start, x, dt, v, self._predictor, v)  # elementwise: in place
                        wp.copy(self._guess, x)
                        wp.copy(x, self._start)
                    self._solve_ground(x, v, dt)
                    eval_implicit_anchors(self._start, v, self._predictor, self.drift, dt, self.drag_term.anchors)
                    self.relaxation.solve(self._guess, x, self.failed, self.counts)
            eval_step_velocity(self._start, x, dt, v)
            self.drag_term.begin_step(x)

    def _solve_ground(self, x, v, dt: float) -> None:
        """v ← the per-point implicit ground's velocity from the predictor v (kept in `_predictor`), the penalty at x."""
        wp.copy(self._predictor, v)
        eval_implicit_ground(self.ground, x, v, self._inverse_mass, self._response_scale(dt), 0.0, self.mask,
                             self.shell.tables.patch(), self._rest_area, self._limit_x, self._limit_v, self._response,
                             self._others, self._normal_force, self._limit_forces, self._forces, self.body,
                             self._coupling)  # dt 0: the penalty at x_n; x stays

    def reset_checks(self) -> None:
        self.failed.zero_()

    def launch_checks(self, state, limit: float) -> None:
        """flag[w] = 1 where world w's minimisation failed since `reset_checks`, or a speed passed `limit` or is NaN."""
        wp.copy(self.flag, self.failed)
        eval_speed_runaway(state.v, limit, self.worlds, self.flag)


class ImplicitOverdampedDynamics(OverdampedDynamics):
    """The implicit overdamped mechanics, ready to run (`ImplicitOverdampedSolver`): dt is required (no bound picks
    it); tol and max_iterations bound each step's minimisation; other arguments as `OverdampedDynamics`. A failed
    minimisation raises `ImplicitStepError` (the state restored to the chunk's start)."""

    solver_type = ImplicitOverdampedSolver

    def __init__(self, shell, *, dt, **options):
        if dt is None:
            raise ValueError("the implicit overdamped mechanics have no stability bound to pick a step from: give dt "
                             "(accuracy sets it; in a walker scene the chemistry step over implicit_substeps)")
        super().__init__(shell, dt=dt, omega=math.inf, **options)
        self.runner.reset = self.solver.reset_checks
        self.runner.modules += (kernels_relax, kernels_drag)

    def set_time_step(self, dt, omega: float = math.inf, check_dt: bool = True) -> None:
        """dt (> 0) as given: backward Euler has no stability bound (`omega` and `check_dt` are not used)."""
        self.omega_max, self.stable_dt = omega, math.inf
        dt = positive("dt", dt)
        self.solver.set_interval(dt)
        if dt != self.dt:
            self.dt = dt
            self.runner.invalidate()

    def runaway(self, time: float, duration: float) -> BlowUpError | None:
        failure = super().runaway(time, duration)
        failed = np.flatnonzero(self.solver.failed.numpy())
        if failure is None or not len(failed):
            return failure
        worlds = "" if self.shell.worlds == 1 else f" in world{'s' * (len(failed) > 1)} {', '.join(map(str, failed))}"
        budget = BUDGET_SPENT in self.solver.failed.numpy()
        why = (f"within {self.solver.max_iterations} iterations; reduce dt, or raise tol or max_iterations" if budget else
               f"(no lower energy: the round-off floor, above {ROUND_OFF_SLACK:g} × tol); use dtype float64 or a larger tol")
        return ImplicitStepError(
            f"a step of the {self.scheme} did not converge{worlds} between t = {time:.6g} and t = {time + duration:.6g}: "
            f"its minimisation stopped short of max|F|/(Y h ℓ̄) <= {self.solver.tol:g} {why}. The state is restored to "
            f"t = {time:.6g}", time, self.steps,
        )

    def mean_iterations(self) -> np.ndarray:
        """Each world's CG iterations per implicit step, over the steps since the dynamics were built."""
        iterations, steps = self.solver.counts.numpy().reshape(-1, 2).T
        return iterations / np.maximum(steps, 1)
