"""Chemical waves on a shell, ready to run: a chemistry solver, its State and a guarded runner.

`Telegraph` and `FitzHughNagumo` each hold a solver (wavewarp/chemistry.py), the State it advances
and a `GuardedRunner`, and own the time step: `dt=None` picks `safety` × the stability bound, a fixed
dt past the bound is refused with a TimeStepError stating the bound and a safe value, and the bound
is estimated again whenever the operator's surface moves. `advance(steps)` runs the steps on the
device as captured graphs; every `check_every` steps one flag is read back: NaN/Inf or a value past
`blowup_limit` restores the last good state and raises `BlowUpError`; FitzHugh–Nagumo's period-2
flip-flop raises `OscillationError` (docs/theory/chemistry.md, "Stability guard").
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .checks import AUTOMATIC_DT, finite, positive
from .chemistry import FLIP_STEPS, FitzHughNagumoSolver, TelegraphSolver
from .kernels import laplace as kernels_laplace
from .kernels import waves as kernels_waves
from .kernels.waves import FLIP_FLOP
from .runner import GuardedRunner, Stepper


class BlowUpError(RuntimeError):
    """A run went non-finite or past its limit; the stepper holds the last good state (`time`, `steps`)."""

    def __init__(self, message: str, time: float, steps: int):
        super().__init__(message)
        self.time = time
        self.steps = steps


class OscillationError(BlowUpError):
    """FHN settled into a bounded period-2 flip-flop (a dt past the stability bound that does not blow up)."""


class TimeStepError(ValueError):
    """A fixed dt exceeds the method's stability bound (at construction, or after the surface moved)."""


class _Stepper(Stepper):
    """A chemistry solver with its state, its time step and a guarded runner."""

    def __init__(self, solver, *, dt, safety, check_dt, check_every, capture):
        self.solver = solver
        self.operator, self.device, self.scalar = solver.operator, solver.device, solver.scalar
        self.safety = self.checked_safety(safety)
        self.check_dt = bool(check_dt)
        self._requested_dt = None if dt is None else positive("dt", dt)
        self.capture = bool(capture)
        self.dt = None
        self._geometry_version = None
        self.state = None
        self.runner = GuardedRunner(self._step, protected=lambda: self.state.arrays(), check=self._check,
                                    reset=solver.reset_checks, device=self.device,
                                    modules=(kernels_laplace, kernels_waves), capture=self.capture,
                                    check_every=check_every)  # fmt: skip

    # ---------------------------------------------------------------- the solver's names
    bound_formula = property(lambda self: self.solver.bound_formula)
    mass_corrections = property(lambda self: self.solver.mass_corrections)
    transport = property(lambda self: self.solver.transport)
    largest_eigenvalue = property(lambda self: self.solver.largest_eigenvalue)
    c = property(lambda self: self.state.c)

    # ---------------------------------------------------------------- the time step
    @property
    def fixed_dt(self) -> bool:
        """True when dt was given (it stays as the surface moves); False when it follows the bound."""
        return self._requested_dt is not None

    @property
    def stable_dt(self) -> float:
        """The method's stability bound at the current surface (see `bound_formula`)."""
        return self.solver.stable_dt()

    def refresh(self) -> None:
        """Where the surface moved: the bound anew, dt set or checked against it (TimeStepError)."""
        if self._geometry_version == self.operator.version:
            return
        bound = self.solver.stable_dt()
        if self._requested_dt is None:
            dt = self.safety * bound
        else:
            dt = self._requested_dt
            if self.check_dt and dt > bound:
                raise TimeStepError(
                    f"dt = {dt:.6g} exceeds the stability bound {bound:.6g} of the {self.scheme} "
                    f"({self.bound_formula}, λ_max(M⁻¹K) = {self.largest_eigenvalue:.6g} by power iteration): "
                    f"use dt <= {bound:.6g}, e.g. dt = {self.safety * bound:.6g} "
                    f"(safety {self.safety}), or {AUTOMATIC_DT}"
                )
        if dt != self.dt:
            self.dt = dt
            self.runner.invalidate()
        self._geometry_version = self.operator.version
        self.solver.prepare(self.dt)

    def change_dt(self, dt: float, recentre: bool = True) -> None:
        """Step from now on with `dt` (fixed), e.g. below a bound that the moving surface lowered.
        The telegraph's half-step velocity is re-centred to the new step (`recentre=False`: it
        already belongs to dt, as in a frame saved after a change), which keeps the leapfrog second
        order across the change. Raises TimeStepError past the current bound."""
        dt = positive("dt", dt)
        bound = self.solver.stable_dt()
        if self.check_dt and dt > bound:
            raise TimeStepError(f"dt = {dt:.6g} exceeds the stability bound {bound:.6g} of the {self.scheme}")
        if recentre:
            self._recentre(self.dt, dt)
        self._requested_dt = self.dt = dt
        self._geometry_version = None  # the next step re-checks dt against the bound
        self.runner.invalidate()

    def _recentre(self, old: float, new: float) -> None:
        """Move a staggered state from step `old` to step `new` (the leapfrog's half-step velocity)."""

    # ---------------------------------------------------------------- stepping
    def _step(self) -> None:
        self.solver.step(self.state, self.state, self.dt)

    def move_surface(self, x) -> None:
        """Move the operator to positions `x` and carry the chemical with the material (the solver's
        `move_surface`); the next step re-checks dt on the new surface."""
        self.solver.move_surface(self.state, x)

    def _check(self, chunk: int):
        return self.chunk_error(chunk, self.solver.launch_checks(self.state, self.blowup_limit))

    def chunk_error(self, steps: int, cause: str | None, coupled: str = "") -> BlowUpError | None:
        """Read the flag of a chunk of `steps` steps (after the solver's `launch_checks`, whose message is
        `cause`): None when clear, else the error to raise once the state is restored. `coupled` names a
        coupling in the message."""
        codes = self.solver.flag.numpy()  # one per world
        code = codes[codes != 0][0] if codes.any() else 0
        if not code:
            return None
        bound = self.solver.stable_dt(last_if_broken=True)
        window = f"between t = {self.time:.6g} and t = {self.time + steps * self.dt:.6g}"
        restored = f"the state is restored to t = {self.time:.6g}"
        if code == FLIP_FLOP:
            return OscillationError(
                f"{self.scheme}{coupled} fell into a period-2 flip-flop {window}: c^(n+1) - c^n changed sign "
                f"every step for {FLIP_STEPS} steps at some vertex, above {self.solver.flip_floor:.3g} and not "
                f"decaying. This bounded oscillation (no NaN, no runaway value) is the instability of a time step "
                f"too large for the state: dt = {self.dt:.6g} against the stability bound {bound:.6g} "
                f"({self.bound_formula}); {restored}. Reduce dt, e.g. to {self.safety * bound:.6g}, or {AUTOMATIC_DT}",
                self.time,
                self.steps,
            )
        return BlowUpError(
            f"{self.scheme}{coupled} blew up {window} ({cause or 'NaN/Inf or a runaway value'}; |value| limit "
            f"{self.blowup_limit:.3g}) with dt = {self.dt:.6g} (stability bound {bound:.6g}); {restored}. "
            "Reduce dt or check the initial data",
            self.time,
            self.steps,
        )

    # ---------------------------------------------------------------- reading the state
    def concentration(self) -> np.ndarray:
        """(V,) control values c at the current time."""
        return self.state.numpy("c")

    def total(self) -> float:
        """C = ∫ c dω = Σ M_I c_I on the operator's surface (lumped and consistent mass agree on it)."""
        return float(self.operator.mass() @ self.concentration())


class Telegraph(_Stepper):
    """`c_tt + α c_t = γ² Δ_LB c` by leapfrog with centred damping (`TelegraphSolver`).

    `c0`, `v0` (V,) are control values (see `gaussian_pulse`, `steady_front`); v^{½} = v0 + dt/2
    c_tt(0). Stable while dt < 2 / (γ sqrt(λ_max(M̃⁻¹K))). No flip detector: the scheme is linear, so
    past the bound the top mode grows without limit (the runaway check stops it), and below it modes
    near ω dt = π alternate sign legitimately.
    """

    def __init__(self, operator, gamma, alpha=0.001, *, c0, v0=None, dt=None, safety=0.9, mass_corrections=0,
                 check_dt=True, check_every=100, blowup_limit=None, capture=True, transport="conservative"):  # fmt: skip
        solver = TelegraphSolver(operator, gamma, alpha, mass_corrections=mass_corrections, transport=transport)
        super().__init__(solver, dt=dt, safety=safety, check_dt=check_dt, check_every=check_every, capture=capture)
        self.gamma, self.alpha = solver.gamma, solver.alpha
        c0 = operator.checked_values(c0, "c0")
        v0 = np.zeros_like(c0) if v0 is None else operator.checked_values(v0, "v0")
        if blowup_limit is None:
            crossing_time = math.sqrt(operator.area) / self.gamma
            blowup_limit = 1e6 * max(1.0, np.max(np.abs(c0)), np.max(np.abs(v0)) * crossing_time)
        self.blowup_limit = positive("blowup_limit", blowup_limit)
        self.refresh()
        self.state = solver.state(c0, v0, self.dt)

    def _recentre(self, old: float, new: float) -> None:
        self.solver.recentre(self.state, old, new)

    v = property(lambda self: self.state.rate)

    def velocity(self) -> np.ndarray:
        """(V,) the leapfrog velocity v^{n-½} = (c^n - c^{n-1}) / dt (control values)."""
        return self.state.numpy("rate")

    def total_rate(self) -> float:
        """Σ M_I v_I: the rate C' of the total at t - dt/2 (the half step the leapfrog velocity belongs to)."""
        return float(self.operator.mass() @ self.velocity())


class FitzHughNagumo(_Stepper):
    """`c_t = γ² Δ_LB c + c(1-c)(c-ν) - w`, `w_t = ε (c - κ w)` (`FitzHughNagumoSolver`; reaction on
    control values). Defaults are the paper's ν, κ, ε, γ; `w0` defaults to 0. With conservative
    transport on a moving surface C(t) = C(0) + `produced()`."""

    def __init__(self, operator, gamma=0.2, nu=-0.01, kappa=1e-4, epsilon=0.005, *, c0, w0=None, dt=None,
                 scheme="explicit", safety=0.9, mass_corrections=0, tol=None, max_cg_iterations=500,
                 check_dt=True, check_every=100, blowup_limit=None, capture=True, transport="conservative"):  # fmt: skip
        solver = FitzHughNagumoSolver(operator, gamma, nu, kappa, epsilon, scheme=scheme, mass_corrections=mass_corrections,
                                      tol=tol, max_cg_iterations=max_cg_iterations, transport=transport)  # fmt: skip
        if solver.implicit and capture and operator.device.is_cuda and not wp.is_conditional_graph_supported():
            capture = False  # the CG loop needs conditional graph nodes (CUDA 12.4+) to be captured
        super().__init__(solver, dt=dt, safety=safety, check_dt=check_dt, check_every=check_every, capture=capture)
        self.gamma, self.nu, self.kappa, self.epsilon = solver.gamma, solver.nu, solver.kappa, solver.epsilon
        self.implicit, self.reaction_lipschitz = solver.implicit, solver.reaction_lipschitz
        c0 = operator.checked_values(c0, "c0")
        w0 = np.zeros_like(c0) if w0 is None else operator.checked_values(w0, "w0")
        self.blowup_limit = positive("blowup_limit", blowup_limit) if blowup_limit is not None else \
            1e6 * max(1.0, np.max(np.abs(c0)), np.max(np.abs(w0)))  # fmt: skip
        self.state = solver.state(c0, w0)
        self.produced_offset = 0.0  # the amount before this stepper's steps (set_produced)
        self.refresh()

    w = property(lambda self: self.state.w)
    flip_floor = property(lambda self: self.solver.flip_floor)

    def inhibitor(self) -> np.ndarray:
        """(V,) the inhibitor w (control values)."""
        return self.state.numpy("w")

    def produced(self) -> float:
        """∫₀ᵗ ∫ r(c, w) dω dt: the amount the reaction r = f(c) - w has added since t = 0, summed exactly as
        the steps add it (diffusion adds none), plus `produced_offset` (a resumed run's amount so far).
        With conservative transport C(t) = C(0) + produced() to round-off (IMEX: to the CG tolerance)."""
        return self.produced_offset + float(np.sum(self.state.history["produced"].numpy().astype(np.float64)))

    def set_produced(self, amount: float, per_vertex=None) -> None:
        """Start `produced()` from `amount` (a run resumed at a frame that stored it); with the frame's
        `per_vertex` amounts (V,) the sums go on exactly as in the run that wrote them."""
        if per_vertex is None:
            self.state.history["produced"].zero_()
            self.produced_offset = finite("amount", amount)
        else:
            self.state.set("produced", per_vertex)
            self.produced_offset = 0.0

    def produced_per_vertex(self) -> np.ndarray:
        """(V,) the amount the reaction has added at each vertex since t = 0 (since a resume from an
        amount alone: `set_produced`)."""
        return self.state.history["produced"].numpy()

