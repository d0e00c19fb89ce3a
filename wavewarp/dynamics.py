"""Shell dynamics for the walkers (docs/theory/dynamics.md): solvers and ready-to-run steppers.

    M_I dv_I/dt = F_I(x) - M_I g ẑ + (Lᵀ f_ground)_I - η M_I (v_I - v_rigid),     dx_I/dt = v_I

(the net force and torque of F, zero in exact arithmetic, are removed from F's round-off as a
rigid-body acceleration: float32 shells would otherwise drift and roll), with the lumped mass M_I = ρ ∫ N_I dω̄⁰ (so Σ M_I x_I / Σ M_I is exactly the centre of mass of
the surface density ρ), the internal forces F of `Shell`, gravity, the ground's contact and
friction forces f_ground on the limit points p = L x (L the Loop limit mask), and an optional
light damping η of the velocity relative to the rigid-body motion v_rigid = v̄ + Ω × (x - c) of
the same momentum and angular momentum (internal vibrations only: it exerts no net force and no
torque, so it can neither fake nor brake sliding or rolling). Symplectic (semi-implicit)
Euler: v first, then x with the new v.

Stability (guarded like the chemistry steppers): dt < 2/ω (√(1 + ζ²) - ζ), with ω² the largest
eigenvalue of M⁻¹H (H the Hessian of the shell energy, by Lanczos on central force
differences) and ζ = (η + η_ground) / 2ω, η_ground = β max_J (Lᵀ1)_J / M_J the contact damping
per unit mass. The contact stiffness 2k|z| is small against the shell's at the scenes'
penetrations; a runaway it causes is caught by the blow-up check. An implicit ground
(`Ground(solve="implicit")`) solves each point's damping, linearised stiffness and friction with its
own end-of-step velocity: ζ = η / 2ω, whatever β and k_f.

`OverdampedSolver` is the mobility model (ζ M v = F, no inertia) on the same terms.

`InertialSolver` / `OverdampedSolver` advance a `State` (x, v) with `step(state_in, state_out, dt)`
under the shell's current active reference; `ShellDynamics` / `OverdampedDynamics` hold a solver,
its state, the time step and a guarded runner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from .checks import AUTOMATIC_DT, finite, plain, positive
from .device import reduction_threads
from .geometry import LimitMask, checked_positions, evaluate, limit_coupling
from .kernels import contact as kernels_contact
from .kernels import dynamics as kernels_dynamics
from .kernels import implicit_contact as kernels_implicit_contact
from .kernels import limit_surface as kernels_limit_surface
from .kernels import reduce as kernels_reduce
from .kernels import shell as kernels_shell
from .kernels.contact import eval_ground
from .kernels.dynamics import (
    eval_rigid_correction,
    eval_speed_runaway,
    eval_trace_row,
    integrate_overdamped_euler,
    integrate_symplectic_euler,
)
from .kernels.implicit_contact import BodyFrame, Coupling, eval_implicit_ground
from .laplace import LaplaceBeltrami
from .runner import GuardedRunner, Stepper
from .shell import Shell, world_value
from .state import State
from .waves import BlowUpError, TimeStepError


@dataclass(frozen=True)
class Ground:
    """The ground z = 0: F_n = max(k z² - β v_z, 0) where z ≤ 0, F_f = -μ F_n tanh(k_f |v_t|) v̂_t.

    contact "point" (the paper's): the law acts on each control vertex's limit point, k and β per point.
    contact "area" (ours): the law is a pressure at the quadrature points of the limit surface,
    k and β per unit rest area, so the load pattern converges under refinement (docs/theory/dynamics.md).
    solve "explicit" (the paper's): the forces at the step's start (the overdamped model sees the last
    step's velocity). "implicit": per point, the damping, the penalty's stiffness (linearised) and the
    friction are solved against the point's own end-of-step velocity: stable at any drag and any k_f,
    and k_f = inf is Coulomb's law (stick while the tangential load is below μ F_n); `sweeps` Jacobi
    sweeps then let each point see the others' forces (0: each point alone).
    slope θ (radians): the ground is inclined, gravity g (sin θ, 0, -cos θ) in its frame (downhill +x).
    """

    stiffness: float = 10.0  # k
    damping: float = 0.5  # β
    friction: float = 0.1  # μ
    sharpness: float = 0.1  # k_f
    contact: str = "point"
    solve: str = "explicit"
    sweeps: int = 8
    slope: float = 0.0

    def __post_init__(self):
        for name in ("stiffness", "damping", "friction", "sharpness"):
            value = getattr(self, name)
            coulomb = name == "sharpness" and value == math.inf and self.solve == "implicit"
            if not ((math.isfinite(value) or coulomb) and value >= 0):
                raise ValueError(f"Ground.{name} must be a finite number >= 0, got {value!r}"
                                 + (" (sharpness inf, Coulomb's law, needs solve='implicit')" if value == math.inf else ""))  # fmt: skip
        if self.contact not in ("point", "area"):
            raise ValueError(f"Ground.contact must be 'point' or 'area', got {self.contact!r}")
        if self.solve not in ("explicit", "implicit"):
            raise ValueError(f"Ground.solve must be 'explicit' or 'implicit', got {self.solve!r}")
        if isinstance(self.sweeps, bool) or not isinstance(self.sweeps, int) or self.sweeps < 0:
            raise ValueError(f"Ground.sweeps must be an integer >= 0, got {self.sweeps!r}")
        if not (math.isfinite(self.slope) and abs(self.slope) < math.pi / 2):
            raise ValueError(f"Ground.slope must be an angle in radians between -π/2 and π/2, got {self.slope!r}")


class InertialSolver:
    """Symplectic Euler for the inertial shell (module docstring) on `shell`'s device and dtype.

    density ρ (mass per reference area); gravity g (along -z; 0 for none); ground a `Ground` or None;
    damping η ≥ 0 (relative to the rigid-body motion). A step acts on state.x, state.v under the shell's
    current active reference (`shell.update_reference`), with no host round-trip.
    """

    scheme = "symplectic Euler shell dynamics"

    def __init__(self, shell: Shell, *, density, gravity=0.0, ground: Ground | None = None, damping=0.0):
        if not isinstance(shell, Shell):
            raise ValueError(f"shell must be a wavewarp.Shell, got {type(shell).__name__}")
        if ground is not None and not isinstance(ground, Ground):
            raise ValueError(f"ground must be a wavewarp.dynamics.Ground or None, got {type(ground).__name__}")
        if shell.self_contact is not None:
            raise ValueError("self-contact acts in quasi-static relaxations only (Shell.relax, QuasiStatic): the dynamics "
                             "steppers do not search its pairs again; set shell.self_contact = None")  # fmt: skip
        self.shell, self.ground = shell, ground
        self.device, self.scalar, self.vec3, self._real = shell.device, shell.scalar, shell.vec3, shell._real
        self.density = positive("density", density)
        self.gravity = finite("gravity", gravity)
        self.damping = finite("damping", damping)
        if self.gravity < 0 or self.damping < 0:
            raise ValueError(f"gravity and damping must be >= 0, got gravity={plain(gravity)!r}, damping={plain(damping)!r}")
        slope = 0.0 if ground is None else ground.slope
        self.gravity_vector = (self.gravity * math.sin(slope), 0.0, -self.gravity * math.cos(slope))
        self.implicit = ground is not None and ground.solve == "implicit"
        mesh = shell.mesh
        n, self.worlds = mesh.n_vertices, mesh.worlds
        self._reduction_threads = reduction_threads(mesh.vertices_per_world, shell.deterministic)  # per world
        rest = LaplaceBeltrami(mesh, rule=shell.rule, device=self.device, dtype="float64")
        self.mass = self.density * rest.mass()  # ρ ∫ N_I dω̄⁰ on the rest surface
        self.world_masses = np.array([world.sum() for world in self.mass.reshape(self.worlds, -1)])
        self.total_mass = world_value(self.world_masses)
        self.mask = LimitMask.of(mesh, device=self.device, dtype=self.scalar.__name__)
        with wp.ScopedDevice(self.device):
            self._mass = wp.array(self.mass.astype(self._real), dtype=self.scalar)
            self._inverse_mass = wp.array((1.0 / self.mass).astype(self._real), dtype=self.scalar)
            self._inverse_total_mass = wp.array((1.0 / self.world_masses).astype(self._real), dtype=self.scalar)
            self._forces = wp.zeros(n, dtype=self.vec3)
            self._rigid_sums = wp.zeros(5 * self.worlds, dtype=self.vec3)  # zeroed by their consumer, rigid_correction_kernel
            self._second_moment = wp.zeros(self.worlds, dtype=wp.types.matrix((3, 3), self.scalar))
            self._rigid = wp.zeros(5 * self.worlds, dtype=self.vec3)
            self._first_moment = wp.zeros(self.worlds, dtype=self.vec3)
            # the ground's points: limit points of the control vertices, or quadrature points (area contact)
            points = n if ground is None or ground.contact == "point" else shell.tables.n_quadrature_points
            self._limit_x = wp.zeros(points, dtype=self.vec3)
            self._limit_v = wp.zeros(points, dtype=self.vec3)
            self._limit_forces = wp.zeros(points, dtype=self.vec3)
            self._normal_force = wp.zeros(points, dtype=self.scalar)
            self._response = wp.zeros(points if self.implicit else 0, dtype=self.scalar)
            self._others = wp.zeros(points if self.implicit else 0, dtype=self.vec3)
            # the implicit sweeps' operator L M⁻¹ Lᵀ (limit points)
            self._coupling = (Coupling.of(limit_coupling(mesh, 1.0 / self.mass), self.scalar)
                              if self.implicit and points == n else None)  # fmt: skip
            # dω̄⁰ at each quadrature point (area contact)
            self._rest_area = evaluate(shell.tables, shell.tables.positions())["area"] if points != n else None
            self.flag = wp.zeros(self.worlds, dtype=wp.int32)  # per world
            self.body = BodyFrame(wp.zeros(self.worlds, dtype=self.vec3))  # the lab frame: U = 0
        self.contact_damping = self._contact_damping()

    inverse_mass = property(lambda self: self._inverse_mass)  # 1/M per control point, on the device
    ground_points = property(lambda self: len(self._limit_x))  # the ground's points: limit or quadrature points

    def ground_tables(self) -> tuple:
        """(patch tables, dω̄⁰ per point or None): what the ground's gather and spread take (`eval_ground`)."""
        return self.shell.tables.patch(), self._rest_area

    def state(self, x0=None, v0=None) -> State:
        """x0 (default: the mesh's own positions) and v0 (default 0), checked, on the device."""
        n = self.shell.mesh.n_vertices
        x0 = self.shell.mesh.vertices if x0 is None else checked_positions(x0, n, "x0")
        v0 = np.zeros((n, 3)) if v0 is None else checked_positions(v0, n, "v0")
        with wp.ScopedDevice(self.device):
            return State(x=wp.array(x0.astype(self._real), dtype=self.vec3), v=wp.array(v0.astype(self._real), dtype=self.vec3))

    # ---------------------------------------------------------------- stability bound
    def _contact_damping(self) -> float:
        """η_ground = β max_J (Lᵀ1)_J / M_J: the contact damping per unit mass (mesh only); for the
        area contact β max_J ∫ N_J dω̄⁰ / M_J = β/ρ."""
        if self.ground is None:
            return 0.0
        if self.ground.contact == "area":
            return self.ground.damping / self.density
        return self.ground.damping * float(np.max(self.limit_column_sums() / self.mass))

    def limit_column_sums(self) -> np.ndarray:
        """(Lᵀ1)_J: the limit mask's column sums, each control point's share of the limit points."""
        m = self.mask
        chi = np.repeat(m.ring_weight.numpy().astype(np.float64), np.diff(m.ring_start.numpy()))
        return m.centre_weight.numpy() + np.bincount(m.ring.numpy(), weights=chi, minlength=len(self.mass))

    def _zeta(self, omega: float) -> float:
        """The damping ratio of the top mode: the background damping, and the contact's when it is explicit."""
        return (self.damping + (0.0 if self.implicit else self.contact_damping)) / (2 * omega)

    def bound(self, omega: float) -> float:
        """The stability bound on dt for the largest frequency ω."""
        zeta = self._zeta(omega)
        return 2.0 / omega * (math.sqrt(1 + zeta**2) - zeta)

    def bound_formula(self, omega: float) -> str:
        return f"dt < 2/ω (√(1+ζ²) - ζ), ζ = {self._zeta(omega):.3g}"

    def largest_frequency(self, x: wp.array, tol: float = 1e-6) -> float:
        """ω = √λ_max(M⁻¹H) at positions x and the current reference: Lanczos (ARPACK) on
        M^-½ H M^-½, with H q from central differences of the shell's forces."""
        from scipy.sparse.linalg import LinearOperator, eigsh

        n = len(self.mass)
        step = (1e-3 if self.scalar == wp.float32 else 1e-6) * self.shell.edge_length
        x = x.numpy().astype(np.float64)
        scale = np.repeat(1.0 / np.sqrt(self.mass), 3)
        probe, forces = wp.empty(n, dtype=self.vec3, device=self.device), wp.empty(n, dtype=self.vec3, device=self.device)

        def matvec(q):
            q = scale * np.ravel(q)
            size = np.abs(q).max() or 1.0
            out = []
            for sign in (1.0, -1.0):
                probe.assign((x + (sign * step / size) * q.reshape(n, 3)).astype(self._real))
                self.shell.forces_device(probe, forces)
                out.append(forces.numpy().astype(np.float64).ravel())
            return scale * (out[1] - out[0]) * (size / (2 * step))

        start = np.random.default_rng(0).standard_normal(3 * n)
        operator = LinearOperator((3 * n, 3 * n), matvec=matvec, dtype=np.float64)
        eigenvalue = eigsh(operator, k=1, which="LA", tol=tol, v0=start, return_eigenvectors=False)[0]
        return math.sqrt(max(float(eigenvalue), 1e-300))

    # ---------------------------------------------------------------- stepping
    def contact_forces(self, x: wp.array, v: wp.array) -> None:
        """Contact and friction at x, v added to the solver's force buffer: on the limit points, reaching the control
        points through Lᵀ (or, for the area contact, as pressures on the quadrature points, spread back)."""
        if self.ground is None:
            return
        eval_ground(self.ground, x, v, self.mask, self.shell.tables.patch(), self._rest_area,
                    self._limit_x, self._limit_v, self._normal_force, self._limit_forces, self._forces)  # fmt: skip

    def step(self, state_in: State, state_out: State, dt: float) -> None:
        """F (shell) → rigid-body sums → contact and friction → integrator (gravity is its uniform acceleration);
        implicit ground: integrator without contact (the predictor) → per-point contact solve → x."""
        if state_out is not state_in:
            wp.copy(state_out.x, state_in.x)
            wp.copy(state_out.v, state_in.v)
        x, v = state_out.x, state_out.v
        with wp.ScopedDevice(self.device):
            self.shell.forces_device(x, self._forces)
            self._rigid_rows(x, v, self.damping > 0)
            if self.implicit:
                self._integrate(x, v, dt, move=False)
                eval_implicit_ground(self.ground, x, v, self._inverse_mass, self._response_scale(dt), dt, self.mask,
                                     self.shell.tables.patch(), self._rest_area, self._limit_x, self._limit_v,
                                     self._response, self._others, self._normal_force, self._limit_forces,
                                     self._forces, self.body, self._coupling)  # fmt: skip
                return
            self.contact_forces(x, v)
            self._integrate(x, v, dt)

    def predictor(self, x: wp.array, v: wp.array, dt: float, out: wp.array) -> None:
        """out = the velocity an implicit-contact step solves its contact from, at x, v (the shell's forces, the rigid
        correction and the integrator without contact: `step`'s first half; x, v unchanged)."""
        wp.copy(out, v)
        with wp.ScopedDevice(self.device):
            self.shell.forces_device(x, self._forces)
            self._rigid_rows(x, v, self.damping > 0)
            self._integrate(x, out, dt, move=False)

    def step_forces(self, x: wp.array, v: wp.array) -> wp.array:
        """The forces a step at x, v divides by M (`step`'s buffer before the integrator: the shell's and the explicit
        ground's; with the implicit ground, its predictor's: the shell's alone), in the solver's force buffer."""
        with wp.ScopedDevice(self.device):
            self.shell.forces_device(x, self._forces)
            if not self.implicit:
                self.contact_forces(x, v)
        return self._forces

    force_buffer = property(lambda self: self._forces)  # the forces as last evaluated (`step`, `predictor`, `step_forces`)
    ground_forces = property(lambda self: self._limit_forces)  # the ground's forces at its points, as last evaluated

    def rigid_motion(self, x: wp.array, v: wp.array) -> wp.array:
        """The rigid-body rows of x, v (kernels/dynamics.py, per world: [N/ΣM, α, centre, v̄, Ω], the first two of the
        force buffer as it is): the centre, the mean velocity and the rotation the damping acts relative to."""
        self._rigid_rows(x, v, True)
        return self._rigid

    def _rigid_rows(self, x: wp.array, v: wp.array, with_momentum: bool) -> None:
        """self._rigid: the rigid-body rows of the force buffer at x, v (`eval_rigid_correction`)."""
        eval_rigid_correction(self._forces, self._mass, x, v, with_momentum, self.worlds, self._reduction_threads,
                              self._inverse_total_mass, self._rigid_sums, self._second_moment, self._rigid)  # fmt: skip

    def _response_scale(self, dt: float) -> float:
        """A point's velocity change per unit of M⁻¹ × force over a step: dt (inertia)."""
        return dt

    def _integrate(self, x: wp.array, v: wp.array, dt: float, move: bool = True) -> None:
        integrate_symplectic_euler(self._forces, self._inverse_mass, self._rigid, self.damping, self.gravity_vector, dt,
                                   self.worlds, x, v, move)  # fmt: skip

    def reset_checks(self) -> None:
        """Clear what a chunk's steps flag (nothing here: the speed check runs after the chunk)."""

    def launch_checks(self, state: State, limit: float) -> None:
        """flag[w] = 1 where some |v_I| of world w passed `limit` or is NaN/Inf (read by the caller)."""
        self.flag.zero_()
        eval_speed_runaway(state.v, limit, self.worlds, self.flag)

    # ---------------------------------------------------------------- measurements
    def launch_trace_row(self, state: State, c: wp.array, origin: wp.array, row: wp.array, trace: wp.array) -> None:
        """Device only (capturable): per world w, trace[row[w], 7w..7w+6] = [c at origin[w], centre of mass,
        x at origin[w]], row[w] += 1."""
        eval_trace_row(self._mass, state.x, c, origin, self.worlds, self._reduction_threads, self._inverse_total_mass,
                       self._first_moment, row, trace)  # fmt: skip

    def external_forces(self, state: State) -> np.ndarray:
        """(V, 3) gravity, contact and friction forces on the control points: the laws at `state` (explicit
        ground), or the contact forces the last step applied (implicit: they depend on that step's predictor)."""
        with wp.ScopedDevice(self.device):
            if not self.implicit:
                self._forces.zero_()
                self.contact_forces(state.x, state.v)
            forces = self._forces.numpy().astype(np.float64)
        return forces + np.outer(self.mass, self.gravity_vector)

    def normal_forces(self, state: State) -> np.ndarray:
        """Ground normal force on each of the ground's points at `state` (implicit: of the last step): (V,) on
        the limit points, or (Q,) on the quadrature points for the area contact (pressure × dω̄⁰)."""
        if self.ground is None:
            return np.zeros(len(self.mass))
        if not self.implicit:
            self.external_forces(state)
        force = self._normal_force.numpy().astype(np.float64)
        return force if self.ground.contact == "point" else force * self._rest_area.numpy()


class OverdampedSolver(InertialSolver):
    """The overdamped mobility model (the paper's "overdamped dynamics"):

        ζ M_I v_I = F_I(x) - M_I g ẑ + (Lᵀ f_ground(L x, L v⁻))_I,     x ← x + dt v

    drag ζ per unit mass against the lab frame, no inertia: every control point moves at the
    velocity its net force gives it. The ground's damping and friction need a velocity; they see the
    last step's v⁻ = (x_n - x_(n-1))/dt (explicit, lagged). Summing over the points, the internal
    forces drop out: the centre of mass moves at (net external force)/(ζ ΣM) exactly, so on the
    ground only friction can move it, at most μ g/ζ.

    Stability: explicit Euler on the gradient flow needs dt < 2ζ/ω² (ω² = λ_max(M⁻¹H)); the lagged
    contact damping feeds back with gain η_ground/ζ, so ζ must exceed η_ground (ValueError otherwise).
    drag=None picks 2 η_ground (gain ½), the least drag that keeps the lag well damped (no ground: give
    ζ). An implicit ground (`Ground(solve="implicit")`) has no lag: each point's contact and friction
    are solved with its own velocity, v = v* + M⁻¹ Lᵀ f / ζ, at any drag. No background damping: the
    drag damps every motion. drag_frame="body" (implicit ground with friction) moves the drag onto the
    velocity relative to each world's horizontal body velocity U, which the friction alone then sets:
    U zeroes the world's net horizontal force (`BodyFrame`; docs/theory/dynamics.md, "Drag in the body
    frame").
    """

    scheme = "overdamped (mobility) shell dynamics"

    def __init__(self, shell: Shell, *, density, drag=None, drag_frame="lab", **options):
        if "damping" in options:
            raise ValueError("OverdampedDynamics has no background damping: its drag ζ damps every motion")
        self.drag = None if drag is None else positive("drag", drag)
        if drag_frame not in ("lab", "body"):
            raise ValueError(f"drag_frame must be 'lab' or 'body', got {drag_frame!r}")
        self.drag_frame = drag_frame
        super().__init__(shell, density=density, **options)
        if drag_frame == "body":
            self._body_frame()

    def _body_frame(self) -> None:
        """The drag on the velocity relative to each world's horizontal body velocity U, which the friction alone
        sets (docs/theory/dynamics.md, "Drag in the body frame")."""
        ground = self.ground
        if ground is None or ground.solve != "implicit" or ground.friction <= 0:
            raise ValueError("drag_frame='body' leaves the horizontal translation to the ground's friction alone: it "
                             "needs a ground with friction > 0 and the implicit contact (Ground(solve='implicit'), in a "
                             "scene --set contact_solve=implicit)")  # fmt: skip
        if abs(math.tan(ground.slope)) >= ground.friction:
            raise ValueError(f"drag_frame='body' on a slope of tan θ = {math.tan(ground.slope):.6g} >= μ = "
                             f"{ground.friction:.6g}: no friction can hold the body, and nothing else brakes its "
                             "translation; use a smaller slope or drag_frame='lab'")  # fmt: skip
        points = len(self._limit_x)
        pull = [(m * self.gravity_vector[0], m * self.gravity_vector[1], 0.0) for m in self.world_masses]
        weight = np.ones(points) if self._rest_area is None else self._rest_area.numpy()
        with wp.ScopedDevice(self.device):
            self.body = BodyFrame(
                wp.zeros(self.worlds, dtype=self.vec3), solve=True,
                external=wp.array(np.array(pull, dtype=self._real), dtype=self.vec3),
                weight=wp.array(np.asarray(weight, dtype=self._real), dtype=self.scalar),
                force_sum=wp.zeros(self.worlds, dtype=self.vec3), stiffness_sum=wp.zeros(self.worlds, dtype=self.scalar),
                threads=reduction_threads(points // self.worlds, self.shell.deterministic))  # fmt: skip

    def _contact_damping(self) -> float:
        eta = super()._contact_damping()
        if self.drag is None:
            if eta == 0:
                raise ValueError("drag=None picks 2 η_ground, and there is no ground: give the drag ζ (> 0)")
            self.drag = 2.0 * eta
        elif self.drag <= eta and not self.implicit:
            raise ValueError(
                f"drag ζ = {self.drag:.6g} does not exceed the ground's damping per unit mass η_ground = {eta:.6g}: the "
                f"lagged contact velocity would oscillate and grow; use drag > {eta:.6g}, e.g. {2 * eta:.6g} "
                f"(drag=None, in a scene --set drag=0, picks that), or the implicit contact (Ground(solve='implicit'), "
                f"in a scene --set contact_solve=implicit), which takes any drag"
            )  # fmt: skip
        return eta

    def bound(self, omega: float) -> float:
        return 2.0 * self.drag / omega**2

    def bound_formula(self, omega: float) -> str:
        return f"dt < 2ζ/ω², ζ = {self.drag:.6g}"

    def _response_scale(self, dt: float) -> float:
        """A point's velocity change per unit of M⁻¹ × force: 1/ζ (no inertia)."""
        return 1.0 / self.drag

    def _integrate(self, x: wp.array, v: wp.array, dt: float, move: bool = True) -> None:
        integrate_overdamped_euler(self._forces, self._inverse_mass, self._rigid, 1.0 / self.drag, self.gravity_vector,
                                   dt, self.worlds, x, v, move)  # fmt: skip


class ShellDynamics(Stepper):
    """Inertial dynamics of `shell`, ready to run: an `InertialSolver`, its state (x, v), the time step
    and a guarded runner.

    c the control concentrations of the active reference (default 0; a coupled stepper updates it with
    `shell.update_reference`); dt None picks `safety` × the stability bound, a fixed dt past it raises
    TimeStepError (check_dt=False lets it run: stability studies); omega, when known (the `omega_max`
    of an identical run), skips the Lanczos estimate of ω. Every `check_every` steps one flag is read:
    NaN/Inf or a speed past `speed_limit` raises BlowUpError with the state restored.
    """

    solver_type = InertialSolver

    def __init__(self, shell: Shell, *, density, gravity=0.0, ground: Ground | None = None, x0=None, v0=None, c=None,
                 dt=None, safety=0.9, check_dt=True, check_every=100, speed_limit=None, capture=True, omega=None,
                 **solver_options):  # fmt: skip
        self.solver = self.solver_type(shell, density=density, gravity=gravity, ground=ground, **solver_options)
        self.shell, self.ground, self.device, self.scalar = shell, ground, self.solver.device, self.solver.scalar
        self.safety = self.checked_safety(safety)
        self.capture = bool(capture)
        self.state = self.solver.state(x0, v0)
        c = np.zeros(shell.mesh.n_vertices) if c is None else shell.checked_concentrations(c)
        shell.update_reference(wp.array(c.astype(shell._real), dtype=self.scalar, device=self.device))
        self.dt = None
        self.runner = GuardedRunner(self._step, protected=lambda: [self.state.x, self.state.v], check=self._check,
                                    device=self.device, capture=self.capture, check_every=check_every,
                                    modules=(kernels_shell, kernels_contact, kernels_implicit_contact, kernels_dynamics,
                                             kernels_limit_surface, kernels_reduce))  # fmt: skip
        shell.listen(self.notify_model_changed)
        self.set_time_step(dt, self.largest_frequency() if omega is None else omega, check_dt)
        v0 = self.state.numpy("v")
        typical = self.solver.gravity * 1e3 * self.dt * self.runner.check_every + float(np.abs(v0).max()) + 1.0
        self.speed_limit = positive("speed_limit", speed_limit) if speed_limit is not None else 1e6 * typical

    x = property(lambda self: self.state.x)
    v = property(lambda self: self.state.v)
    mass = property(lambda self: self.solver.mass)
    total_mass = property(lambda self: self.solver.total_mass)
    world_masses = property(lambda self: self.solver.world_masses)
    density = property(lambda self: self.solver.density)
    gravity = property(lambda self: self.solver.gravity)
    damping = property(lambda self: self.solver.damping)
    contact_damping = property(lambda self: self.solver.contact_damping)

    def notify_model_changed(self) -> None:
        """The shell's V̄ or terms changed: the captured steps are captured anew."""
        self.runner.invalidate()

    def set_time_step(self, dt, omega: float, check_dt: bool = True) -> None:
        """Take ω as the largest frequency (e.g. the largest over the active references a coupled
        run will visit), derive the bound, and set dt: None = `safety` × the bound; a fixed dt past
        the bound raises TimeStepError unless `check_dt` is false."""
        self.omega_max = positive("omega", omega)
        self.stable_dt = self.solver.bound(self.omega_max)
        if dt is None:
            dt = self.safety * self.stable_dt
        elif positive("dt", dt) > self.stable_dt and check_dt:
            raise TimeStepError(
                f"dt = {dt:.6g} exceeds the stability bound {self.stable_dt:.6g} of the {self.scheme} "
                f"({self.solver.bound_formula(self.omega_max)}, ω = {self.omega_max:.6g} from λ_max(M⁻¹H) by Lanczos): "
                f"use dt <= {self.stable_dt:.6g}, e.g. dt = {self.safety * self.stable_dt:.6g} (safety {self.safety}), "
                f"or {AUTOMATIC_DT}"
            )  # fmt: skip
        if dt != self.dt:
            self.dt = float(dt)
            self.runner.invalidate()

    def largest_frequency(self, tol: float = 1e-6) -> float:
        """ω = √λ_max(M⁻¹H) at the current positions and reference (`InertialSolver.largest_frequency`)."""
        return self.solver.largest_frequency(self.state.x, tol)

    def _step(self) -> None:
        self.solver.step(self.state, self.state, self.dt)

    def _check(self, chunk: int):
        return self.runaway(self.time, chunk * self.dt)

    def runaway(self, time: float, duration: float) -> BlowUpError | None:
        """Read one flag: a BlowUpError (not raised) if some |v_I| passed `speed_limit` or is NaN/Inf,
        for the steps from `time` over `duration`; None when all is well."""
        self.solver.launch_checks(self.state, self.speed_limit)
        if not self.solver.flag.numpy().any():
            return None
        return BlowUpError(
            f"{self.scheme} blew up between t = {time:.6g} and t = {time + duration:.6g} (NaN/Inf or a speed past "
            f"{self.speed_limit:.3g}) with dt = {self.dt:.6g} (stability bound {self.stable_dt:.6g}); the state is "
            f"restored to t = {time:.6g}. Reduce dt", time, self.steps,
        )  # fmt: skip

    # ---------------------------------------------------------------- state (NumPy)
    def positions(self) -> np.ndarray:
        return self.state.numpy("x")

    def velocities(self) -> np.ndarray:
        return self.state.numpy("v")

    def center_of_mass(self) -> np.ndarray:
        """Σ M_I x_I / Σ M_I: exactly the centre of mass of the density ρ on the surface."""
        return self.mass @ self.positions() / self.total_mass

    def momentum(self) -> np.ndarray:
        return self.mass @ self.velocities()

    def kinetic_energy(self) -> float:
        return 0.5 * float(self.mass @ np.sum(self.velocities() ** 2, axis=1))

    def external_forces(self) -> np.ndarray:
        """(V, 3) gravity, contact and friction forces on the control points at the current state."""
        return self.solver.external_forces(self.state)

    def normal_forces(self) -> np.ndarray:
        """Ground normal force on each of the ground's points at the current state (`InertialSolver.normal_forces`)."""
        return self.solver.normal_forces(self.state)


class OverdampedDynamics(ShellDynamics):
    """The overdamped mobility model, ready to run (`OverdampedSolver`): drag ζ (None: 2 η_ground), no
    background damping; other arguments as `ShellDynamics`."""

    solver_type = OverdampedSolver

    drag = property(lambda self: self.solver.drag)
