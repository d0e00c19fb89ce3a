"""Walker scenes (SPEC §3 "Walker scenes", §4, §6; paper Fig. 3a): FitzHugh–Nagumo waves drive an
active shell that walks on the ground under gravity and friction.

A walker run: the shell is put down touching the ground (a symmetric contact, an equilibrium),
settles for `settle` time units with c = 0, then the wave starts at t = 0 from a narrow Gaussian at
the origin vertex (w = 0). Each chemistry step the active reference follows c and the mechanics
advance to the same time (`coupled.Walking`). Measured (docs/walkers.md): the oscillation period T
from the upward half-maximum crossings of c at the origin vertex, the centre-of-mass displacement,
and the speed in R per T along the direction of propagation (from the origin towards the far side).
"""

from __future__ import annotations


import numpy as np
import warp as wp

from .coupled import Walking
from .dynamics import Ground, OverdampedDynamics, ShellDynamics
from .geometry import limit_positions
from .laplace import LaplaceBeltrami
from .mesh import Mesh
from .balance import ChemicalBalance, FirstArrival, arrival_measurements
from .scene import TRANSPORT, Param, WaveClock, frame_png, mean_edge, scene_mesh
from .shell import Shell
from .initial import gaussian_pulse
from .chemistry import fhn_kinetic_period
from .waves import FitzHughNagumo

WALKER_PARAMETERS = {
    "young": Param(200.0, "Y (ours): the sphere walker's elastic sag under its weight is about 1% of R "
                   "(docs/walkers.md); stiffer shells need proportionally smaller mechanics steps", positive=True),  # fmt: skip
    "poisson": Param(0.33, "Poisson ratio (SPEC §3)"),
    "gamma": Param(0.2, "FHN diffusion γ (SPEC §5)", positive=True),
    "nu": Param(-0.01, "FHN threshold ν (SPEC §5; < 0: the medium oscillates)"),
    "kappa": Param(1e-4, "FHN κ (SPEC §5)", minimum=0.0),
    "epsilon": Param(0.005, "FHN ε (SPEC §5)", minimum=0.0),
    "width": Param(0.0, "width of the initial Gaussian (length); 0 = 1.5 mean control edges, the narrowest the "
                   "mesh resolves", minimum=0.0),  # fmt: skip
    "density": Param(0.01, "surface mass density ρ (SPEC §4)", positive=True),
    "gravity": Param(0.5, "g (SPEC §4)", minimum=0.0),
    "stiffness": Param(10.0, "ground contact k (SPEC §4)", minimum=0.0),
    "contact_damping": Param(0.5, "ground contact damping β (SPEC §4)", minimum=0.0),
    "contact": Param("point", "point: k and β per limit point of a control vertex (SPEC §4); area (ours): a pressure "
                     "k/a z² - β/a v_z on the limit surface, which converges under refinement", choices=("point", "area")),  # fmt: skip
    "contact_area": Param(0.0, "area contact: the area a per limit point of the SPEC's k and β; 0 = this mesh's mean rest "
                          "area per control vertex (the same total stiffness as the point law); fix it to compare meshes",
                          minimum=0.0),  # fmt: skip
    "friction": Param(0.1, "friction coefficient μ (SPEC §4)", minimum=0.0),
    "sharpness": Param(0.1, "friction regularisation k_f (SPEC §4)", minimum=0.0),
    "damping": Param(0.2, "background damping η of the vibrations relative to the rigid-body motion (ours; no "
                     "net force or torque): they decay in 1/η = 5 ≪ T ≈ 276 (inertial mechanics)", minimum=0.0),  # fmt: skip
    "mechanics": Param("inertial", "inertial: symplectic Euler with lumped mass (chosen by measurement, docs/walkers.md); "
                       "overdamped: the mobility model ζ M v = F (no inertia)", choices=("inertial", "overdamped")),  # fmt: skip
    "drag": Param(0.0, "overdamped mechanics: drag ζ per unit mass against the lab frame; 0 = 2 η_ground, the least "
                  "that keeps the lagged contact damping stable with gain 1/2", minimum=0.0),  # fmt: skip
    "dt": Param(0.5, "chemistry step (explicit FHN; bound ≈ 1.7): the kinetic period is within 0.2% of its "
                "dt → 0 value", positive=True),  # fmt: skip
    # SPEC §5; BENCHMARKS.md "Accuracy": two corrections carry the FHN front at level 4 (10.5% slow), lumped pins it
    "mass_corrections": Param(2, "FHN diffusion: p Richardson steps from the lumped mass (0) towards the consistent "
                              "one", minimum=0),  # fmt: skip
    "ramp": Param(True, "the active reference follows c linearly over each chemistry step's mechanics substeps; "
                  "false: it jumps at each step, which kicks the stiffest modes (docs/walkers.md)"),
    "safety": Param(0.9, "mechanics step = dt / n, the largest within safety × its stability bound", positive=True),
    "settle": Param(40.0, "time on the ground before the wave starts, c = 0 (the drop's bounce decays)", minimum=0.0),
    "periods": Param(4.0, "run length in periods T₀ of the FHN kinetics (SPEC values: T₀ = 275.8)", positive=True),
    "frames": Param(48, "frames written between t = 0 and the end", minimum=1),
    "sensitive": Param(True, "true: the wave runs on the deformed shell; false: on the rest shell (the twin)"),
    "transport": TRANSPORT,
    "mirror": Param(False, "start the wave at the mirror image of the origin (x → -x): the walk must mirror"),
    "dtype": Param("float32", "float32 (default) or float64", choices=("float32", "float64")),
}


def walker_parameters(**scene) -> dict:
    """WALKER_PARAMETERS updated with a scene's own parameters."""
    return {**WALKER_PARAMETERS, **scene}


def ground_lift(mesh: Mesh, weight: float, ground: Ground) -> tuple:
    """(lift, depth): adding `lift` to z makes the mesh's lowest limit point touch the ground z = 0;
    `depth` is how deep a rigid body of `weight` sinks into the contact (Σ k max(-z_i, 0)² = weight
    over the limit points, or Σ_q k max(-z_q, 0)² dω̄⁰_q over the quadrature points for the area
    contact). The walkers start at lift - depth: little is left to settle."""
    from scipy.optimize import brentq

    from .geometry import limit_surface

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


class WalkerRun(WaveClock):
    """An FHN wave on an inertial active shell on the ground: the sphere, prism, cube and bilayer walkers.

    `mesh` is put on the ground (`ground_lift`) in its orientation; `radius` is the length unit of
    the speed (R); `size` the length in the volume penalty μV Y h / size⁴; `origin` the wave's origin
    point in the mesh's coordinates (mirrored in x with p["mirror"]); `forward`, the direction of
    propagation, is +x (-x mirrored). The meshes are mirror-symmetric in x and y: the origin lies on
    the mirror plane y = 0 (no sideways walk) and mirroring it is exact.
    """

    def __init__(self, name: str, mesh: Mesh, p: dict, *, radius: float, size: float, origin, model: str = "koiter",
                 rule: str = "3", device=None):  # fmt: skip
        from .geometry import limit_surface

        area = limit_surface(mesh, device="cpu", dtype="float64").area.sum()
        weight = p["density"] * p["gravity"] * area
        per = 1.0
        if p["contact"] == "area":  # the SPEC's k and β per point, spread over the area a of one
            per = p["contact_area"] or area / mesh.n_vertices
        ground = Ground(stiffness=p["stiffness"] / per, damping=p["contact_damping"] / per, friction=p["friction"],
                        sharpness=p["sharpness"], contact=p["contact"])  # fmt: skip
        touching, depth = ground_lift(mesh, weight, ground)
        lift = np.array([0.0, 0.0, touching - depth])
        mesh = Mesh(mesh.vertices + lift, mesh.triangles)
        self.name, self.mesh, self.p, self.radius = name, mesh, p, radius
        dtype = p["dtype"]
        mirror = np.array([-1.0, 1.0, 1.0]) if p["mirror"] else np.ones(3)
        self.origin_vertex = nearest_vertex(mesh, mirror * np.asarray(origin, dtype=np.float64) + lift)
        self.forward = np.array([-1.0, 0.0, 0.0]) if p["mirror"] else np.array([1.0, 0.0, 0.0])
        self.shell = Shell(mesh, thickness=p["thickness"], young=p["young"], poisson=p["poisson"], AC=p["AC"],
                           AI=p["AI"], volume_penalty=p["mu_v"] * p["young"] * p["thickness"] / size**4, model=model,
                           rule=rule, device=device, dtype=dtype)  # fmt: skip
        common = dict(density=p["density"], gravity=p["gravity"], ground=ground, safety=p["safety"])
        if p["mechanics"] == "overdamped":
            self.dynamics = OverdampedDynamics(self.shell, drag=p["drag"] or None, **common)
        else:
            self.dynamics = ShellDynamics(self.shell, damping=p["damping"], **common)
        self.period_kinetic = fhn_kinetic_period(p["nu"], p["kappa"], p["epsilon"])
        self._bound_over_reference_range()
        self.dynamics.run_until(p["settle"])
        settled = self.dynamics.positions()
        self.rest_height = float(self.dynamics.mass @ mesh.vertices[:, 2] / self.dynamics.total_mass)  # rigid, in contact
        self.contact_depth = depth
        # a moving surface is re-read every chemistry step: matrix-free K c (assembly costs ~60 K c's, BENCHMARKS.md "Speed")
        self.operator = LaplaceBeltrami(mesh, settled if p["sensitive"] else None, rule=rule, assembled=not p["sensitive"],
                                        device=device, dtype=dtype)  # fmt: skip
        width = p["width"] or 1.5 * mean_edge(mesh)
        c0, _ = gaussian_pulse(self.operator, self.origin_vertex, width / radius, gamma=p["gamma"], radius=radius)
        self.wave = FitzHughNagumo(self.operator, p["gamma"], p["nu"], p["kappa"], p["epsilon"], c0=c0, dt=p["dt"],
                                   mass_corrections=p["mass_corrections"], transport=p["transport"])  # fmt: skip
        self.initial_total = self.wave.total()
        self.balance = ChemicalBalance(mesh, sensitive=p["sensitive"], rule=rule, device=device, dtype=dtype)
        self.arrival = FirstArrival(c0, device=self.shell.device, scalar=self.shell.scalar)
        t_end = p["periods"] * self.period_kinetic
        self.steps_per_frame = max(1, round(t_end / p["frames"] / self.wave.dt))
        with wp.ScopedDevice(self.shell.device):
            self._trace_row = wp.zeros(1, dtype=wp.int32)
            self._trace_rows = wp.zeros((self.steps_per_frame, TRACE_COLUMNS - 1), dtype=self.shell.scalar)
        self.coupled = Walking(self.dynamics, self.wave, sensitive=p["sensitive"], recorder=self._record_trace_row,
                               ramp=p["ramp"])  # fmt: skip
        self.frames = max(1, round(t_end / (self.steps_per_frame * self.wave.dt)))
        self.resolved = {**p, "width": width, "mechanics_dt": self.dynamics.dt, "substeps": self.coupled.substeps,
                         "drag": getattr(self.dynamics, "drag", 0.0), "contact_area": per if p["contact"] == "area" else 0.0,
                         "period_kinetic": self.period_kinetic}  # fmt: skip
        n = mesh.n_vertices
        self.series = {"positions": (n, 3), "velocities": (n, 3), "concentration": (n,), "inhibitor": (n,),
                       "reaction_amount": (), "first_arrival": (n,),
                       "trace": (self.steps_per_frame, TRACE_COLUMNS)}  # fmt: skip
        self.field_range = (0.0, 1.0)
        self.ground_size = 8.0 * radius
        self.trace = np.empty((0, TRACE_COLUMNS))  # every chemistry step: t, c_origin, centre of mass, origin
        self._frame_trace = np.repeat(self._sample()[None], self.steps_per_frame, axis=0)
        self.snapshot = None

    def _bound_over_reference_range(self) -> None:
        """ω for the mechanics' bound: the largest over the uniform references c = 0, c = 1 and the
        FHN lower branch's c = -0.4 (the wave spans [-0.4, 1]); the contraction stiffens the shell."""
        shell, omegas = self.shell, [self.dynamics.omega_max]
        for value in (1.0, -0.4):
            shell.update_reference(wp.full(self.mesh.n_vertices, value, dtype=shell.scalar, device=shell.device))
            omegas.append(self.dynamics.largest_frequency())
        shell.update_reference(wp.zeros(self.mesh.n_vertices, dtype=shell.scalar, device=shell.device))
        self.dynamics.set_time_step(None, max(omegas))

    def _sample(self) -> np.ndarray:
        c = self.wave.c.numpy()[self.origin_vertex]
        x = self.dynamics.positions()
        return np.array([self.wave.time, c, *(self.dynamics.mass @ x / self.dynamics.total_mass), *x[self.origin_vertex]])

    def frame(self) -> dict:
        return {"positions": self.dynamics.positions(), "velocities": self.dynamics.velocities(),
                "concentration": self.wave.concentration(), "inhibitor": self.wave.inhibitor(),
                "reaction_amount": np.array(self.wave.produced()), "first_arrival": self.arrival.times(self.wave.dt),
                "trace": self._frame_trace}  # fmt: skip

    def _record_trace_row(self) -> None:
        self.dynamics.solver.launch_trace_row(self.dynamics.state, self.wave.c, self.origin_vertex, self._trace_row,
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
        real, d = self.shell._real, self.dynamics
        d.x.assign(np.asarray(frame["positions"]).astype(real))
        d.v.assign(np.asarray(frame["velocities"]).astype(real))
        self.wave.c.assign(np.asarray(frame["concentration"]).astype(real))
        self.wave.w.assign(np.asarray(frame["inhibitor"]).astype(real))
        self.wave.set_produced(float(frame["reaction_amount"]))
        self.wave.steps = int(round(frame["time"] / self.wave.dt))
        self.wave.time = self.wave.steps * self.wave.dt
        self.arrival.restore(frame["first_arrival"], self.wave.steps, self.wave.dt)
        self.shell.update_reference(self.wave.c)
        if self.p["sensitive"]:
            self.operator.update(d.x)
        wp.synchronize_device(self.shell.device)

    def record(self, time: float, frame: dict, stored: bool = False) -> None:
        """Append the frame's trace rows (new times only), check the chemical's balance (C(0) plus the
        reaction's amount) and keep the snapshot for the rendered frame."""
        del stored  # written and resumed frames carry the same trace
        self.balance.record(time, frame["positions"], frame["concentration"],
                            self.initial_total + float(frame["reaction_amount"]))  # fmt: skip
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
                **locomotion(self.trace, self.forward, self.radius, self.rest_height, self.period_kinetic)}  # fmt: skip

    def figures(self, stem: str) -> list:
        paths = [f"{stem}_locomotion.png", f"{stem}_frame.png"]
        locomotion_png([(self.name, self.p["sensitive"], self.trace, self.forward, self.radius)], paths[0])
        frame_png(self, paths[1])
        return paths


TRACE_COLUMNS = 8  # t, c at the origin vertex, centre of mass (3), the origin vertex's position (3)


def upward_crossings(t: np.ndarray, c: np.ndarray, level: float = 0.5) -> np.ndarray:
    """Times where c rises through `level`, linearly interpolated between samples."""
    k = np.flatnonzero((c[:-1] < level) & (c[1:] >= level))
    return t[k] + (level - c[k]) / (c[k + 1] - c[k]) * (t[k + 1] - t[k])


def measured_period(crossings: np.ndarray) -> float | None:
    """T: the mean interval between crossings (None with fewer than two)."""
    return float(np.mean(np.diff(crossings))) if len(crossings) >= 2 else None


def locomotion(trace: np.ndarray, forward, radius: float, rest_height: float, period_kinetic: float) -> dict:
    """Period, displacement and speed from a trace (rows: t, c at the origin, centre of mass, origin).

    T: the mean interval between upward half-maximum crossings of c at the origin (None with
    fewer than two). The speed is measured over whole periods, between the first and the last
    crossing (the first pulse's start-up excluded), in R per T along `forward` (the propagation
    direction at the start); the displacement is the whole run's. Per period k (a pulse):
    `pulse_displacements_R` its forward displacement, and `pulse_alignment` the cosine between its
    horizontal displacement and the direction of propagation at its start, the horizontal
    direction from the origin vertex (the origin turns with the shell) to the centre of mass.
    `sag_R`: the elastic sag, how far the settled centre of mass lies below that of the rigid
    shell in the same contact (`rest_height`).
    """
    t, c, com, origin = trace[:, 0], trace[:, 1], trace[:, 2:5], trace[:, 5:8]
    forward = np.asarray(forward, dtype=np.float64)
    side = np.cross([0.0, 0.0, 1.0], forward)
    displacement = com[-1] - com[0]
    out = {"period_kinetic": period_kinetic, "period": None, "displacement": displacement.tolist(),
           "distance_R": float(displacement @ forward / radius), "lateral_R": float(displacement @ side / radius),
           "sag_R": float((rest_height - com[0, 2]) / radius), "speed_R_per_T": None, "pulse_displacements_R": [],
           "pulse_alignment": []}  # fmt: skip
    crossings = upward_crossings(t, c)
    period = measured_period(crossings)
    if period is not None:
        at = np.stack([np.interp(crossings, t, column) for column in np.hstack([com, origin]).T], axis=1)
        along = at[:, :3] @ forward
        step = np.diff(at[:, :2], axis=0)
        direction = at[:-1, :2] - at[:-1, 3:5]
        alignment = np.sum(step * direction, axis=1) / (np.linalg.norm(step, axis=1) * np.linalg.norm(direction, axis=1))
        out.update(period=period, pulse_displacements_R=(np.diff(along) / radius).tolist(),
                   pulse_alignment=alignment.tolist(), speed_R_per_T=float((along[-1] - along[0]) / radius / (len(crossings) - 1)))  # fmt: skip
    return out


def locomotion_png(runs, path, title: str = "walkers: displacement against time (paper Fig. 3a)") -> None:
    """Forward displacement of the centre of mass in R against t/T, one line per run
    (name, sensitive, trace, forward, radius); sensitive solid, insensitive dashed, as Fig. 3a."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import write_png

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for name, sensitive, trace, forward, radius in runs:
        t, c, com = trace[:, 0], trace[:, 1], trace[:, 2:5]
        scale = measured_period(upward_crossings(t, c)) or 1.0
        ax.plot(t / scale, (com - com[0]) @ np.asarray(forward) / radius, "-" if sensitive else "--",
                label=f"{name} ({'sensitive' if sensitive else 'insensitive'})")  # fmt: skip
    ax.set_xlabel("t / T (T: the measured oscillation period)")
    ax.set_ylabel("displacement / R (direction of propagation)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_png(fig, path)


def sphere_walker_run(name: str, p: dict, *, mesh=None, device=None, model="koiter", report=print) -> WalkerRun:
    """The sphere walker: the icosphere rests on the vertex at its south pole (its coordinate planes
    are mirror planes), the wave starts on the equator at -x (mirrored: +x)."""
    from .mesh import icosphere

    R = p["radius"]
    mesh = scene_mesh(mesh, lambda: icosphere(R, p["level"]), report)
    return WalkerRun(name, mesh, p, radius=R, size=R, origin=[-R, 0.0, 0.0], model=model, device=device)


def box_walker_run(name: str, p: dict, make_box, origins: dict, *, radius: float, axis_to_x=False, mesh=None,
                   device=None, report=print) -> WalkerRun:  # fmt: skip
    """A box walker resting on a face: `make_box(L, divisions)` centred at 0 (`axis_to_x`: a prism,
    turned so that its axis lies along x and a square face down); the wave starts at
    origins[p["origin"]] × L (in the turned frame)."""
    L = p["edge"]

    def build():
        box = make_box(L, p["divisions"] + p["divisions"] % 2)
        if axis_to_x:  # (x, y, z) -> (z, x, y): axis along x, the square face at -y down
            box = Mesh(box.vertices[:, [2, 0, 1]], box.triangles)
        return box

    mesh = scene_mesh(mesh, build, report)
    origin = np.asarray(origins[p["origin"]], dtype=np.float64) * L
    return WalkerRun(name, mesh, p, radius=radius, size=L, origin=origin, rule=p["rule"], device=device)
