"""Chemistry solvers (docs/theory/chemistry.md): the telegraph and FitzHugh–Nagumo time steps on a
`LaplaceBeltrami` operator, advancing a `State` with `step(state_in, state_out, dt)`.

A solver holds what the model and the operator's current surface fix (parameters, scratch arrays,
the stability bound of the surface) and no evolving state: c, c_t (`rate`) or w and the FHN
detector's history live in the State. A step is a fixed sequence of kernel launches with no host
round-trip, so it can be captured inside a graph. `move_surface(state, x)` moves the operator to a
deformed shell and carries the chemical with the material (docs/theory/transport.md).

Mass: `mass_corrections=0` is the lumped mass; p > 0 replaces M⁻¹ by W_p, p Richardson steps towards
the consistent Galerkin mass (docs/theory/chemistry.md).
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod

import numpy as np
import warp as wp

from .checks import count, finite, plain, positive
from .kernels.waves import (
    eval_fhn_explicit,
    eval_fhn_heun_corrector,
    eval_fhn_heun_predictor,
    eval_fhn_imex_rhs,
    eval_fhn_inhibitor,
    eval_flip,
    eval_runaway,
    eval_telegraph,
    eval_telegraph_recentre,
    eval_transport,
)
from .laplace import LaplaceBeltrami
from .shifted_solve import ShiftedMassSolver
from .state import State

FHN_SCHEMES = ("explicit", "heun", "imex")
TRANSPORTS = ("conservative", "material")
# FHN flip detector (docs/theory/chemistry.md): a vertex stops the run after FLIP_STEPS steps in a row
# whose increment d = c^{n+1} - c^n flips sign, exceeds FLIP_FLOOR × max(1, |c0|, |w0|) (float32
# round-off and the CG tolerance stay below it) and keeps |d| >= FLIP_HOLD |d^{n-1}| (same phase, two
# steps back: the alternation of a stable dt decays by its factor squared, < FLIP_HOLD below 0.9995
# of the bound).
FLIP_STEPS = 8
FLIP_FLOOR = 1e-3
FLIP_HOLD = 0.999


class ChemistrySolver(ABC):
    """Shared machinery of the chemistry solvers: the operator, the diffusion term, the stability bound
    of the operator's current surface, the transport across surface moves, the runaway checks."""

    scheme = ""
    bound_formula = ""

    def __init__(self, operator, *, mass_corrections=0, transport="conservative"):
        if not isinstance(operator, LaplaceBeltrami):
            raise ValueError(f"operator must be a wavewarp.LaplaceBeltrami, got {type(operator).__name__}")
        if transport not in TRANSPORTS:
            raise ValueError(f"transport must be one of {', '.join(TRANSPORTS)}, got {transport!r}")
        self.operator, self.transport = operator, transport
        self.device, self.scalar = operator.device, operator.scalar
        self._real = np.float32 if self.scalar == wp.float32 else np.float64
        self.mass_corrections = count("mass_corrections", mass_corrections, 0)
        self.largest_eigenvalue, self._stable_dt, self._bound_version = None, None, None
        n = operator.n_vertices
        with wp.ScopedDevice(self.device):
            self.flag = wp.zeros(operator.mesh.worlds, dtype=wp.int32)  # one per world
            self._stiffness_c = wp.empty(n, dtype=self.scalar)
            self.acceleration = wp.empty(n, dtype=self.scalar)
            self._old_mass = wp.empty(n, dtype=self.scalar)

    # ---------------------------------------------------------------- what a subclass provides
    @abstractmethod
    def _bound(self, eigenvalue: float) -> float:
        """The stability bound on dt for λ_max(M̃⁻¹K) = eigenvalue."""

    @abstractmethod
    def step(self, state_in: State, state_out: State, dt: float) -> None:
        """Advance state_in by dt into state_out (the same object: in place). Device work only."""

    @abstractmethod
    def transported(self, state: State) -> list:
        """The state's arrays of amounts per unit area, carried by the material when the surface moves."""

    @abstractmethod
    def watched(self, state: State) -> list:
        """The state's arrays checked for NaN/Inf and runaway values."""

    def prepare(self, dt: float) -> None:
        """Host-side preparation for steps of dt on the current surface (FHN IMEX: its preconditioner)."""

    def reset_checks(self) -> None:
        """Clear the flag a chunk of steps sets."""
        self.flag.zero_()

    # ---------------------------------------------------------------- the surface and its bound
    def stable_dt(self, last_if_broken: bool = False) -> float:
        """The method's stability bound on the operator's current surface (see `bound_formula`): λ_max(M̃⁻¹K)
        by power iteration on the device, estimated again whenever the surface moved. `last_if_broken`:
        the last bound where the surface went non-finite (a blow-up's message)."""
        if last_if_broken and self._stable_dt is not None:
            try:
                return self.stable_dt()
            except RuntimeError:
                return self._stable_dt
        if self._bound_version != self.operator.version:
            self.largest_eigenvalue = self.operator.largest_eigenvalue(self.mass_corrections)
            self._stable_dt = self._bound(self.largest_eigenvalue)
            self._bound_version = self.operator.version
        return self._stable_dt

    def world_stable_dts(self, worlds: int) -> np.ndarray:
        """Each batched world's own stability bound on the operator's current surface (host-driven power
        iteration per world: names the world whose surface lowered the batch's `stable_dt`)."""
        eigenvalues = self.operator.world_largest_eigenvalues(worlds, self.mass_corrections)
        return np.array([self._bound(float(value)) for value in eigenvalues])

    def move_surface(self, state: State, x) -> None:
        """Move the operator to control positions `x` ((V, 3) NumPy or a wp.array of vec3 on the device)
        and carry the state's chemical with it: "conservative" keeps every vertex's amount M_I c_I (c_I
        scales by M_I(old) / M_I(new), likewise c_t and w), "material" keeps the control values. Device
        work only: it may be captured inside a graph."""
        conservative = self.transport == "conservative"
        if conservative:
            wp.copy(self._old_mass, self.operator.mass_device)
        self.operator.update(x)
        if conservative:
            for values in self.transported(state):
                eval_transport(self._old_mass, self.operator.mass_device, values)

    # ---------------------------------------------------------------- pieces of a step
    def diffusion_acceleration(self, c: wp.array) -> None:
        """self.acceleration = M̃⁻¹ K c (W_p K c with p = mass_corrections)."""
        self.operator.apply_device(c, self._stiffness_c)
        self.operator.inverse_mass_device(self._stiffness_c, self.acceleration, self.mass_corrections)

    def launch_checks(self, state: State, limit: float) -> str | None:
        """Launch the runaway checks of the watched arrays into `flag`; return a message for failures
        found otherwise (FHN IMEX: its CG missed the tolerance), else None."""
        for values in self.watched(state):
            eval_runaway(values, limit, self.flag)
        return None

    @staticmethod
    def _copy_fields(state_in: State, state_out: State) -> None:
        if state_out is not state_in:
            state_out.assign(state_in)

    def _array(self, values) -> wp.array:
        return wp.array(np.asarray(values).astype(self._real), dtype=self.scalar, device=self.device)


class TelegraphSolver(ChemistrySolver):
    """`c_tt + α c_t = γ² Δ_LB c` by leapfrog with centred damping (docs/theory/chemistry.md).

    Weak form `M c_tt + α M c_t + γ² K c = 0` with state (c^n, v^{n-½}) in `state.c`, `state.rate`:

        v^{n+½} = [(1 - αdt/2) v^{n-½} - dt γ² M̃⁻¹K c^n] / (1 + αdt/2),   c^{n+1} = c^n + dt v^{n+½}

    stable while dt < 2 / (γ sqrt(λ_max(M̃⁻¹K))) for every α ≥ 0. On a moving surface (conservative
    transport) this is the evolving-surface form d²/dt²(M c) + α d/dt(M c) + γ² K c = 0 in the amounts
    M c, M v: Σ M v decays by (1 - αdt/2)/(1 + αdt/2) per step and Σ M c follows it.
    """

    scheme = "telegraph leapfrog"
    bound_formula = "dt < 2 / (γ sqrt(λ_max))"

    def __init__(self, operator, gamma, alpha=0.001, *, mass_corrections=0, transport="conservative"):
        super().__init__(operator, mass_corrections=mass_corrections, transport=transport)
        self.gamma = positive("gamma", gamma)
        self.alpha = finite("alpha", alpha)
        if self.alpha < 0:
            raise ValueError(f"alpha must be >= 0 (a dissipation rate), got {plain(alpha)!r}")

    def _bound(self, eigenvalue: float) -> float:
        return 2.0 / (self.gamma * math.sqrt(eigenvalue))

    def state(self, c0: np.ndarray, v0: np.ndarray, dt: float) -> State:
        """The state at t = 0 for steps of dt: c0 and the half-step rate v^{-½} that makes the first step's
        v^{½} = v0 + dt/2 c_tt(0) (control values on the operator's current surface)."""
        c = self._array(c0)
        self.diffusion_acceleration(c)
        acceleration = self.acceleration.numpy().astype(np.float64)
        a0 = -(self.gamma**2) * acceleration - self.alpha * v0
        half_damping = 0.5 * self.alpha * dt
        v_half = v0 + 0.5 * dt * a0
        rate = ((1 + half_damping) * v_half + dt * self.gamma**2 * acceleration) / (1 - half_damping)
        return State(c=c, rate=self._array(rate))

    def step(self, state_in: State, state_out: State, dt: float) -> None:
        self._copy_fields(state_in, state_out)
        self.diffusion_acceleration(state_out.c)
        eval_telegraph(self.acceleration, self.gamma, self.alpha, dt, state_out.c, state_out.rate)

    def recentre(self, state: State, old: float, new: float) -> None:
        """Move the half-step rate from t_n - old/2 to t_n - new/2 (a change of dt): the variable-step leapfrog."""
        self.diffusion_acceleration(state.c)
        eval_telegraph_recentre(self.acceleration, self.gamma, self.alpha, old, new, state.rate)

    def transported(self, state: State) -> list:
        return [state.c, state.rate]

    def watched(self, state: State) -> list:
        return [state.c]


def telegraph_total(total: float, rate: float, alpha: float, dt: float, time: float) -> float:
    """The telegraph invariant: C(t) = C(0) + C'(0) (1 - e^{-αt}) / α, from C'' + α C' = 0, with C(0) =
    `total` and C'(0) = `rate` e^{-α dt/2} from the leapfrog's rate Σ M v at t = -dt/2 (before the
    first step). Exact for the discrete system to O(α² dt²)."""
    growth = time if alpha == 0 else -math.expm1(-alpha * time) / alpha
    return total + rate * math.exp(-0.5 * alpha * dt) * growth


def fhn_reaction_lipschitz(nu: float) -> float:
    """L_f = max over c in [0, 1] of |f'(c)|, f = c(1-c)(c-ν): f' = -3c² + 2(1+ν)c - ν."""
    candidates = [0.0, 1.0] + ([(1 + nu) / 3] if 0 <= (1 + nu) / 3 <= 1 else [])
    return max(abs(-3 * c * c + 2 * (1 + nu) * c - nu) for c in candidates)


@functools.lru_cache(maxsize=64)
def fhn_kinetic_period(nu=-0.01, kappa=1e-4, epsilon=0.005) -> float:
    """The limit-cycle period of the FHN kinetics without diffusion, ċ = c(1-c)(c-ν) - w,
    ẇ = ε(c - κw) (ν < 0: the rest state is an unstable focus and the medium oscillates). The mean of
    the last cycles of an adaptive Runge–Kutta solve from c = 0.1; default values: 275.7. Raises
    ValueError when the kinetics do not oscillate. Kept per (ν, κ, ε): every walker built asks for it."""
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


class FitzHughNagumoSolver(ChemistrySolver):
    """`c_t = γ² Δ_LB c + c(1-c)(c-ν) - w`, `w_t = ε (c - κ w)` (reaction on control values).

    scheme="explicit": Euler, stable while dt < 2 / (γ² λ_max(M̃⁻¹K) + L_f), L_f the largest |f'| on
    [0, 1]. scheme="heun": Heun's second-order Runge–Kutta step (an Euler predictor, then the trapezoid of its two
    rates), the same bound (its stability interval on the real axis is Euler's [-2, 0]) at two operator applications
    a step; the walkers' front speed is first order in dt under Euler (docs/theory/chemistry.md). scheme="imex": (M + dt γ² K) c^{n+1} = M (c^n + dt (f(c^n) - w^n)) by Jacobi-preconditioned
    CG on the device (relative tolerance `tol`), then w^{n+1} = (w^n + dt ε c^{n+1}) / (1 + dt ε κ): no
    diffusive limit, stable while dt < 2 / L_f (lumped mass only). After each step a per-vertex detector
    (`flip_kernel`) flags a bounded period-2 flip-flop, the instability of a dt past the bound that does
    not blow up. The state carries w, the detector's history and `produced`, the amount the reaction
    has added per vertex (so C(t) = C(0) + Σ produced with conservative transport).
    """

    def __init__(self, operator, gamma=0.2, nu=-0.01, kappa=1e-4, epsilon=0.005, *, scheme="explicit",
                 mass_corrections=0, tol=None, max_cg_iterations=500, transport="conservative"):  # fmt: skip
        if scheme not in FHN_SCHEMES:
            raise ValueError(f"scheme must be one of {', '.join(FHN_SCHEMES)}, got {scheme!r}")
        if scheme == "imex" and mass_corrections:
            raise ValueError("scheme='imex' solves with the lumped mass: mass_corrections must be 0")
        super().__init__(operator, mass_corrections=mass_corrections, transport=transport)
        self.scheme = {"explicit": "FitzHugh–Nagumo explicit Euler", "heun": "FitzHugh–Nagumo Heun (RK2)",
                       "imex": "FitzHugh–Nagumo imex Euler"}[scheme]
        self.bound_formula = "dt < 2 / L_f" if scheme == "imex" else "dt < 2 / (γ² λ_max + L_f)"
        self.heun = scheme == "heun"
        self.implicit = scheme == "imex"
        self.gamma = positive("gamma", gamma)
        self.nu, self.kappa = finite("nu", nu), finite("kappa", kappa)
        self.epsilon = finite("epsilon", epsilon)
        if self.epsilon < 0 or self.kappa < 0:
            raise ValueError(f"epsilon and kappa must be >= 0, got epsilon={plain(epsilon)!r}, kappa={plain(kappa)!r}")
        self.reaction_lipschitz = fhn_reaction_lipschitz(self.nu)
        self.flip_floor = FLIP_FLOOR
        if self.implicit:
            if tol is None:
                tol = 1e-5 if self.scalar == wp.float32 else 1e-10
            self.cg = ShiftedMassSolver(operator, positive("tol", tol), count("max_cg_iterations", max_cg_iterations, 1))
            self._rhs = wp.empty(operator.n_vertices, dtype=self.scalar, device=self.device)
        if self.heun:  # the predictor c̃, w̃ and the rates at step n
            self._stage = [wp.empty(operator.n_vertices, dtype=self.scalar, device=self.device) for _ in range(4)]

    def _bound(self, eigenvalue: float) -> float:
        if self.implicit:
            return 2.0 / self.reaction_lipschitz
        return 2.0 / (self.gamma**2 * eigenvalue + self.reaction_lipschitz)

    def state(self, c0: np.ndarray, w0: np.ndarray) -> State:
        """The state at t = 0: c0, w0, the flip detector's history and the produced amounts at zero. The
        detector's floor scales with max(1, |c0|, |w0|)."""
        self.flip_floor = FLIP_FLOOR * max(1.0, np.max(np.abs(c0)), np.max(np.abs(w0)))
        c, w = self._array(c0), self._array(w0)
        zeros = [wp.zeros_like(c) for _ in range(3)]
        history = {"previous": wp.clone(c), "increment": zeros[0], "earlier": zeros[1],
                   "streak": wp.zeros(len(c0), dtype=wp.int32, device=self.device), "produced": zeros[2]}  # fmt: skip
        return State(c=c, w=w, history=history)

    def prepare(self, dt: float) -> None:
        if self.implicit:
            self.cg.prepare(dt * self.gamma**2)

    def step(self, state_in: State, state_out: State, dt: float) -> None:
        self._copy_fields(state_in, state_out)
        c, w, h = state_out.c, state_out.w, state_out.history
        if self.implicit:
            eval_fhn_imex_rhs(c, w, self.operator.mass_device, self.nu, dt, self._rhs, h["produced"])
            self.cg.solve(self._rhs, c)
            eval_fhn_inhibitor(c, self.epsilon, self.kappa, dt, w)
        elif self.heun:
            mass, c_stage, w_stage, rate_c, rate_w = self.operator.mass_device, *self._stage
            self.diffusion_acceleration(c)
            eval_fhn_heun_predictor(self.acceleration, mass, self.gamma, self.nu, self.kappa, self.epsilon, dt, c, w,
                                    c_stage, w_stage, rate_c, rate_w, h["produced"])
            self.diffusion_acceleration(c_stage)
            eval_fhn_heun_corrector(self.acceleration, mass, self.gamma, self.nu, self.kappa, self.epsilon, dt, c_stage,
                                    w_stage, rate_c, rate_w, c, w, h["produced"])
        else:
            self.diffusion_acceleration(c)
            eval_fhn_explicit(self.acceleration, self.operator.mass_device, self.gamma, self.nu, self.kappa, self.epsilon,
                              dt, c, w, h["produced"])  # fmt: skip
        eval_flip(c, self.flip_floor, FLIP_HOLD, FLIP_STEPS, h["previous"], h["increment"], h["earlier"], h["streak"],
                  self.flag)  # fmt: skip

    def launch_checks(self, state: State, limit: float) -> str | None:
        super().launch_checks(state, limit)
        if self.implicit and self.cg.failed.numpy()[0]:
            self.flag.fill_(1)
            return (f"the CG solve of (M + dt γ² K) c = b missed its tolerance {self.cg.tol:g} within "
                    f"{self.cg.max_iterations} iterations; raise max_cg_iterations")  # fmt: skip
        return None

    def reset_checks(self) -> None:
        """Clear the flags a chunk of steps sets (FHN IMEX: its CG's failure flag too)."""
        super().reset_checks()
        if self.implicit:
            self.cg.failed.zero_()

    def transported(self, state: State) -> list:
        return [state.c, state.w, state.history["previous"]]  # previous: c^n for the flip detector's increment

    def watched(self, state: State) -> list:
        return [state.c, state.w]
