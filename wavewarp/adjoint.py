"""Reverse mode through a walker's walk, with checkpoints (docs/theory/gradients.md, "Reverse mode").

The walk the adjoint covers: overdamped mechanics (v' = F/(ζM), x' = x + dt v'), the contact on the limit points or
per area, explicit with a smooth friction law (k_f finite: the paper's) or implicit with any k_f (Coulomb's law, the
scenes' default: its adjoint in wavewarp/adjoint_contact.py) with the drag in the lab or the body frame, the Koiter
or the bilayer shell, the sensitive wave (the scenes' default: the chemistry on the moving surface, taken back by
wavewarp/adjoint_wave.py with the ĉ the substeps' references hand it) or the insensitive one (the same on the fixed
rest surface), one world, float64. The objective is the walk's J, the centre of mass's displacement along the wave in R
from the walk's start to its end. One pass back gives dJ/dθ for every parameter of `ADJOINT_PARAMETERS` asked for and
dJ/d(x₀, v₀, c₀, w₀) of the start state, whatever their number.

Per mechanics substep, backwards: ŵ = v̂' + dt x̂', F̂ = ŵ/(ζM); the shell's x̂ += (∂F/∂x)ᵀF̂ = -H F̂ (H symmetric:
the central difference of the forces along F̂); the ground's law at the limit points is differentiated by hand
(kernels/adjoint_contact.py) and reaches x̂, v̂ through Lᵀ; the shell's parameters by F̂ · ∂F/∂θ = -∂Ė/∂θ, Ė the
energy's rate of change along F̂, whose terms one pass over the quadrature points gives with their derivatives in AC
and AI (Y scales every term, h the stretching and volume once and the bending thrice, μV the volume term). The
rigid-body correction of the forces' round-off (kernels/dynamics.py) has zero derivative: the net force and torque
of F vanish at every x.

The whole run: back through the settling too, replayed from the placement (its overdamped phase by the same
adjoint, its inertial phase by symplectic Euler's with the damping toward the rigid-body motion) and the placement's
depth, which the contact stiffness sets.

Checkpoints: the coupled state every K chemistry steps (K of order √N, N the steps, chosen for the fewest bytes), each
stretch of K steps run again from its checkpoint, storing its substeps' (x, v), and then taken backwards: O(√N)
states, one extra forward run.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import warp as wp

from . import kernels
from .adjoint_contact import ImplicitContactAdjoint
from .adjoint_settling import SettlingAdjoint
from .adjoint_shape import RestShapeAdjoint, check_rest_shape
from .adjoint_wave import WaveAdjoint
from .coupled import GRAPH_SUBSTEPS
from .device import mat22, run_steps
from .gradients import control_points
from .initial import gaussian_pulse_adjoint
from .kernels import check_one_device
from .kernels.adjoint import (
    ShellRates,
    eval_area_scale,
    eval_count,
    eval_damping_adjoint,
    eval_directional_derivative,
    eval_pull,
    eval_push,
    eval_scaled_inverse_mass,
    eval_shell_parameter_gradient,
    eval_step_adjoint,
    eval_weighted_dot,
)
from .kernels.adjoint_contact import eval_ground_adjoint
from .kernels.adjoint_shape import eval_point_weight_share
from .kernels.contact import ground_motion, spread_to_control_points
from .kernels.dynamics import eval_reference_ramp
from .walker_gradients import WalkerGradientError

SHELL_PARAMETERS = ("AC", "AI", "thickness", "young", "mu_v")
GROUND_PARAMETERS = ("stiffness", "contact_damping", "friction", "sharpness")  # kernels/adjoint_contact.py's slots
SHAPE_PARAMETERS = ("elongation",)  # through the rest shape's gradient (wavewarp/adjoint_shape.py)
ADJOINT_PARAMETERS = SHELL_PARAMETERS + GROUND_PARAMETERS + ("drag",) + SHAPE_PARAMETERS
SETTLE_FREE = ("AC", "AI")  # the walk's start (settled at c = 0) does not depend on them
ACTION_STEP = 1e-4  # the Hessian action's central difference, in mean edges along the direction's largest component (1e-5: round-off)
MODULES = (kernels.laplace, kernels.waves, kernels.shell, kernels.contact, kernels.implicit_contact, kernels.dynamics, kernels.limit_surface,
           kernels.reduce, kernels.adjoint, kernels.adjoint_contact, kernels.adjoint_wave)  # what a walk and its adjoint launch


def rate_factors(p) -> np.ndarray:
    """Rows AC, AI, h, Y, μV (SHELL_PARAMETERS' slots) of ∂Ė/∂θ's weights on `Shell.rates_device`'s (Ė_S, Ė_B, Ė_V,
    ∂/∂AC, ∂/∂AI): the stretching modulus and the volume penalty go as Y h, the bending modulus as Y h³, the penalty
    as μV."""
    factors = np.zeros((len(SHELL_PARAMETERS), 5))
    factors[0, 3] = factors[1, 4] = 1.0
    factors[2, :3] = np.array([1.0, 3.0, 1.0]) / p.thickness
    factors[3, :3] = 1.0 / p.young
    factors[4, 2] = 1.0 / p.mu_v if p.mu_v else 0.0
    return factors


def check_adjoint_walk(p, wrt) -> None:
    """Raise WalkerGradientError, naming the fix, where the reverse mode does not cover a walker of parameters `p`
    or the parameters `wrt`."""
    unknown = [name for name in wrt if name not in ADJOINT_PARAMETERS]
    if unknown:
        raise WalkerGradientError(f"--wrt {','.join(unknown) or '(nothing)'}: the reverse mode differentiates "
                                  f"{', '.join(ADJOINT_PARAMETERS)} (central differences take the rest: --method "
                                  "differences)")  # fmt: skip
    if p.mechanics != "overdamped":
        raise WalkerGradientError("the reverse mode covers the overdamped walk; set mechanics=overdamped, or take "
                                  "central differences (--method differences)")  # fmt: skip
    if p.sensitive and p.dt == 0:
        raise WalkerGradientError("dt = auto follows the settled surface's stability bound, which the sensitive wave's "
                                  "parameters move: give the chemistry step a value (--set dt=0.5)")  # fmt: skip
    if "sharpness" in wrt and math.isinf(p.sharpness):
        raise WalkerGradientError("sharpness = inf is Coulomb's law, which has no derivative in k_f: --set "
                                  "sharpness=1e4 walks as Coulomb does")  # fmt: skip
    if "contact_damping" in wrt and p.drag == 0:
        raise WalkerGradientError("drag = 0 (automatic) follows the contact damping β (2 η_ground): give the drag a "
                                  "value (--set drag=...) to differentiate β")  # fmt: skip
    if "mu_v" in wrt and p.mu_v == 0:
        raise WalkerGradientError("mu_v = 0: the model has no volume term to differentiate; give mu_v > 0")
    if any(name in SHAPE_PARAMETERS for name in wrt):
        check_rest_shape(p)


def check_adjoint_shell(shell) -> None:
    """Raise WalkerGradientError where the reverse mode does not cover `shell` (its model, dtype, worlds)."""
    needs = [(shell.scalar != wp.float64, "dtype=float64"), (shell.worlds != 1, "one world")]
    missing = [fix for needed, fix in needs if needed]
    if missing:
        raise WalkerGradientError(f"the reverse mode needs {'; '.join(missing)} (--method differences takes the rest)")


def checkpoint_spacing(steps: int, substeps: int, checkpoint_bytes: int, row_bytes: int, step_bytes: int) -> int:
    """The chemistry steps K between checkpoints that hold the fewest bytes over N = `steps`: ⌈N/K⌉ checkpoints of
    `checkpoint_bytes` and a stretch of K·S + 1 stored substeps of `row_bytes` ((x, v)) and K + 1 steps of
    `step_bytes` ((c, w)). K is of order √(N · checkpoint / (S · row)), the bytes of order √N."""

    def held(every):
        return math.ceil(steps / every) * checkpoint_bytes + (every * substeps + 1) * row_bytes + (every + 1) * step_bytes

    return min(range(1, steps + 1), key=held)


class WalkAdjoint(SettlingAdjoint, RestShapeAdjoint):
    """dJ/dθ and dJ/d(x₀, v₀) of a `WalkerRun`'s walk from its current state (module docstring). `wrt`: names of
    `ADJOINT_PARAMETERS`; `checkpoint_every`: chemistry steps between checkpoints (None: `checkpoint_spacing`'s);
    `rest_forms`: also dJ/dā⁰ and dJ/db̄⁰, the shell's rest metric and curvature at every quadrature point (the rest
    forms' share of a rest shape's gradient: its mass, volume and placement held); `rest_shape`: also dJ/dX of the
    whole run, X the control points of the run's mesh (wavewarp/adjoint_shape.py; implies `rest_forms`)."""

    def __init__(self, run, wrt=(), checkpoint_every=None, rest_forms: bool = False, rest_shape: bool = False):
        check_adjoint_walk(run.p, wrt)
        check_adjoint_shell(run.shell)
        check_one_device("WalkAdjoint", shell=run.shell, operator=run.operator, wave=run.wave.c, x=run.dynamics.state.x)
        rest_shape = rest_shape or any(name in SHAPE_PARAMETERS for name in wrt)
        if rest_shape:
            check_rest_shape(run.p)
        rest_forms = rest_forms or rest_shape
        self.run, self.wrt = run, list(wrt)
        self.checkpoint_every = checkpoint_every
        self.wave, self.dynamics, self.shell = run.wave, run.dynamics, run.shell
        self.solver, self.coupled = run.dynamics.solver, run.coupled
        shell, n = self.shell, run.mesh.n_vertices
        forward = np.asarray(run.forward, dtype=np.float64)
        seed = np.outer(self.dynamics.mass / (self.dynamics.total_mass * run.radius), forward)
        with wp.ScopedDevice(shell.device):
            self._seed = wp.array(seed, dtype=shell.vec3)
            self._scratch = {name: wp.zeros(n, dtype=shell.vec3) for name in
                             ("x_hat", "v_hat", "w_hat", "force_hat", "probe", "plus", "minus",
                              "x", "v", "v_next", "v_star", "a_ctrl", "v_star_hat", "x_step",
                              "x_step_end")}  # fmt: skip
            points = self.solver.ground_points  # the ground's: limit points, or quadrature points (area contact)
            self._points = {name: wp.zeros(points, dtype=shell.vec3) for name in
                            ("p", "u", "a", "unused", "p_hat", "u_hat", "u_star_hat")}  # fmt: skip
            self._patch, area = self.solver.ground_tables()
            self._area = area  # dω̄⁰ at the quadrature points (area contact), None on limit points
            self._unit_area = None if area is None else wp.ones(points, dtype=shell.scalar)
            self._counters = {"step": wp.zeros(1, dtype=wp.int32), "substep": wp.zeros(1, dtype=wp.int32)}
            self._c_start, self._c_end = wp.empty_like(self.wave.c), wp.empty_like(self.wave.c)
            self._w_start = wp.empty_like(self.wave.c)
            self._largest = wp.zeros(1, dtype=wp.float64)
            self._shell_gradient = wp.zeros(len(SHELL_PARAMETERS) + 1, dtype=wp.float64)  # + drag
            self._ground_gradient = wp.zeros(len(GROUND_PARAMETERS), dtype=wp.float64)
            self._c_ramp = wp.empty_like(self.wave.c)
            self._rates = wp.zeros(1, dtype=ShellRates)
            self._factors = wp.array(rate_factors(run.p), dtype=wp.float64)
            self._mass = wp.array(self.dynamics.mass, dtype=wp.float64)
            self._damping_sums = wp.zeros(3, dtype=wp.vec3d)
            self._damping_moment = wp.zeros(1, dtype=wp.mat33d)
        self.capture = run.dynamics.capture and run.wave.capture
        self._graphs = {}
        self._stiffness_placement = 0.0  # the stiffness's share through the placement depth
        self._settling = None  # the settling's inertial solver and replay state, made on first use
        self._contacts = {}  # solver id -> its implicit contact's adjoint (ImplicitContactAdjoint)
        if self.solver.implicit:
            self._contact_of(self.solver)
        self._xs = self._vs = self._cs = self._ws = None  # the stretch's stored rows, allocated by `gradient`
        self.sensitive = bool(run.p.sensitive)
        self._wave_adjoint = WaveAdjoint(self.wave, shell.tables, moving=self.sensitive)
        self._ramp = 1.0  # the reference's share of c_end at the substep being taken back
        self._reference_adjoint = False  # the walk's substeps hand ĉ back to the wave (not the settling's)
        with wp.ScopedDevice(shell.device):  # the insensitive wave's surface, and its shape's adjoint
            self._rest_x = wp.array(run.mesh.vertices, dtype=shell.vec3)
            self._rest_operator_hat = wp.zeros(n, dtype=shell.vec3)
        points, m22 = shell.tables.n_quadrature_points, mat22(wp.float64)
        self._rest_forms_hat = (wp.zeros(points, dtype=m22, device=shell.device),
                                wp.zeros(points, dtype=m22, device=shell.device)) if rest_forms else None  # fmt: skip
        self._rest_volume_hat = wp.zeros(1, dtype=wp.float64, device=shell.device)
        self._mass_hat = wp.zeros(n, dtype=wp.float64, device=shell.device) if rest_shape else None  # M̂
        per_area = rest_shape and self._area is not None  # the area contact's weights' adjoint â
        self._weight_hat = wp.zeros(len(self._area), dtype=wp.float64, device=shell.device) if per_area else None

    # ---------------------------------------------------------------- the forward walk
    def _state_arrays(self) -> list:
        return self.wave.state.arrays() + [self.dynamics.state.x, self.dynamics.state.v]

    def _place_surface(self) -> None:
        """The sensitive wave's operator at the shell's positions (as the run holds it between steps)."""
        if self.sensitive:
            self.wave.operator.update(self.dynamics.state.x)

    def _set_reference(self, k: int) -> None:
        """The active reference before substep k (1…S) of the chemistry step from c_start to c_end (`Walking._step`)."""
        self._ramp = k / self.coupled.substeps if self.coupled.ramp else 1.0
        if self.coupled.ramp:
            eval_reference_ramp(self._c_start, self._c_end, k / self.coupled.substeps, self._c_ramp)
            self.shell.update_reference(self._c_ramp)
        else:
            self.shell.update_reference(self._c_end)

    def _coupled_step(self, store: bool = False) -> None:
        """One chemistry step and its mechanics substeps as `Walking._step` takes them, the sensitive wave then moved to
        the new surface. `store`: c (and w) before the step and (x, v) before each substep pushed at the device's
        counters (the stretch's rows)."""
        wave, d, counters = self.wave, self.dynamics, self._counters
        wp.copy(self._c_start, wave.c)
        if store:
            eval_push(wave.c, counters["step"], self._cs)
            eval_push(wave.state.w, counters["step"], self._ws)
            eval_count(counters["step"], 1)
        wave.solver.step(wave.state, wave.state, wave.dt)
        wp.copy(self._c_end, wave.c)
        for k in range(1, self.coupled.substeps + 1):
            if store:
                self._push_mechanics()
            self._set_reference(k)
            d.solver.step(d.state, d.state, d.dt)
        if self.sensitive:
            wave.solver.move_surface(wave.state, d.state.x)

    def _push_mechanics(self) -> None:
        counter = self._counters["substep"]
        eval_push(self.dynamics.state.x, counter, self._xs)
        eval_push(self.dynamics.state.v, counter, self._vs)
        eval_count(counter, 1)

    def _run(self, step, steps: int, kind, substeps=None) -> None:
        """`steps` calls of `step` as captured graphs (CUDA, or Warp's CPU graph) of at most GRAPH_SUBSTEPS substeps
        (`substeps` a call; default the walk's)."""
        run_steps(step, steps, device=self.shell.device, graphs=self._graphs.setdefault(kind, {}), modules=MODULES,
                  capture=self.capture, graph_steps=max(1, GRAPH_SUBSTEPS // (substeps or self.coupled.substeps)))

    def _ensure_rows(self, rows: int, steps: int = 0) -> None:
        """Room for `rows` stored (x, v) and `steps` + 1 stored c; the captured graphs, which hold the old rows, are
        dropped when they grow."""
        if self._xs is None or len(self._xs) < rows or len(self._cs) < steps + 1:
            rows, steps = max(rows, 0 if self._xs is None else len(self._xs)), max(steps, 0 if self._cs is None else len(self._cs) - 1)
            with wp.ScopedDevice(self.shell.device):
                self._xs = wp.empty((rows, self.run.mesh.n_vertices), dtype=self.shell.vec3)
                self._vs = wp.empty_like(self._xs)
                self._cs = wp.empty((steps + 1, self.run.mesh.n_vertices), dtype=self.shell.scalar)
                self._ws = wp.empty_like(self._cs)
            self._graphs.clear()

    def centre(self) -> float:
        """The centre of mass along the wave, in R."""
        return float(self.dynamics.center_of_mass() @ self.run.forward) / self.run.radius

    def walk(self, steps: int) -> float:
        """Advance the run `steps` chemistry steps as its own coupled steps do; returns J (the distance walked, in R)."""
        start = self.centre()
        self._place_surface()
        self._run(self._coupled_step, int(steps), "forward")
        self._advance_clocks(steps)
        return self.centre() - start

    def _advance_clocks(self, steps: int) -> None:
        wave, d = self.wave, self.dynamics
        wave.steps += steps
        wave.time += steps * wave.dt
        d.steps += steps * self.coupled.substeps
        d.time += steps * self.coupled.substeps * d.dt

    # ---------------------------------------------------------------- the gradient
    def gradient(self, steps: int, settle: bool = False) -> dict:
        """Walk `steps` chemistry steps from the current state (leaving the run at the end), then back: {"objective":
        J, "gradient": {name: dJ/dθ}, "start": {"x": dJ/dx₀, "v": dJ/dv₀ (V × 3 NumPy, at the walk's start), "c":
        dJ/dc₀, "w": dJ/dw₀ (V)}, "steps", "substeps", "checkpoint_every", "checkpoints", "stored_substeps" (the most
        held at once), "state_bytes" (the walk's checkpoints and the stored stretch)}, and with `rest_forms`
        "rest_forms": {"metric": dJ/dā⁰, "curvature": dJ/db̄⁰} (Q × 2 × 2), "rest_volume": dJ/dV̄, "pulse_sigma": dJ/dσ
        of the pulse's width, and for the insensitive wave "rest_operator" and "rest_pulse": its rest surface's and its
        pulse's shares of dJ/dX̄ (V × 3); with `rest_shape` "rest_shape": dJ/dX (V × 3, the whole run's). `settle`: the
        current state is the run's settled start, and the gradient goes on back through the settling (replayed from the
        placement) to the whole run's."""
        steps = int(steps)
        if steps < 1:
            raise WalkerGradientError(f"steps {steps}: the walk needs at least one chemistry step")
        if self._mass_hat is not None and not settle:
            raise WalkerGradientError("the rest shape's gradient is the whole run's: take it with settle=True")
        every = self.checkpoint_every or checkpoint_spacing(
            steps, self.coupled.substeps, sum(a.capacity for a in self._state_arrays()),
            2 * self.dynamics.state.x.capacity, 2 * self.wave.c.capacity)
        if every < 1:
            raise WalkerGradientError(f"checkpoint_every {every}: give at least 1 chemistry step")
        every = min(int(every), steps)
        substeps = self.coupled.substeps
        with wp.ScopedDevice(self.shell.device):
            checkpoints = [wp.empty((math.ceil(steps / every),) + a.shape, dtype=a.dtype) for a in self._state_arrays()]
        self._ensure_rows(every * substeps + 1, every)
        self._stiffness_placement = 0.0
        start = self.centre()
        self._place_surface()
        x_start = self.dynamics.state.x.numpy().astype(np.float64)
        for index, first in enumerate(range(0, steps, every)):
            for store, live in zip(checkpoints, self._state_arrays()):
                wp.copy(store[index], live)
            self._run(self._coupled_step, min(every, steps - first), "forward")
        objective = self.centre() - start
        x_end = self.dynamics.state.x.numpy().astype(np.float64)
        end = [wp.clone(a) for a in self._state_arrays()]
        s = self._scratch
        wp.copy(s["x_hat"], self._seed)
        s["v_hat"].zero_()
        self._shell_gradient.zero_()
        self._ground_gradient.zero_()
        for hat in self._rest_forms_hat or ():
            hat.zero_()
        self._rest_volume_hat.zero_()
        for hat in (self._mass_hat, self._weight_hat):
            if hat is not None:
                hat.zero_()
        for contact in self._contacts.values():
            contact.gradient.zero_()
        self._wave_adjoint.zero()
        self._rest_operator_hat.zero_()
        for index in reversed(range(len(checkpoints[0]))):
            self._backward_stretch([store[index] for store in checkpoints], min(every, steps - index * every))
        for live, saved in zip(self._state_arrays(), end):  # the run is left at the walk's end
            wp.copy(live, saved)
        self.shell.update_reference(self.wave.c)
        self._place_surface()
        self._advance_clocks(steps)
        x_hat = s["x_hat"].numpy().astype(np.float64) - self._seed.numpy()
        start_gradient = {"x": x_hat, "v": s["v_hat"].numpy().astype(np.float64)}
        start_gradient["c"] = self._wave_adjoint.c_hat.numpy().astype(np.float64)
        start_gradient["w"] = self._wave_adjoint.w_hat.numpy().astype(np.float64)
        run = self.run
        if settle or self._rest_forms_hat is not None:  # the pulse on the settled surface (sensitive), or the rest one
            surface = x_start if self.sensitive else run.mesh.vertices
            pulse_hat, sigma_hat = gaussian_pulse_adjoint(run.mesh, surface, run.origin_vertex,
                                                          run.resolved["width"] / run.radius, start_gradient["c"],
                                                          radius=run.radius)  # fmt: skip
            if settle and self.sensitive:  # c₀ moves with x₀
                x_hat = x_hat + pulse_hat
        if settle:
            s["x_hat"].assign(x_hat)
            self._settle_adjoint()
        state_bytes = sum(a.capacity for a in checkpoints) + 2 * self._xs.capacity + 2 * self._cs.capacity
        result = {"objective": objective, "gradient": self._named_gradient(),
                  "start": start_gradient, "steps": steps,
                  "substeps": substeps, "checkpoint_every": every, "checkpoints": len(checkpoints[0]),
                  "stored_substeps": len(self._xs), "state_bytes": int(state_bytes)}  # fmt: skip
        if self._rest_forms_hat is not None:
            result["rest_forms"] = {name: hat.numpy().astype(np.float64)
                                    for name, hat in zip(("metric", "curvature"), self._rest_forms_hat)}
            result["rest_volume"] = float(self._rest_volume_hat.numpy()[0])
            result["pulse_sigma"] = sigma_hat  # σ = width / R
            if not self.sensitive:
                result["rest_pulse"] = pulse_hat
            if not self.sensitive:
                result["rest_operator"] = self._rest_operator_hat.numpy().astype(np.float64)
        if self._mass_hat is not None:
            placement_hat = self._scratch["x_hat"].numpy().astype(np.float64)
            result["rest_shape"] = self._rest_shape_gradient(x_start, x_end, placement_hat, result)
            if "elongation" in self.wrt:  # x⁰ = s∘X + lift ẑ: dJ/ds = Σ x̂⁰_x X_x = Σ X̂_x x⁰_x / s²
                stretched = float(result["rest_shape"][:, 0] @ run.mesh.vertices[:, 0])
                result["gradient"]["elongation"] = stretched / run.p.elongation**2
        return result

    def _backward_stretch(self, checkpoint: list, count: int) -> None:
        """Run `count` chemistry steps again from `checkpoint`, storing c and every substep's (x, v), then take them
        backwards (the device's counters walk the stored rows down)."""
        for live, saved in zip(self._state_arrays(), checkpoint):
            wp.copy(live, saved)
        self._place_surface()
        for counter in self._counters.values():
            counter.zero_()
        self._run(lambda: self._coupled_step(store=True), count, "recompute")
        eval_push(self.wave.c, self._counters["step"], self._cs)
        self._push_mechanics()  # the stretch's end: the rows count·S of (x, v) and count of c
        eval_count(self._counters["substep"], -1)
        self._reference_adjoint = True
        self._run(self._backward_step, count, "backward")
        self._reference_adjoint = False

    def _backward_step(self) -> None:
        """One chemistry step backwards: its substeps' adjoints, last first, the references ramped as they were."""
        counters, s, substeps, chemistry = self._counters, self._scratch, self.coupled.substeps, self._wave_adjoint
        eval_count(counters["step"], -1)
        eval_pull(self._cs, counters["step"], 0, self._c_start)
        eval_pull(self._ws, counters["step"], 0, self._w_start)
        if self.sensitive:  # the step's surface and the next; x̂ gains the next surface's mass share
            eval_pull(self._xs, counters["substep"], -substeps, s["x_step"])
            eval_pull(self._xs, counters["substep"], 0, s["x_step_end"])
        step_x = s["x_step"] if self.sensitive else self._rest_x
        chemistry.recompute(self._c_start, self._w_start, step_x)
        wp.copy(self._c_end, chemistry.c_tilde)  # c̃: before the transport
        chemistry.transport_back(s["x_step_end"], s["x_hat"])
        for k in reversed(range(1, substeps + 1)):
            eval_count(counters["substep"], -1)
            eval_pull(self._xs, counters["substep"], 0, s["x"])
            eval_pull(self._vs, counters["substep"], 0, s["v"])
            eval_pull(self._vs, counters["substep"], 1, s["v_next"])
            self._set_reference(k)
            self._substep_adjoint(s["x"], s["v"], s["v_next"])
        chemistry.step_back(self._c_start, step_x, s["x_hat"] if self.sensitive else self._rest_operator_hat)

    def _substep_adjoint(self, x, v, v_next) -> None:
        """x̂, v̂ (after a walk's substep) → before it, and the parameters' gradients (module docstring)."""
        self._step_adjoint(self.solver, x, v, v_next, self.dynamics.dt)

    def _step_adjoint(self, solver, x, v, v_next, dt: float) -> None:
        """One step of `solver` (the overdamped walk's, or the settling's inertial one) backwards: x̂, v̂ after it →
        before it."""
        overdamped = solver is self.solver
        if solver.implicit:
            self._implicit_adjoint(solver, x, v, dt, overdamped)
        elif overdamped:
            self._overdamped_adjoint(x, v_next, dt)
        else:
            self._inertial_adjoint(solver, x, v, dt)
        if self._mass_hat is not None:
            self._mass_share(solver, x, v, dt)
        self._shell_adjoint(x)
        if not solver.implicit:
            self._explicit_ground_adjoint(solver, x, v)

    def _contact_of(self, solver) -> ImplicitContactAdjoint:
        if id(solver) not in self._contacts:
            self._contacts[id(solver)] = ImplicitContactAdjoint(solver)
        return self._contacts[id(solver)]

    def _implicit_adjoint(self, solver, x, v, dt: float, overdamped: bool) -> None:
        """A step with the implicit contact backwards up to F̂ (docs/theory/gradients.md): the predictor v* and the
        contact solved again, ŵ = v̂' + dt x̂'; v = v* + scale M⁻¹Lᵀf gives f̂ = scale L M⁻¹ ŵ; the contact's adjoint
        gives û*, ẑ; v̂* = ŵ + Lᵀû*; then the predictor's adjoint (overdamped: F̂ = v̂*/(ζM); inertial: F̂ = dt v̂*/M
        and the damping's)."""
        s, contact = self._scratch, self._contact_of(solver)
        scale = 1.0 / solver.drag if overdamped else dt
        solver.predictor(x, v, dt, s["v_star"])
        contact.forward(x, s["v_star"], scale, dt)
        eval_step_adjoint(s["x_hat"], s["v_hat"], dt, s["w_hat"])
        eval_scaled_inverse_mass(s["w_hat"], solver.inverse_mass, scale, s["a_ctrl"])
        pts = self._points
        self._gather(solver, s["a_ctrl"], pts["a"], weighted=True)
        pts["p_hat"].zero_()
        contact.backward(pts["a"], scale, dt, pts["u_star_hat"], pts["p_hat"], s["w_hat"], self._mass_hat,
                         self._weight_hat)  # fmt: skip
        wp.copy(s["v_star_hat"], s["w_hat"])
        self._spread(solver, pts["u_star_hat"], s["v_star_hat"])
        self._spread(solver, pts["p_hat"], s["x_hat"])
        if overdamped:  # v̂ stays 0: the step does not read v
            self._mobility_adjoint(s["v_star_hat"], s["v_star"])
        else:
            self._symplectic_adjoint(solver, x, v, dt, s["v_star_hat"])

    def _overdamped_adjoint(self, x, v_next, dt: float) -> None:
        """The explicit overdamped step's adjoint: ŵ = v̂' + dt x̂' (v̂ = 0 before the ground's share), then the
        mobility's."""
        s = self._scratch
        eval_step_adjoint(s["x_hat"], s["v_hat"], dt, s["w_hat"])
        self._mobility_adjoint(s["w_hat"], v_next)

    def _inertial_adjoint(self, solver, x, v, dt: float) -> None:
        """The explicit symplectic Euler step's adjoint: ŵ = v̂' + dt x̂', then the velocity update's."""
        s = self._scratch
        eval_step_adjoint(s["x_hat"], s["v_hat"], dt, s["w_hat"])
        self._symplectic_adjoint(solver, x, v, dt, s["w_hat"])

    def _mobility_adjoint(self, w_hat, velocity) -> None:
        """velocity = (F/M + g - a_rigid)/ζ backwards from its adjoint w_hat: F̂ = ŵ/(ζM), the drag's -ŵ·velocity/ζ."""
        solver = self.solver
        eval_scaled_inverse_mass(w_hat, solver.inverse_mass, 1.0 / solver.drag, self._scratch["force_hat"])
        if "drag" in self.wrt or self._mass_hat is not None:  # the automatic drag moves with the masses
            eval_weighted_dot(w_hat, velocity, -1.0 / solver.drag, len(SHELL_PARAMETERS), self._shell_gradient)

    def _symplectic_adjoint(self, solver, x, v, dt: float, w_hat) -> None:
        """v' = v + dt (F/M + g - a_rigid - η (v - v_rigid)) backwards from its adjoint w_hat: F̂ = dt ŵ/M, and v̂ and
        x̂'s share through the damping toward the rigid-body motion."""
        s = self._scratch
        eval_scaled_inverse_mass(w_hat, solver.inverse_mass, dt, s["force_hat"])
        eval_damping_adjoint(w_hat, x, v, self._mass, solver.rigid_motion(x, v), solver.total_mass, dt * solver.damping,
                             self._damping_sums, self._damping_moment, s["x_hat"], s["v_hat"])

    def _shell_adjoint(self, x) -> None:
        """F̂ (the step's force adjoint) back to x̂ through the shell (-H F̂) and to its parameters (F̂ · ∂F/∂θ =
        -∂Ė/∂θ, Ė the energy's rate of change as x moves along F̂: `Shell.rates_device`)."""
        s, shell = self._scratch, self.shell
        force_hat, gradient = s["force_hat"], self._shell_gradient
        eval_directional_derivative(x, force_hat, ACTION_STEP * shell.edge_length, shell.forces_device, self._largest,
                                    s["probe"], s["plus"], s["minus"], s["x_hat"])  # fmt: skip
        rest = self._rest_forms_hat is not None
        if self._reference_adjoint:
            shell.rates_device(x, force_hat, self._rates, self._wave_adjoint.by_concentration, self._ramp)
        elif rest or any(name in SHELL_PARAMETERS for name in self.wrt):
            shell.rates_device(x, force_hat, self._rates)
        else:
            return
        eval_shell_parameter_gradient(self._rates, self._factors, gradient)
        if rest:
            shell.rest_forms_rates_device(x, force_hat, *self._rest_forms_hat)
            if shell.has_volume:
                shell.volume_target_rate_device(self._rates, self._rest_volume_hat)

    def _explicit_ground_adjoint(self, solver, x, v) -> None:
        """F̂ back to x̂, v̂ through the explicit ground law at the limit points (Lᵀ of its adjoint), and to its
        parameters (`solver`: the step's)."""
        s = self._scratch
        force_hat, ground = s["force_hat"], solver.ground
        pts = self._points
        ground_motion(ground, x, v, solver.mask, self._patch, pts["p"], pts["u"])
        self._gather(solver, force_hat, pts["a"], weighted=True)
        if self._weight_hat is not None:  # the pressures' spread a_q f_q: â_q += f_q·(G F̂)_q (`_mass_share` left f)
            eval_point_weight_share(solver.ground_forces, pts["a"], self._area, self._weight_hat)
        eval_ground_adjoint(ground, pts["p"], pts["u"], pts["a"], pts["p_hat"], pts["u_hat"], self._ground_gradient)
        self._spread(solver, pts["p_hat"], s["x_hat"])
        self._spread(solver, pts["u_hat"], s["v_hat"])

    def _gather(self, solver, field, out, weighted: bool) -> None:
        """out = G field at the ground's points (L, or the quadrature basis N), times each point's dω̄⁰ where
        `weighted` and the contact is per area: the transpose of the spread that takes their forces to the vertices."""
        ground_motion(solver.ground, field, field, solver.mask, self._patch, out, self._points["unused"])
        if weighted and self._area is not None:
            eval_area_scale(out, self._area, out)

    def _spread(self, solver, point_values, out) -> None:
        """out += Gᵀ point_values (the adjoint of the gather: unweighted)."""
        spread_to_control_points(solver.ground, point_values, solver.mask, self._patch, self._unit_area, out)

    def _named_gradient(self) -> dict:
        values = self._gradients()
        return {name: float(values[name]) for name in self.wrt if name not in SHAPE_PARAMETERS}

    def _gradients(self) -> dict:
        """dJ/dθ of every parameter whose share was accumulated (ζ's: with "drag" asked for, or the rest shape)."""
        shell = self._shell_gradient.numpy().astype(np.float64)  # copies: the device arrays stay as summed
        ground = self._ground_gradient.numpy().astype(np.float64)
        ground[GROUND_PARAMETERS.index("stiffness")] += self._stiffness_placement
        for key, contact in self._contacts.items():  # the implicit contact's laws; its scale 1/ζ in the walk's solver
            ground = ground + contact.gradient.numpy()[:4]
            if key == id(self.solver):
                shell[-1] -= contact.gradient.numpy()[4] / self.solver.drag**2
        per = self.run.resolved["contact_area"] if self._area is not None else 1.0
        ground[:2] /= per  # the law's k and β are the scene's per contact area
        return {**dict(zip(SHELL_PARAMETERS, shell)), "drag": shell[-1], **dict(zip(GROUND_PARAMETERS, ground))}


def walker_adjoint_gradient(scene, p, wrt, *, points=(), mesh=None, hold_start: bool = False, seed: int = 0,
                            checkpoint_every=None, device=None, report=print) -> dict:  # fmt: skip
    """dJ/dθ of a walker `scene` (a scene module: its `build`) at parameters `p` by the reverse mode (float64), J the
    distance walked in R over the whole run: back through the walk and then the settling, replayed from the
    placement (not needed for `SETTLE_FREE` parameters alone: the settling, at c = 0, does not see them).
    `points`: the rest shape's control points (vertex indices of the scene's mesh, or "all") whose dJ/dX is taken
    (wavewarp/adjoint_shape.py); `mesh`: the scene's mesh in place of its own (a designed rest shape). `hold_start`:
    the walk's derivative with its settled start held. Returns
    `WalkAdjoint.gradient`'s dict with "start_held", "period_kinetic" and, with `points`, "points" and
    "shape_gradient" (P × 3, per unit length)."""
    check_adjoint_walk(p, wrt)
    if not (len(wrt) or len(points)):
        raise WalkerGradientError(f"--wrt (nothing): name one or more of {', '.join(ADJOINT_PARAMETERS)}, or the "
                                  "rest shape's control points (--points)")  # fmt: skip
    if len(points) or any(name in SHAPE_PARAMETERS for name in wrt):
        check_rest_shape(p)
        if hold_start:
            raise WalkerGradientError("the rest shape's gradient is the whole run's (the settling sees the shape): "
                                      "drop --hold-start")  # fmt: skip
    run = scene.build(replace(p, dtype="float64"), mesh=mesh, device=device, seed=seed, report=report)
    chosen = control_points(points, run.mesh.n_vertices) if len(points) else []
    settle = not hold_start and (bool(chosen) or any(name not in SETTLE_FREE for name in wrt))
    adjoint = WalkAdjoint(run, wrt, checkpoint_every, rest_shape=bool(chosen))
    result = adjoint.gradient(run.frames * run.steps_per_frame, settle=settle)
    if chosen:
        result.update(points=chosen, shape_gradient=result["rest_shape"][chosen])
    return {**result, "start_held": bool(hold_start), "period_kinetic": run.period_kinetic}
