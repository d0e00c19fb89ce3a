"""Walker scenes (paper Fig. 3a; docs/theory/dynamics.md): FitzHugh–Nagumo waves drive an active shell
that walks on the ground under gravity and friction.

A walker run: the shell is put down touching the ground (a symmetric contact, an equilibrium),
settles for `settle` time units with c = 0, then the wave starts at t = 0 from a narrow Gaussian at
the origin vertex (w = 0). Each chemistry step the active reference follows c and the mechanics
advance to the same time (`coupled.Walking`). Measured (wavewarp/measurements.py): the oscillation
period T from the upward half-maximum crossings of c at the origin vertex, the centre-of-mass
displacement, and the speed in R per T along the direction of propagation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import warp as wp

from .balance import ChemicalBalance, FirstArrival, arrival_measurements
from .chemistry import fhn_kinetic_period
from .coupled import Walking
from .dynamics import Ground
from .figures import FHN_TIME_UNIT, frame_png, locomotion_png
from .geometry import limit_positions, limit_surface
from .initial import gaussian_pulse
from .measurements import BodyRotation, locomotion
from .mesh import Mesh, icosphere
from .model import ModelBuilder
from .parameters import SceneError, as_dict, param
from .runs import WaveClock, imperfect, mean_edge, scene_mesh, transport_parameter
from .sizing import check_steps

AUTO_DT_SAFETY = 0.4  # dt=auto: this fraction of the chemistry's stability bound on the settled shell
TRACE_COLUMNS = 8  # t, c at the origin vertex, centre of mass (3), the origin vertex's position (3)


@dataclass(frozen=True)
class WalkerParameters:
    """The walkers' parameters (a scene adds its surface's and overrides the couplings)."""

    young: float = param(200.0, "Young's modulus Y: the sphere walker sags about 1% of R under its weight", positive=True)
    poisson: float = param(0.33, "Poisson ratio ν")
    thickness: float = param(2.1, "shell thickness h = 0.084 R", positive=True)
    AC: float = param(0.1, "metric coupling AC")
    AI: float = param(0.0, "curvature coupling AI")
    mu_v: float = param(0.4, "volume penalty μV in units of Y h / size⁴", minimum=0.0)
    gamma: float = param(0.2, "FHN diffusion γ", positive=True)
    nu: float = param(-0.01, "FHN threshold ν (< 0: the medium oscillates)")
    kappa: float = param(1e-4, "FHN κ", minimum=0.0)
    epsilon: float = param(0.005, "FHN ε", minimum=0.0)
    width: float = param(0.0, "width of the initial Gaussian (length); auto (0) = 1.5 mean control edges", minimum=0.0, auto=True)
    density: float = param(0.01, "surface mass density ρ", positive=True)
    gravity: float = param(0.5, "gravity g", minimum=0.0)
    stiffness: float = param(10.0, "ground contact stiffness k", minimum=0.0)
    contact_damping: float = param(0.5, "ground contact damping β", minimum=0.0)
    contact: str = param("point", "point: k and β per limit point of a control vertex; area: a pressure on the limit "
                         "surface (converges under refinement)", choices=("point", "area"))  # fmt: skip
    contact_area: float = param(0.0, "area contact: the area a per point of k and β; auto (0) = the mean rest area per control "
                                "vertex", minimum=0.0, auto=True)  # fmt: skip
    friction: float = param(0.1, "friction coefficient μ", minimum=0.0)
    sharpness: float = param(math.inf, "friction regularisation k_f of μ|F_n| tanh(k_f |v_t|); inf: Coulomb's law (needs "
                             "contact_solve=implicit); the paper's 0.1 makes friction a weak viscous drag", minimum=0.0,
                             infinite=True)  # fmt: skip
    contact_solve: str = param("implicit", "explicit: the contact and friction forces at the step's start (overdamped: "
                               "with the last step's velocity; needs drag > η_ground); implicit: each point's damping, "
                               "stiffness and friction solved with its own end-of-step velocity (any drag, any k_f)",
                               choices=("explicit", "implicit"))  # fmt: skip
    contact_sweeps: int = param(8, "implicit contact: Jacobi sweeps coupling the points' forces (0: each point alone)",
                                minimum=0)  # fmt: skip
    slope: float = param(0.0, "ground inclination in degrees (downhill along +x, the wave's direction)", minimum=-60.0)
    damping: float = param(0.2, "damping η of the vibrations relative to the rigid-body motion (inertial mechanics)",
                           minimum=0.0)  # fmt: skip
    mechanics: str = param("overdamped", "overdamped: the mobility model ζ M v = F, the paper's (with Coulomb friction "
                           "the friction-dominated regime), explicit Euler under its bending-stiffness bound; "
                           "overdamped-implicit: the same model by backward Euler, implicit_substeps steps per chemistry "
                           "step and no stability bound (needs contact_solve=implicit); inertial: symplectic Euler with "
                           "lumped mass", choices=("overdamped", "overdamped-implicit", "inertial"))  # fmt: skip
    implicit_substeps: int = param(1, "overdamped-implicit mechanics: backward-Euler steps per chemistry step (accuracy "
                                   "sets them, not the bending stiffness)", minimum=1)  # fmt: skip
    ground_passes: int = param(1, "overdamped-implicit mechanics: the ground's solve and the step's minimisation taken "
                               "this many times, each from the last solution's velocity (the split's error falls each "
                               "pass)", minimum=1)
    drag: float = param(60.0, "overdamped mechanics: drag ζ per unit mass, a property of the medium, the same at every "
                        "level (60 ≈ 2 η_ground of the level-4 sphere); auto (0) = 2 η_ground of the mesh, which the "
                        "explicit contact needs", minimum=0.0, auto=True)  # fmt: skip
    drag_frame: str = param("lab", "overdamped mechanics: lab: the drag brakes every motion; body: it acts on the velocity "
                            "relative to the body's horizontal translation, which the friction alone sets (needs "
                            "contact_solve=implicit)", choices=("lab", "body"))  # fmt: skip
    dt: float = param(0.5, "chemistry step (explicit FHN); auto (0) = 0.4 × the settled shell's stability bound, or "
                      "less where frames asks for more frames", minimum=0.0, auto=True)  # fmt: skip
    mass_corrections: int = param(2, "Richardson steps from the lumped towards the consistent mass in the diffusion",
                                  minimum=0)  # fmt: skip
    fhn_scheme: str = param("explicit", "chemistry step: explicit (Euler) or heun (second order, two diffusion "
                            "applications a step; the front's speed error from dt falls from first to second order)",
                            choices=("explicit", "heun"))
    ramp: bool = param(True, "the active reference follows c linearly over each chemistry step's mechanics substeps")
    safety: float = param(0.9, "mechanics step = dt / n, the largest within safety × its stability bound", positive=True)
    settle: float = param(40.0, "time on the ground before the wave starts, c = 0 (overdamped: this long with the "
                          "inertial mechanics, then as long overdamped)", minimum=0.0)  # fmt: skip
    periods: float = param(4.0, "run length in periods T₀ of the FHN kinetics", positive=True)
    frames: int = param(48, "frames written between t = 0 and the end", minimum=1)
    noise: float = param(0.0, "random perturbation / R of the rest shape (seeded by --seed): an ensemble of gaits",
                         minimum=0.0)  # fmt: skip
    elongation: float = param(1.0, "rest shape: the scene's shape stretched by this factor along x, the wave's "
                              "direction (a shape parameter for gradients and sweeps)", positive=True)  # fmt: skip
    sensitive: bool = param(True, "true: the wave runs on the deformed shell; false: on the rest shell (the twin)")
    transport: str = transport_parameter()
    mirror: bool = param(False, "start the wave at the mirror image of the origin (x → -x)")
    dtype: str = param("float32", "float32 or float64", choices=("float32", "float64"))


def ground_lift(mesh: Mesh, weight: float, ground: Ground) -> tuple:
    """(lift, depth): adding `lift` to z makes the mesh's lowest limit point touch the ground z = 0;
    `depth` is how deep a rigid body of `weight` sinks into the contact (Σ k max(-z_i, 0)² = weight
    over the limit points, or Σ_q k max(-z_q, 0)² dω̄⁰_q over the quadrature points for the area
    contact). The walkers start at lift - depth: little is left to settle."""
    from scipy.optimize import brentq

    z = limit_positions(mesh, device="cpu", dtype="float64")[:, 2]
    lift = -z.min()
    weights = np.ones_like(z)
    if ground.contact == "area":
        surface = limit_surface(mesh, device="cpu", dtype="float64")
        z, weights = surface.points[:, 2], surface.area
    height = z + lift
    depth = 0.0
    if weight > 0 and ground.stiffness > 0:
        def excess(d):
            return ground.stiffness * np.sum(weights * np.maximum(d - height, 0.0) ** 2) - weight

        depth = brentq(excess, 0.0, height.max())
    return float(lift), float(depth)


def nearest_vertex(mesh: Mesh, point) -> int:
    return int(np.argmin(np.linalg.norm(mesh.vertices - np.asarray(point, dtype=np.float64), axis=1)))


@dataclass(frozen=True)
class Placement:
    """A walker put down on the ground: its lifted `mesh`, `ground`, the contact's area per point `per`
    (1 for the point contact), the rigid contact `depth`, the wave's `origin_vertex`, the direction of
    propagation `forward` (+x, or -x mirrored)."""

    mesh: Mesh
    ground: Ground
    per: float
    depth: float
    origin_vertex: int
    forward: np.ndarray


def place_walker(mesh: Mesh, p, origin) -> Placement:
    """`mesh`, stretched by `p.elongation` along x about x = 0, on the ground (`ground_lift`, started at lift -
    depth) with the wave's origin vertex nearest `origin` (stretched alike; mirrored in x with `p.mirror`)."""
    stretch = np.array([p.elongation, 1.0, 1.0])
    mesh, origin = Mesh(mesh.vertices * stretch, mesh.triangles), stretch * np.asarray(origin, dtype=np.float64)
    area = limit_surface(mesh, device="cpu", dtype="float64").area.sum()
    weight = p.density * p.gravity * area
    per = 1.0
    if p.contact == "area":  # the paper's k and β per point, spread over the area a of one
        per = p.contact_area or area / mesh.n_vertices
    if p.sharpness == math.inf and p.contact_solve != "implicit":
        raise SceneError("sharpness=inf (Coulomb's law) needs the implicit contact: --set contact_solve=implicit")
    if p.mechanics == "overdamped-implicit" and p.contact_solve != "implicit":
        raise SceneError("mechanics=overdamped-implicit solves the ground implicitly: --set contact_solve=implicit")
    if p.drag_frame == "body" and (not p.mechanics.startswith("overdamped") or p.contact_solve != "implicit"):
        raise SceneError("drag_frame=body is a drag of the overdamped mechanics that leaves the translation to the "
                         "friction: --set mechanics=overdamped --set contact_solve=implicit")  # fmt: skip
    if p.slope > 60.0:
        raise SceneError(f"bad value for slope: {p.slope!r} (must be <= 60 degrees)")
    ground = Ground(stiffness=p.stiffness / per, damping=p.contact_damping / per, friction=p.friction,
                    sharpness=p.sharpness, contact=p.contact, solve=p.contact_solve, sweeps=p.contact_sweeps,
                    slope=math.radians(p.slope))  # fmt: skip
    touching, depth = ground_lift(mesh, weight, ground)
    lift = np.array([0.0, 0.0, touching - depth])
    mirror = np.array([-1.0, 1.0, 1.0]) if p.mirror else np.ones(3)
    lifted = Mesh(mesh.vertices + lift, mesh.triangles)
    origin_vertex = nearest_vertex(lifted, mirror * np.asarray(origin, dtype=np.float64) + lift)
    forward = np.array([-1.0, 0.0, 0.0]) if p.mirror else np.array([1.0, 0.0, 0.0])
    return Placement(lifted, ground, per, depth, origin_vertex, forward)


def walker_model(mesh: Mesh, ps: list, ground: Ground, *, size: float, bilayer: bool, rule: str, device):
    """The walkers' model on `mesh` (one world per parameter set of `ps`, a `Mesh.union` for several):
    the Koiter or bilayer shell with the per-world couplings and moduli, volume, gravity, ground and
    the FHN wave of ps[0]."""
    p = ps[0]
    builder = ModelBuilder(mesh, device=device, dtype=p.dtype, rule=rule)
    add_shell = builder.add_bilayer if bilayer else builder.add_koiter
    add_shell(thickness=[q.thickness for q in ps], young=[q.young for q in ps], poisson=p.poisson,
              AC=[q.AC for q in ps], AI=[q.AI for q in ps])  # fmt: skip
    if any(q.mu_v > 0 for q in ps):
        builder.add_volume(penalty=[q.mu_v * q.young * q.thickness / size**4 for q in ps])
    builder.add_gravity(g=p.gravity, density=p.density).add_ground(ground)
    builder.add_fitzhugh_nagumo(gamma=p.gamma, nu=p.nu, kappa=p.kappa, epsilon=p.epsilon, sensitive=p.sensitive,
                                mass_corrections=p.mass_corrections, transport=p.transport, scheme=p.fhn_scheme)
    return builder.finalize()


def implicit_step(p, chemistry_dt=None) -> float:
    """The overdamped-implicit mechanics' step: the chemistry step over `implicit_substeps` (before the wave is built,
    while settling, the scene's dt, or the parameter's default where dt is auto)."""
    return (chemistry_dt or p.dt or WalkerParameters.dt) / p.implicit_substeps


def walker_dynamics(model, p, dt=None):
    """The walkers' inertial (or overdamped) shell dynamics on `model`, bound by ω over the references the
    wave visits (`bound_over_reference_range`); its step `dt` (None: safety × the bound; overdamped-implicit:
    `implicit_step`, no bound)."""
    if p.mechanics == "overdamped-implicit":
        return model.dynamics(overdamped=True, implicit=True, drag=p.drag or None, drag_frame=p.drag_frame,
                              dt=dt or implicit_step(p), ground_passes=p.ground_passes)
    if p.mechanics == "overdamped":
        dynamics = model.dynamics(overdamped=True, drag=p.drag or None, drag_frame=p.drag_frame, safety=p.safety)
    else:
        dynamics = model.dynamics(damping=p.damping, safety=p.safety)
    dynamics.set_time_step(dt, bound_over_reference_range(dynamics))
    return dynamics


def settled_walker_dynamics(model, p, settle_dt=None):
    """`walker_dynamics(model, p)` with the walker put down: `p.settle` time units on the ground at c = 0.
    An overdamped walker first settles as long with the inertial mechanics (damping p.damping), then goes
    on overdamped from the positions reached: overdamped alone, the sag's slowest mode relaxes over
    ζ / ω_min², and 40 time units at level 4 left less than half the sag (0.56% of R against 1.29%);
    inertial alone, the body's bounce on the ground rings on. `settle_dt`: the step while settling, or
    for an overdamped walker the pair (inertial, overdamped); None: safety × each bound. Returns
    (dynamics, the step or pair used, as `settle_dt` takes it, and the steps taken with each)."""
    if not p.mechanics.startswith("overdamped"):
        dynamics = walker_dynamics(model, p, settle_dt)
        dynamics.run_until(p.settle)
        return dynamics, dynamics.dt, (dynamics.steps,)
    inertial_dt, overdamped_dt = settle_dt if settle_dt is not None else (None, None)
    settling = walker_dynamics(model, replace(p, mechanics="inertial"), inertial_dt)
    settling.run_until(p.settle)
    dynamics = walker_dynamics(model, p, overdamped_dt)
    dynamics.state.set("x", settling.positions())
    dynamics.time, dynamics.steps = settling.time, settling.steps
    dynamics.run_until(2 * p.settle)
    return dynamics, (settling.dt, dynamics.dt), (settling.steps, dynamics.steps - settling.steps)


def bound_over_reference_range(dynamics) -> float:
    """ω for the mechanics' bound: the largest over the uniform references c = 0, c = 1 and the
    FHN lower branch's c = -0.4 (the wave spans [-0.4, 1]); the contraction stiffens the shell."""
    shell, omegas = dynamics.shell, [dynamics.omega_max]
    n = shell.mesh.n_vertices
    for value in (1.0, -0.4):
        shell.update_reference(wp.full(n, value, dtype=shell.scalar, device=shell.device))
        omegas.append(dynamics.largest_frequency())
    shell.update_reference(wp.zeros(n, dtype=shell.scalar, device=shell.device))
    return max(omegas)


def check_walker_steps(p) -> None:
    """Refuse, before anything is built, an explicit dt that makes the walk to its end absurdly long."""
    if p.dt:
        t_end = p.periods * fhn_kinetic_period(p.nu, p.kappa, p.epsilon)
        check_steps(t_end / p.dt, p.dt, t_end)


class WalkerRun(WaveClock):
    """An FHN wave on an inertial active shell on the ground: the sphere, prism, cube and bilayer walkers.

    `mesh` is put on the ground (`ground_lift`) in its orientation; `radius` is the length unit of
    the speed (R); `size` the length in the volume penalty μV Y h / size⁴; `origin` the wave's origin
    point in the mesh's coordinates (mirrored in x with `mirror`); `forward`, the direction of
    propagation, is +x (-x mirrored). The meshes are mirror-symmetric in x and y: the origin lies on
    the mirror plane y = 0 (no sideways walk) and mirroring it is exact. `bilayer`: the shell's
    active reference is the supplement's bilayer model. `mechanics_dt`, when given, is the mechanics' step
    while the shell settles, a pair (inertial, overdamped) for an overdamped walker
    (`settled_walker_dynamics`; default: safety × its bound; a batch's worlds share the strictest).
    """

    def __init__(self, name: str, mesh: Mesh, p, *, radius: float, size: float, origin, bilayer: bool = False,
                 rule: str = "3", device=None, mechanics_dt=None, report=print):  # fmt: skip
        check_walker_steps(p)
        placed = place_walker(mesh, p, origin)
        mesh, per, depth = placed.mesh, placed.per, placed.depth
        self.name, self.mesh, self.p, self.radius = name, mesh, p, radius
        self.origin_vertex, self.forward = placed.origin_vertex, placed.forward
        self.model = walker_model(mesh, [p], placed.ground, size=size, bilayer=bilayer, rule=rule, device=device)
        self.shell = self.model.shell
        self.dynamics, self.settle_dt, self.settle_steps = settled_walker_dynamics(self.model, p, mechanics_dt)
        self.period_kinetic = fhn_kinetic_period(p.nu, p.kappa, p.epsilon)
        settled = self.dynamics.positions()
        self.rest_height = float(self.dynamics.mass @ mesh.vertices[:, 2] / self.dynamics.total_mass)  # rigid, in contact
        self.contact_depth = depth
        # a moving surface is re-read every chemistry step: matrix-free K c (assembly costs ~60 K c's)
        self.operator = self.model.operator(settled if p.sensitive else None, assembled=not p.sensitive)
        width = p.width or 1.5 * mean_edge(mesh)
        c0, _ = gaussian_pulse(self.operator, self.origin_vertex, width / radius, gamma=p.gamma, radius=radius)
        t_end = p.periods * self.period_kinetic
        dt = p.dt or min(AUTO_DT_SAFETY * self.model.wave(self.operator, c0=c0).stable_dt, t_end / p.frames)
        self.wave = self.model.wave(self.operator, c0=c0, dt=dt)
        self.initial_total = self.wave.total()
        self.balance = ChemicalBalance(mesh, sensitive=p.sensitive, rule=rule, device=device, dtype=p.dtype)
        self.rotation = BodyRotation(self.dynamics.mass)
        self.arrival = FirstArrival(c0, device=self.shell.device, scalar=self.shell.scalar)
        self.steps_per_frame = max(1, round(t_end / p.frames / self.wave.dt))
        with wp.ScopedDevice(self.shell.device):
            self._origin = wp.array([self.origin_vertex], dtype=wp.int32)
            self._trace_row = wp.zeros(1, dtype=wp.int32)
            self._trace_rows = wp.zeros((self.steps_per_frame, TRACE_COLUMNS - 1), dtype=self.shell.scalar)
        if p.mechanics == "overdamped-implicit":
            self.dynamics.set_time_step(implicit_step(p, dt))
        self.coupled = Walking(self.dynamics, self.wave, sensitive=p.sensitive, recorder=self._record_trace_row,
                               ramp=p.ramp)  # fmt: skip
        self.frames = max(1, round(t_end / (self.steps_per_frame * self.wave.dt)))
        if self.frames < p.frames:
            report(f"{self.frames} frames, not the {p.frames} asked for: a frame holds whole chemistry steps of dt = "
                   f"{dt:.4g} over {t_end:.4g}; --set dt=auto (or a smaller dt) gives every frame")  # fmt: skip
        drag = self.dynamics.drag if p.mechanics.startswith("overdamped") else 0.0
        resolved = replace(p, width=width, drag=drag, dt=dt, contact_area=per if p.contact == "area" else 0.0)
        self.resolved = {**as_dict(resolved), "mechanics_dt": self.dynamics.dt, "substeps": self.coupled.substeps,
                         "period_kinetic": self.period_kinetic}  # fmt: skip
        n = mesh.n_vertices
        self.series = {"positions": (n, 3), "velocities": (n, 3), "concentration": (n,), "inhibitor": (n,),
                       "reaction_amount": (), "reaction_per_vertex": (n,), "first_arrival": (n,),
                       "trace": (self.steps_per_frame, TRACE_COLUMNS)}  # fmt: skip
        self.ground_size = 8.0 * radius
        self.trace = np.empty((0, TRACE_COLUMNS))  # every chemistry step: t, c_origin, centre of mass, origin
        self._frame_trace = np.repeat(self._sample()[None], self.steps_per_frame, axis=0)
        self.snapshot = None
        self.concentrations = []  # per frame: the control concentrations, for the run's colour scale (run_range)
        self.time_unit = FHN_TIME_UNIT

    def _sample(self) -> np.ndarray:
        c = self.wave.c.numpy()[self.origin_vertex]
        x = self.dynamics.positions()
        return np.array([self.wave.time, c, *(self.dynamics.mass @ x / self.dynamics.total_mass), *x[self.origin_vertex]])

    def frame(self) -> dict:
        return {**self.coupled.state.to_frame(), "reaction_amount": np.array(self.wave.produced()),
                "reaction_per_vertex": self.wave.produced_per_vertex(), "first_arrival": self.arrival.times(self.wave.dt), "trace": self._frame_trace}  # fmt: skip

    def _record_trace_row(self) -> None:
        self.dynamics.solver.launch_trace_row(self.dynamics.state, self.wave.c, self._origin, self._trace_row,
                                              self._trace_rows)  # fmt: skip
        self.arrival.launch(self.wave.c)

    def advance_frame(self) -> None:
        """One frame of coupled steps on the device; the trace rows (one per chemistry step) are read once."""
        start = self.wave.steps
        self._trace_row.zero_()
        self.coupled.advance(self.steps_per_frame)
        times = (start + np.arange(1, self.steps_per_frame + 1)) * self.wave.dt
        self._frame_trace = np.column_stack([times, self._trace_rows.numpy().astype(np.float64)])

    def restore(self, frame: dict) -> None:
        """Continue from a saved frame (HDF5 resume): positions, velocities, c, w, the reaction's amount and the time."""
        restore_walk(self, frame, self.p.sensitive)

    def record(self, time: float, frame: dict, stored: bool = False) -> None:
        """Append the frame's trace rows (new times only), check the chemical's balance (C(0) plus the
        reaction's amount) and keep the concentrations and the snapshot for the rendered frame."""
        del stored  # written and resumed frames carry the same trace
        self.concentrations.append(np.array(frame["concentration"]))
        self.balance.record(time, frame["positions"], frame["concentration"],
                            self.initial_total + float(frame["reaction_amount"]))  # fmt: skip
        self.rotation.record(frame["positions"])
        rows = np.asarray(frame["trace"])
        last = self.trace[-1, 0] if len(self.trace) else -np.inf
        self.trace = np.concatenate([self.trace, rows[rows[:, 0] > last + 1e-9 * self.wave.dt]])
        target = self.frames * self.steps_per_frame * self.wave.dt / 3
        if self.snapshot is None or abs(time - target) < abs(self.snapshot[0] - target):
            self.snapshot = (time, np.array(frame["positions"]), np.array(frame["concentration"]))

    def measurements(self) -> dict:
        return {"time": self.time, "mechanics_steps": self.steps * self.coupled.substeps,
                "contact_depth_R": self.contact_depth / self.radius, **self.balance.measurements(),
                **arrival_measurements(self.arrival.times(self.wave.dt)),
                **locomotion(self.trace, self.forward, self.radius, self.rest_height, self.period_kinetic),
                **self.rotation.measurements(self.forward)}  # fmt: skip

    def figures(self, stem: str) -> list:
        paths = [f"{stem}_locomotion.png", f"{stem}_frame.png"]
        locomotion_png([(self.name, self.p.sensitive, self.trace, self.forward, self.radius)], paths[0])
        frame_png(self, paths[1])
        return paths


def restore_walk(run, frame: dict, sensitive: bool) -> None:
    """A walker run's (or batch's: every world's frames joined) state from a saved frame: x, v, c, w, the reaction's
    amounts, the first arrivals and the time; the reference and, `sensitive`, the wave's operator follow."""
    run.coupled.state.assign_frame(frame)
    per_vertex = frame.get("reaction_per_vertex")  # NaN in a file written before it was stored
    run.wave.set_produced(float(frame["reaction_amount"]),
                          per_vertex if per_vertex is not None and np.isfinite(per_vertex).all() else None)
    run.wave.steps = int(round(frame["time"] / run.wave.dt))
    run.wave.time = float(frame["time"])  # as the uninterrupted run summed it
    run.arrival.restore(frame["first_arrival"], run.wave.steps, run.wave.dt)
    run.shell.update_reference(run.wave.c)
    if sensitive:
        run.operator.update(run.dynamics.x)
    wp.synchronize_device(run.shell.device)


def sphere_walker_recipe(p, *, mesh=None, device=None, bilayer=False, report=print) -> tuple:
    """The sphere walker's noiseless mesh and `WalkerRun` options: the icosphere rests on the vertex at its
    south pole (its coordinate planes are mirror planes), the wave starts on the equator at -x
    (mirrored: +x)."""
    R = p.radius
    mesh = scene_mesh(mesh, lambda: icosphere(R, p.level), report, size=("level", p.level, icosphere), device=device)
    return mesh, {"radius": R, "size": R, "origin": [-R, 0.0, 0.0], "bilayer": bilayer}


def box_walker_recipe(p, make_box, origins: dict, *, radius: float, axis_to_x=False, mesh=None, device=None,
                      report=print) -> tuple:  # fmt: skip
    """A box walker's noiseless mesh and `WalkerRun` options: resting on a face, `make_box(L, divisions)`
    centred at 0 (`axis_to_x`: a prism, turned so that its axis lies along x and a square face down);
    the wave starts at origins[p.origin] × L (in the turned frame)."""
    L = p.edge

    def build():
        box = make_box(L, p.divisions)
        if axis_to_x:  # (x, y, z) -> (z, x, y): axis along x, the square face at -y down
            box = Mesh(box.vertices[:, [2, 0, 1]], box.triangles)
        return box

    mesh = scene_mesh(mesh, build, report, size=("divisions", p.divisions, make_box), device=device)
    origin = np.asarray(origins[p.origin], dtype=np.float64) * L
    return mesh, {"radius": radius, "size": L, "origin": origin, "rule": p.rule}


def sphere_walker_run(name: str, p, *, mesh=None, device=None, bilayer=False, seed=0, report=print) -> WalkerRun:
    """The sphere walker (`sphere_walker_recipe`), its rest shape perturbed by `p.noise` (seeded)."""
    mesh, options = sphere_walker_recipe(p, mesh=mesh, device=device, bilayer=bilayer, report=report)
    return WalkerRun(name, imperfect(mesh, p.noise * p.radius, seed), p, device=device, report=report, **options)


def box_walker_run(name: str, p, make_box, origins: dict, *, radius: float, axis_to_x=False, mesh=None, device=None,
                   seed=0, report=print) -> WalkerRun:  # fmt: skip
    """A box walker (`box_walker_recipe`), its rest shape perturbed by `p.noise` × radius (seeded)."""
    mesh, options = box_walker_recipe(p, make_box, origins, radius=radius, axis_to_x=axis_to_x, mesh=mesh,
                                      device=device, report=report)  # fmt: skip
    return WalkerRun(name, imperfect(mesh, p.noise * radius, seed), p, device=device, report=report, **options)
