"""Chemical waves on a shell (SPEC §5): telegraph and FitzHugh–Nagumo steppers on Warp arrays.

A stepper advances control values on the device with no host round-trip inside a step: each
step is a fixed sequence of kernel launches (captured once as a graph, CUDA or Warp's CPU
graphs, and replayed), the implicit solves loop on the device (`wp.capture_while`). Every
`check_every` steps one flag is read back: NaN/Inf or a value past `blowup_limit` restores
the last good state and raises `BlowUpError` (no NaN is ever left in the state). FHN past its
bound can instead settle into a bounded period-2 flip-flop: a per-vertex detector inside each step
(`flip_kernel`: c^{n+1} - c^n alternating in sign, above a floor and not decaying, FLIP_STEPS steps
in a row) sets the same flag to FLIP_FLOP, and the check raises `OscillationError` (a
BlowUpError), state restored likewise (SPEC §8).

Stability guard: λ_max(M̃⁻¹K) comes from power iteration on the device
(`LaplaceBeltrami.largest_eigenvalue`); a `dt` past the method's bound is refused with a
ValueError stating the bound and a safe value, and `dt=None` picks `safety × bound`. The
bound is re-estimated whenever the operator's surface moves (`LaplaceBeltrami.update`).

Mass: `mass_corrections=0` is the lumped mass of SPEC §5; p > 0 replaces M⁻¹ by W_p, p
Richardson steps towards the consistent Galerkin mass (more accurate waves, smaller dt;
docs/chemistry.md).

Moving surface (SPEC §5 "Transport on the moving surface"): `move_surface(x)` moves the
operator and, with `transport="conservative"` (default), carries the chemical with the material:
every vertex keeps its amount M_I c_I (and M_I c_t, M_I w), so the discrete system is the
evolving-surface Galerkin form d/dt(M c) = ... and Σ M_I c_I changes only through the equation's
own terms. `transport="material"` keeps the control values instead (does not conserve C).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
import warp as wp

from .checks import count, finite, positive
from .device import run_steps
from .kernels import laplace as kernels_laplace
from .kernels import waves as kernels_waves
from .kernels.waves import (
    FLIP_FLOP,
    fhn_explicit_kernel,
    fhn_imex_rhs_kernel,
    fhn_inhibitor_kernel,
    flip_kernel,
    runaway_kernel,
    telegraph_kernel,
    telegraph_recentre_kernel,
    transport_kernel,
)
from .laplace import LaplaceBeltrami
from .shifted_solve import ShiftedMassSolver

FHN_SCHEMES = ("explicit", "imex")
TRANSPORTS = ("conservative", "material")
# FHN flip detector (SPEC §8; docs/chemistry.md): a vertex stops the run after FLIP_STEPS steps in a
# row whose increment d = c^{n+1} - c^n flips sign, exceeds FLIP_FLOOR × max(1, |c0|, |w0|) (float32
# round-off and the CG tolerance stay below it) and keeps |d| >= FLIP_HOLD |d^{n-1}| (same phase, two
# steps back: the alternation of a stable dt decays by its factor squared, < FLIP_HOLD below 0.9995
# of the bound).
FLIP_STEPS = 8
FLIP_FLOOR = 1e-3
FLIP_HOLD = 0.999


class BlowUpError(RuntimeError):
    """A run went non-finite or past `blowup_limit`; the stepper holds the last good state (`time`, `steps`)."""

    def __init__(self, message: str, time: float, steps: int):
        super().__init__(message)
        self.time = time
        self.steps = steps


class OscillationError(BlowUpError):
    """FHN settled into a bounded period-2 flip-flop (a dt past the stability bound that does not blow up)."""


class TimeStepError(ValueError):
    """A fixed dt exceeds the method's stability bound (at construction, or after the surface moved)."""


class _Stepper(ABC):
    """Shared machinery: dt and its guard, graph capture, blow-up detection, time keeping."""

    scheme = ""
    bound_formula = ""

    def __init__(self, operator, *, dt, safety, mass_corrections, check_dt, check_every, blowup_limit, capture,
                 transport):  # fmt: skip
        if not isinstance(operator, LaplaceBeltrami):
            raise ValueError(f"operator must be a wavewarp.LaplaceBeltrami, got {type(operator).__name__}")
        if transport not in TRANSPORTS:
            raise ValueError(f"transport must be one of {', '.join(TRANSPORTS)}, got {transport!r}")
        self.transport = transport
        self.operator = operator
        self.device, self.scalar = operator.device, operator.scalar
        self._real = np.float32 if self.scalar == wp.float32 else np.float64
        self.safety = positive("safety", safety)
        if self.safety > 1:
            raise ValueError(f"safety must lie in (0, 1], got {safety!r}")
        self.mass_corrections = count("mass_corrections", mass_corrections, 0)
        self.check_dt = bool(check_dt)
        self.check_every = count("check_every", check_every, 1)
        self._requested_dt = None if dt is None else positive("dt", dt)
        self._blowup_limit = None if blowup_limit is None else positive("blowup_limit", blowup_limit)
        self.capture = bool(capture)
        self.dt = None
        self.time = 0.0
        self.steps = 0
        self.largest_eigenvalue = None
        self._geometry_version = self._bound_version = None
        self._graphs = {}
        self._backups = None
        with wp.ScopedDevice(self.device):
            self._flag = wp.zeros(1, dtype=wp.int32)
            self._stiffness_c = wp.empty(operator.n_vertices, dtype=self.scalar)
            self._acceleration = wp.empty(operator.n_vertices, dtype=self.scalar)
            self._old_mass = wp.empty(operator.n_vertices, dtype=self.scalar)

    # ---------------------------------------------------------------- subclass interface
    @abstractmethod
    def _bound(self, eigenvalue: float) -> float:
        """The stability bound on dt for λ_max(M̃⁻¹K) = eigenvalue."""

    @abstractmethod
    def _step(self) -> None:
        """Launch one time step (no host round-trip: it is captured as a graph)."""

    @abstractmethod
    def _state(self) -> list:
        """Arrays saved before each chunk of steps and restored on blow-up."""

    @abstractmethod
    def _watched(self) -> list:
        """Arrays checked for NaN/Inf and runaway values."""

    @abstractmethod
    def _transported(self) -> list:
        """Arrays of amounts per unit area, carried by the material when the surface moves."""

    def _geometry_changed(self) -> None:
        """The surface moved and the bound and dt were refreshed (FHN IMEX rebuilds its preconditioner)."""

    # ---------------------------------------------------------------- stability guard
    @property
    def fixed_dt(self) -> bool:
        """True when dt was given (it stays as the surface moves); False when it follows the bound."""
        return self._requested_dt is not None

    @property
    def stable_dt(self) -> float:
        """The method's stability bound at the current surface (see `bound_formula`)."""
        self._update_bound()
        return self._stable_dt

    def _update_bound(self) -> None:
        if self._bound_version != self.operator.version:
            self.largest_eigenvalue = self.operator.largest_eigenvalue(self.mass_corrections)
            self._stable_dt = self._bound(self.largest_eigenvalue)
            self._bound_version = self.operator.version

    def _refresh(self) -> None:
        if self._geometry_version == self.operator.version:
            return
        self._update_bound()
        if self._requested_dt is None:
            dt = self.safety * self._stable_dt
        else:
            dt = self._requested_dt
            if self.check_dt and dt > self._stable_dt:
                raise TimeStepError(
                    f"dt = {dt:.6g} exceeds the stability bound {self._stable_dt:.6g} of the {self.scheme} "
                    f"({self.bound_formula}, λ_max(M⁻¹K) = {self.largest_eigenvalue:.6g} by power iteration): "
                    f"use dt <= {self._stable_dt:.6g}, e.g. dt = {self.safety * self._stable_dt:.6g} "
                    f"(safety {self.safety}), or dt=None to choose it automatically"
                )
        if dt != self.dt:
            self.dt = dt
            self._graphs.clear()
        self._geometry_version = self.operator.version
        self._geometry_changed()

    def change_dt(self, dt: float, recentre: bool = True) -> None:
        """Step from now on with `dt` (fixed), e.g. below a bound that the moving surface lowered.
        The telegraph's half-step velocity is re-centred to the new step (`recentre=False`: it
        already belongs to dt, as in a frame saved after a change), which keeps the leapfrog second
        order across the change. Raises TimeStepError past the current bound."""
        dt = positive("dt", dt)
        self._update_bound()
        if self.check_dt and dt > self._stable_dt:
            raise TimeStepError(f"dt = {dt:.6g} exceeds the stability bound {self._stable_dt:.6g} of the {self.scheme}")
        if recentre:
            self._recentre(self.dt, dt)
        self._requested_dt = self.dt = dt
        self._geometry_version = None  # the next step re-checks dt against the bound
        self._graphs.clear()

    def _recentre(self, old: float, new: float) -> None:
        """Move a staggered state from step `old` to step `new` (the leapfrog's half-step velocity)."""

    # ---------------------------------------------------------------- moving surface
    def move_surface(self, x) -> None:
        """Move the operator to control positions `x` ((V, 3) NumPy or a wp.array of vec3 on the device)
        and carry the chemical with it: "conservative" keeps every vertex's amount M_I c_I (c_I scales
        by M_I(old) / M_I(new), likewise c_t and w), "material" keeps the control values. Device work
        only: it may be captured inside a graph. The next step re-checks dt on the new surface."""
        conservative = self.transport == "conservative"
        if conservative:
            wp.copy(self._old_mass, self.operator.mass_device)
        self.operator.update(x)
        if conservative:
            for values in self._transported():
                wp.launch(transport_kernel, dim=len(values), inputs=[self._old_mass, self.operator.mass_device],
                          outputs=[values], device=self.device)  # fmt: skip

    # ---------------------------------------------------------------- stepping
    def _diffusion_acceleration(self, c: wp.array) -> None:
        """self._acceleration = M̃⁻¹ K c (W_p K c with p = mass_corrections)."""
        self.operator.apply_device(c, self._stiffness_c)
        self.operator.inverse_mass_device(self._stiffness_c, self._acceleration, self.mass_corrections)

    def _run(self, steps: int) -> None:
        run_steps(self._step, steps, device=self.device, graphs=self._graphs, modules=(kernels_laplace, kernels_waves),
                  capture=self.capture)  # fmt: skip

    def _check_chunk(self) -> str | None:
        """Launch the runaway checks into self._flag; return a message for other failures."""
        for values in self._watched():
            wp.launch(runaway_kernel, dim=len(values), inputs=[values, self.scalar(self.blowup_limit)],
                      outputs=[self._flag], device=self.device)  # fmt: skip
        return None

    def _chunk_error(self, steps: int, cause: str | None, coupled: str = "") -> BlowUpError | None:
        """Read the flag of a chunk of `steps` steps (after `_check_chunk`, whose message is `cause`):
        None when clear, else the error to raise once the caller has restored the state (FLIP_FLOP
        comes from FitzHughNagumo's flip detector only). `coupled` names a coupling in the message."""
        code = self._flag.numpy()[0]
        if not code:
            return None
        window = f"between t = {self.time:.6g} and t = {self.time + steps * self.dt:.6g}"
        restored = f"the state is restored to t = {self.time:.6g}"
        if code == FLIP_FLOP:
            return OscillationError(
                f"{self.scheme}{coupled} fell into a period-2 flip-flop {window}: c^(n+1) - c^n changed sign "
                f"every step for {FLIP_STEPS} steps at some vertex, above {self.flip_floor:.3g} and not decaying. "
                f"This bounded oscillation (no NaN, no runaway value) is the instability of a time step too large "
                f"for the state: dt = {self.dt:.6g} against the stability bound {self._stable_dt:.6g} "
                f"({self.bound_formula}); {restored}. Reduce dt, e.g. to {self.safety * self._stable_dt:.6g}, "
                "or use dt=None",
                self.time,
                self.steps,
            )
        return BlowUpError(
            f"{self.scheme}{coupled} blew up {window} ({cause or 'NaN/Inf or a runaway value'}; |value| limit "
            f"{self.blowup_limit:.3g}) with dt = {self.dt:.6g} (stability bound {self._stable_dt:.6g}); {restored}. "
            "Reduce dt or check the initial data",
            self.time,
            self.steps,
        )

    def advance(self, steps: int = 1):
        """Advance `steps` time steps on the device; returns self.

        Raises BlowUpError (state restored to the last good check) on NaN/Inf or values past
        `blowup_limit`, its OscillationError on FHN's period-2 flip-flop, and ValueError when the
        surface moved and a fixed dt now exceeds the bound.
        """
        steps = count("steps", steps, 0)
        self._refresh()
        if self._backups is None:
            self._backups = [wp.empty_like(a) for a in self._state()]
        backups = self._backups
        done = 0
        while done < steps:
            chunk = min(self.check_every, steps - done)
            for backup, a in zip(backups, self._state()):
                wp.copy(backup, a)
            self._flag.zero_()
            self._run(chunk)
            error = self._chunk_error(chunk, self._check_chunk())
            if error is not None:
                for backup, a in zip(backups, self._state()):
                    wp.copy(a, backup)
                raise error
            done += chunk
            self.steps += chunk
            self.time += chunk * self.dt
        return self

    def run_until(self, time: float):
        """Advance by whole steps to the first step at or after `time`; returns self."""
        time = finite("time", time)
        self._refresh()
        return self.advance(max(0, math.ceil((time - self.time) / self.dt - 1e-9)))

    def _initial(self, values, name: str) -> np.ndarray:
        return self.operator.checked_values(values, name)

    def _device_array(self, values: np.ndarray) -> wp.array:
        return wp.array(values.astype(self._real), dtype=self.scalar, device=self.device)

    def concentration(self) -> np.ndarray:
        """(V,) control values c at the current time."""
        return self.c.numpy().astype(np.float64)

    def total(self) -> float:
        """C = ∫ c dω = Σ M_I c_I on the operator's surface (lumped and consistent mass agree on it)."""
        return float(self.operator.mass() @ self.concentration())


class Telegraph(_Stepper):
    """`c_tt + α c_t = γ² Δ_LB c` by leapfrog with centred damping (SPEC §5).

    Weak form `M c_tt + α M c_t + γ² K c = 0` with state (c^n, v^{n-½}):

        v^{n+½} = [(1 - αdt/2) v^{n-½} - dt γ² M̃⁻¹K c^n] / (1 + αdt/2),   c^{n+1} = c^n + dt v^{n+½}

    stable while dt < 2 / (γ sqrt(λ_max(M̃⁻¹K))) for every α ≥ 0. `c0`, `v0` (V,) are control
    values (see `gaussian_pulse`, `steady_front`); v^{½} = v0 + dt/2 (c_tt at t = 0). On a moving
    surface (`move_surface`, conservative) this is the evolving-surface form
    d²/dt²(M c) + α d/dt(M c) + γ² K c = 0 in the amounts M c, M v: Σ M v decays by
    (1 - αdt/2)/(1 + αdt/2) per step and Σ M c follows it (`total_rate`, `telegraph_total`).
    No flip detector: the scheme is linear, so past the bound the top mode grows without limit
    (the runaway check stops it), and below it modes near ω dt = π alternate sign legitimately.
    """

    scheme = "telegraph leapfrog"
    bound_formula = "dt < 2 / (γ sqrt(λ_max))"

    def __init__(self, operator, gamma, alpha=0.001, *, c0, v0=None, dt=None, safety=0.9, mass_corrections=0,
                 check_dt=True, check_every=100, blowup_limit=None, capture=True, transport="conservative"):  # fmt: skip
        super().__init__(operator, dt=dt, safety=safety, mass_corrections=mass_corrections, check_dt=check_dt,
                         check_every=check_every, blowup_limit=blowup_limit, capture=capture,
                         transport=transport)  # fmt: skip
        self.gamma = positive("gamma", gamma)
        self.alpha = finite("alpha", alpha)
        if self.alpha < 0:
            raise ValueError(f"alpha must be >= 0 (a dissipation rate), got {alpha!r}")
        c0 = self._initial(c0, "c0")
        v0 = np.zeros_like(c0) if v0 is None else self._initial(v0, "v0")
        if self._blowup_limit is None:
            crossing_time = math.sqrt(operator.area) / self.gamma
            self._blowup_limit = 1e6 * max(1.0, np.max(np.abs(c0)), np.max(np.abs(v0)) * crossing_time)
        self.blowup_limit = self._blowup_limit
        self.c = self._device_array(c0)
        self._refresh()
        self._diffusion_acceleration(self.c)
        a0 = -(self.gamma**2) * self._acceleration.numpy().astype(np.float64) - self.alpha * v0
        half_damping = 0.5 * self.alpha * self.dt
        v_half = v0 + 0.5 * self.dt * a0
        self.v = self._device_array(((1 + half_damping) * v_half + self.dt * self.gamma**2 *
                                     self._acceleration.numpy().astype(np.float64)) / (1 - half_damping))  # fmt: skip

    def _bound(self, eigenvalue: float) -> float:
        return 2.0 / (self.gamma * math.sqrt(eigenvalue))

    def _step(self) -> None:
        self._diffusion_acceleration(self.c)
        s = self.scalar
        wp.launch(telegraph_kernel, dim=len(self.c),
                  inputs=[self._acceleration, s(self.gamma**2), s(0.5 * self.alpha * self.dt), s(self.dt)],
                  outputs=[self.c, self.v], device=self.device)  # fmt: skip

    def _recentre(self, old: float, new: float) -> None:
        self._diffusion_acceleration(self.c)
        s = self.scalar
        wp.launch(telegraph_recentre_kernel, dim=len(self.v),
                  inputs=[self._acceleration, s(self.gamma**2), s(self.alpha), s(0.5 * (old - new))], outputs=[self.v],
                  device=self.device)  # fmt: skip

    def _state(self) -> list:
        return [self.c, self.v]

    def _watched(self) -> list:
        return [self.c]

    def _transported(self) -> list:
        return [self.c, self.v]

    def velocity(self) -> np.ndarray:
        """(V,) the leapfrog velocity v^{n-½} = (c^n - c^{n-1}) / dt (control values)."""
        return self.v.numpy().astype(np.float64)

    def total_rate(self) -> float:
        """Σ M_I v_I: the rate C' of the total at t - dt/2 (the half step the leapfrog velocity belongs to)."""
        return float(self.operator.mass() @ self.velocity())


def telegraph_total(total: float, rate: float, alpha: float, dt: float, time: float) -> float:
    """The telegraph invariant (SPEC §5): C(t) = C(0) + C'(0) (1 - e^{-αt}) / α, from C'' + α C' = 0, with
    C(0) = `total` and C'(0) = `rate` e^{-α dt/2} from the leapfrog's rate Σ M v at t = -dt/2
    (`Telegraph.total_rate` before the first step). Exact for the discrete system to O(α² dt²)."""
    growth = time if alpha == 0 else -math.expm1(-alpha * time) / alpha
    return total + rate * math.exp(-0.5 * alpha * dt) * growth


def fhn_reaction_lipschitz(nu: float) -> float:
    """L_f = max over c in [0, 1] of |f'(c)|, f = c(1-c)(c-ν): f' = -3c² + 2(1+ν)c - ν."""
    candidates = [0.0, 1.0] + ([(1 + nu) / 3] if 0 <= (1 + nu) / 3 <= 1 else [])
    return max(abs(-3 * c * c + 2 * (1 + nu) * c - nu) for c in candidates)


def fhn_kinetic_period(nu=-0.01, kappa=1e-4, epsilon=0.005) -> float:
    """The limit-cycle period of the FHN kinetics without diffusion, ċ = c(1-c)(c-ν) - w,
    ẇ = ε(c - κw) (SPEC §5; ν < 0: the rest state is an unstable focus and the medium
    oscillates). The mean of the last cycles of an adaptive Runge–Kutta solve from c = 0.1;
    SPEC values: 275.7. Raises ValueError when the kinetics do not oscillate."""
    from scipy.integrate import solve_ivp

    def rates(_, y):
        c, w = y
        return [c * (1 - c) * (c - nu) - w, epsilon * (c - kappa * w)]

    horizon = 60.0 / max(epsilon, 1e-6)
    solution = solve_ivp(rates, (0.0, horizon), [0.1, 0.0], max_step=0.5, rtol=1e-9, atol=1e-12)
    c, t = solution.y[0], solution.t
    rising = (c[:-1] < 0.5) & (c[1:] >= 0.5)
    crossings = t[:-1][rising] + (0.5 - c[:-1][rising]) / (c[1:][rising] - c[:-1][rising]) * np.diff(t)[rising]
    if len(crossings) < 4:
        raise ValueError(f"the FHN kinetics (ν={nu}, κ={kappa}, ε={epsilon}) do not oscillate: no period")
    return float(np.mean(np.diff(crossings[len(crossings) // 2:])))


class FitzHughNagumo(_Stepper):
    """`c_t = γ² Δ_LB c + c(1-c)(c-ν) - w`, `w_t = ε (c - κ w)` (SPEC §5; reaction on control values).

    scheme="explicit": Euler, stable while dt < 2 / (γ² λ_max(M̃⁻¹K) + L_f), L_f the largest
    |f'| on [0, 1] (1 - ν for the SPEC's ν). scheme="imex": (M + dt γ² K) c^{n+1} =
    M (c^n + dt (f(c^n) - w^n)) by Jacobi-preconditioned CG on the device (relative tolerance
    `tol`), then w^{n+1} = (w^n + dt ε c^{n+1}) / (1 + dt ε κ): no diffusive limit, stable while
    dt < 2 / L_f (lumped mass only). Defaults are the SPEC's ν, κ, ε, γ; `w0` defaults to 0.
    Past the bound the cubic can hold the unstable mode in a bounded period-2 flip-flop instead of
    a blow-up: `flip_kernel` after each step catches it (OscillationError, module docstring).
    On a moving surface (`move_surface`, conservative): d/dt(M c) + γ² K c = M r(c, w),
    d/dt(M w) = M ε (c - κ w); `produced()` sums the reaction's amount, so C(t) = C(0) + produced().
    """

    def __init__(self, operator, gamma=0.2, nu=-0.01, kappa=1e-4, epsilon=0.005, *, c0, w0=None, dt=None,
                 scheme="explicit", safety=0.9, mass_corrections=0, tol=None, max_cg_iterations=500,
                 check_dt=True, check_every=100, blowup_limit=None, capture=True, transport="conservative"):  # fmt: skip
        if scheme not in FHN_SCHEMES:
            raise ValueError(f"scheme must be one of {', '.join(FHN_SCHEMES)}, got {scheme!r}")
        if scheme == "imex" and mass_corrections:
            raise ValueError("scheme='imex' solves with the lumped mass: mass_corrections must be 0")
        self.scheme = f"FitzHugh–Nagumo {scheme} Euler"
        self.bound_formula = "dt < 2 / (γ² λ_max + L_f)" if scheme == "explicit" else "dt < 2 / L_f"
        self.implicit = scheme == "imex"
        if self.implicit and capture and operator.device.is_cuda and not wp.is_conditional_graph_supported():
            capture = False  # the CG loop needs conditional graph nodes (CUDA 12.4+) to be captured
        super().__init__(operator, dt=dt, safety=safety, mass_corrections=mass_corrections, check_dt=check_dt,
                         check_every=check_every, blowup_limit=blowup_limit, capture=capture,
                         transport=transport)  # fmt: skip
        self.gamma = positive("gamma", gamma)
        self.nu, self.kappa = finite("nu", nu), finite("kappa", kappa)
        self.epsilon = finite("epsilon", epsilon)
        if self.epsilon < 0 or self.kappa < 0:
            raise ValueError(f"epsilon and kappa must be >= 0, got epsilon={epsilon!r}, kappa={kappa!r}")
        self.reaction_lipschitz = fhn_reaction_lipschitz(self.nu)
        c0 = self._initial(c0, "c0")
        w0 = np.zeros_like(c0) if w0 is None else self._initial(w0, "w0")
        scale = max(1.0, np.max(np.abs(c0)), np.max(np.abs(w0)))
        if self._blowup_limit is None:
            self._blowup_limit = 1e6 * scale
        self.blowup_limit = self._blowup_limit
        self.flip_floor = FLIP_FLOOR * scale
        self.c, self.w = self._device_array(c0), self._device_array(w0)
        self._previous, self._increment, self._earlier = wp.clone(self.c), wp.zeros_like(self.c), wp.zeros_like(self.c)
        self._streak = wp.zeros(len(c0), dtype=wp.int32, device=self.device)
        self._produced = wp.zeros_like(self.c)  # per vertex, the amount the reaction added (see `produced`)
        self.produced_offset = 0.0  # the amount before this stepper's steps (set_produced)
        if self.implicit:
            if tol is None:
                tol = 1e-5 if self.scalar == wp.float32 else 1e-10
            self._solver = ShiftedMassSolver(operator, positive("tol", tol), count("max_cg_iterations", max_cg_iterations, 1))
            self._rhs = wp.empty_like(self.c)
        self._refresh()

    def _bound(self, eigenvalue: float) -> float:
        if self.implicit:
            return 2.0 / self.reaction_lipschitz
        return 2.0 / (self.gamma**2 * eigenvalue + self.reaction_lipschitz)

    def _geometry_changed(self) -> None:
        if self.implicit:
            self._solver.prepare(self.dt * self.gamma**2)

    def _step(self) -> None:
        s = self.scalar
        if self.implicit:
            wp.launch(fhn_imex_rhs_kernel, dim=len(self.c),
                      inputs=[self.c, self.w, self.operator.mass_device, s(self.nu), s(self.dt)],
                      outputs=[self._rhs, self._produced], device=self.device)  # fmt: skip
            self._solver.solve(self._rhs, self.c)
            wp.launch(fhn_inhibitor_kernel, dim=len(self.c), inputs=[self.c, s(self.epsilon), s(self.kappa), s(self.dt)],
                      outputs=[self.w], device=self.device)  # fmt: skip
        else:
            self._diffusion_acceleration(self.c)
            wp.launch(fhn_explicit_kernel, dim=len(self.c),
                      inputs=[self._acceleration, self.operator.mass_device, s(self.gamma**2), s(self.nu), s(self.kappa),
                              s(self.epsilon), s(self.dt)],
                      outputs=[self.c, self.w, self._produced], device=self.device)  # fmt: skip
        wp.launch(flip_kernel, dim=len(self.c), inputs=[self.c, s(self.flip_floor), s(FLIP_HOLD), FLIP_STEPS],
                  outputs=[self._previous, self._increment, self._earlier, self._streak, self._flag],
                  device=self.device)  # fmt: skip

    def _run(self, steps: int) -> None:
        if self.implicit:
            self._solver.failed.zero_()
        super()._run(steps)

    def _check_chunk(self) -> str | None:
        super()._check_chunk()
        if self.implicit and self._solver.failed.numpy()[0]:
            self._flag.fill_(1)
            return (f"the CG solve of (M + dt γ² K) c = b missed its tolerance {self._solver.tol:g} within "
                    f"{self._solver.max_iterations} iterations; raise max_cg_iterations")  # fmt: skip
        return None

    def _state(self) -> list:
        return [self.c, self.w, self._previous, self._increment, self._earlier, self._streak, self._produced]

    def _watched(self) -> list:
        return [self.c, self.w]

    def _transported(self) -> list:
        return [self.c, self.w, self._previous]  # previous: c^n for the flip detector's increment

    def produced(self) -> float:
        """∫₀ᵗ ∫ r(c, w) dω dt: the amount the reaction r = f(c) - w has added since t = 0, summed exactly as
        the steps add it (diffusion adds none), plus `produced_offset` (a resumed run's amount so far).
        With conservative transport C(t) = C(0) + produced() to round-off (IMEX: to the CG tolerance)."""
        return self.produced_offset + float(np.sum(self._produced.numpy().astype(np.float64)))

    def set_produced(self, amount: float) -> None:
        """Start `produced()` from `amount` (a run resumed at a frame that stored it)."""
        self._produced.zero_()
        self.produced_offset = finite("amount", amount)

    def inhibitor(self) -> np.ndarray:
        """(V,) the inhibitor w (control values)."""
        return self.w.numpy().astype(np.float64)
