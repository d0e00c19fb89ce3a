"""Quasi-static wave scenes: a telegraph wave on an active shell that is in equilibrium at every
relaxation (the oocytes, the box wave guides, buckling; docs/theory/scenes.md).

`TelegraphParameters` are the parameters these scenes share; `SphereParameters` and
`BoxParameters` add the surface's. `QuasiStaticWaveRun` builds the model (Koiter shell, volume
term, self-contact where asked, the telegraph wave), the initial pulse or front and the
`QuasiStatic` coupling, and runs it frame by frame; `sphere_wave_run` and `box_wave_run` are what
the scene scripts call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .boxes import box_wave_measurements, face_heights, imprint_measurements
from .balance import ChemicalBalance
from .chemistry import telegraph_total
from .coupled import COUPLINGS, FoldError, QuasiStatic
from .figures import arrival_map_png, frame_png, imprint_png, kymograph_png
from .initial import gaussian_pulse, steady_front
from .laplace import J_FLOOR
from .measurements import ArrivalTimes, oocyte_measurements, oocyte_profile
from .mesh import Mesh, icosphere
from .model import ModelBuilder
from .parameters import as_dict, param
from .relax import NEWTON_STEPS
from .runs import WaveClock, imperfect, mean_edge, scene_mesh, transport_parameter
from .schema import COUNTER
from .sizing import check_steps
from .waves import BlowUpError, TimeStepError


@dataclass(frozen=True)
class TelegraphParameters:
    """The quasi-static telegraph scenes' parameters (a scene adds or overrides its own)."""

    young: float = param(1.0, "Young's modulus Y: the unit of stress (quasi-static: only ratios matter)", positive=True)
    poisson: float = param(0.33, "Poisson ratio ν")
    gamma: float = param(1.0, "wave speed γ", positive=True)
    alpha: float = param(0.001, "telegraph dissipation α", minimum=0.0)
    dt: float = param(0.0, "time step; auto (0) = 0.4 × the rest surface's stability bound, shrunk so that the frames "
                      "asked for end on t_end", minimum=0.0, auto=True)  # fmt: skip
    frames: int = param(48, "frames written between t = 0 and t_end", minimum=1)
    sensitive: bool = param(True, "true: the wave runs on the deformed shell; false: on the rest shell (the twin)")
    transport: str = transport_parameter()
    coupling: str = param("quasi-static", "quasi-static: the shell relaxes to equilibrium after every relaxation "
                          "interval; overdamped: it moves by a backward-Euler step of ζ ṗ = f over it (tau_m)",
                          choices=COUPLINGS, legacy="quasi-static")
    tau_m: float = param(1.0, "overdamped coupling: the mechanical relaxation time τ_m = ζ S²/(Y h), S the scene's "
                         "size (R, L)", positive=True)
    mass_corrections: int = param(0, "Richardson steps from the lumped towards the consistent mass (0: lumped)",
                                  minimum=0)  # fmt: skip
    relax_every: int = param(0, "chemistry steps per relaxation; auto (0) = as many as keep the wave within half a control "
                             "edge between relaxations", minimum=0, auto=True)  # fmt: skip
    relax_tol: float = param(0.0, "relaxation tolerance, a residual strain; auto (0) = the dtype's default", minimum=0.0, auto=True)
    relax_iterations: int = param(0, "CG iterations per relaxation before the Newton finish; auto (0) = 2,000 on a CPU, "
                                  "20,000 on a GPU", minimum=0, auto=True)  # fmt: skip
    newton_steps: int = param(NEWTON_STEPS, "Newton steps a relaxation's finish may take", minimum=1)
    relax_method: str = param("auto", "auto: CG, then Newton where CG spends its budget; ncg: CG only; newton: "
                              "Newton only", choices=("auto", "ncg", "newton"))  # fmt: skip
    accept_unconverged: bool = param(False, "true: a relaxation that spends its budget is accepted (the shell lags its "
                             "reference) instead of stopping the run")  # fmt: skip
    dtype: str = param("float32", "float32 or float64", choices=("float32", "float64"))


@dataclass(frozen=True)
class SphereParameters(TelegraphParameters):
    """A sphere with a wave from its pole (oocytes, buckling)."""

    radius: float = param(10.0, "sphere radius R", positive=True)
    thickness: float = param(0.5, "shell thickness h (h/R = 0.05 at the default R)", positive=True)
    AC: float = param(0.0, "metric coupling AC")
    AI: float = param(0.0, "curvature coupling AI")
    mu_v: float = param(0.0, "volume penalty μV in units of Y h / R⁴", minimum=0.0)
    width: float = param(math.sqrt(2.0), "pulse width σR in length units (the paper's σ² = 2/R²)", positive=True)
    level: int = param(4, "icosphere level (level 4: 5,120 triangles)", minimum=1)
    mass_corrections: int = param(2, "Richardson steps from the lumped towards the consistent mass (2: the accurate "
                                  "wave shape and speed)", minimum=0)  # fmt: skip
    t_end: float = param(0.0, "end time; auto (0) = the scene's end (π R / γ: the wave's pole-to-pole time)", minimum=0.0, auto=True)
    noise: float = param(0.0, "random perturbation / R of the rest shape (seeded by --seed)", minimum=0.0)


@dataclass(frozen=True)
class BoxParameters(TelegraphParameters):
    """A box (cube, prism) with a wave from a face centre, an edge or a vertex (the wave guides)."""

    edge: float = param(20.0, "L: all edges of the box (L = 20 h)", positive=True)
    thickness: float = param(1.0, "shell thickness h", positive=True)
    width: float = param(math.sqrt(2.0), "pulse width in length units", positive=True)
    divisions: int = param(24, "control squares per face edge (even)", minimum=2, even=True)
    t_end: float = param(0.0, "end time; auto (0) = 2.2 L / γ: past the face opposite the origin, until the fronts that meet "
                         "there have peaked", minimum=0.0, auto=True)  # fmt: skip
    AC: float = param(0.2, "metric coupling AC")
    AI: float = param(0.0, "curvature coupling AI")
    mu_v: float = param(0.0, "volume penalty μV in units of Y h / L⁴", minimum=0.0)
    rule: str = param("3x4", "quadrature: the 3-point rule on 4 sub-triangles resolves the rounded box edges")


# relax_iterations 0: CG's budget before the Newton finish, by device (is_cuda): a GPU CG iteration costs
# ~1/6 of a CPU one against the same host factorization (docs/theory/shell.md)
CG_BUDGET = {False: 2000, True: 20000}
UNRESOLVED_MASS_GROWTH = 50.0  # a vertex's lumped mass over its rest value past which a blow-up is named a fold


def quasi_static_model(mesh: Mesh, ps: list, *, size: float, rule: str = "3", device=None, self_contact: bool = False):
    """The quasi-static scenes' Model: Koiter shell, volume term where μV > 0, self-contact where asked,
    the telegraph wave. `ps`: one parameter set, or one per batched world of `mesh` (a `Mesh.union`;
    they differ only in batch.PER_WORLD)."""
    p = ps[0]
    values = lambda name: [getattr(q, name) for q in ps] if len(ps) > 1 else getattr(p, name)  # noqa: E731
    builder = ModelBuilder(mesh, device=device, dtype=p.dtype, rule=rule)
    builder.add_koiter(thickness=values("thickness"), young=values("young"), poisson=p.poisson, AC=values("AC"),
                       AI=values("AI"))  # fmt: skip
    if any(q.mu_v > 0 for q in ps):
        penalties = [q.mu_v * q.young * q.thickness / size**4 for q in ps]
        builder.add_volume(penalty=penalties if len(ps) > 1 else penalties[0])
    if self_contact:
        builder.add_self_contact()
    builder.add_telegraph(gamma=p.gamma, alpha=p.alpha, sensitive=p.sensitive, mass_corrections=p.mass_corrections,
                          transport=p.transport)  # fmt: skip
    try:
        return builder.finalize()
    except ValueError as error:  # self-contact on too coarse a mesh: name the scene's switches
        if not self_contact:
            raise
        raise ValueError(f"{error}: raise --set level, or --set self_contact=false") from None


def initial_values(operator, origin, initial: dict, *, gamma: float, size: float) -> tuple:
    """(c0, v0) of `initial`: "gaussian" (sigma, distance) or "front" (k, delta), from `origin`."""
    if initial["kind"] == "gaussian":
        return gaussian_pulse(operator, origin, initial["sigma"], gamma=gamma, radius=size,
                              distance=initial.get("distance", "chord"))  # fmt: skip
    return steady_front(operator, origin, k=initial["k"], delta=initial["delta"], gamma=gamma)


def frame_clock(p, t_end: float, edge: float, bound: float, report=print) -> tuple:
    """(dt, relax_every, steps_per_frame, frames) of a quasi-static run to `t_end` with `p.frames`
    frames, control edges `edge` long and the wave's stability bound `bound` on the rest surface."""
    interval = t_end / p.frames
    dt = p.dt or 0.4 * bound
    relax_every = p.relax_every or max(1, int(min(0.5 * edge / p.gamma, interval) / dt))
    # (1e-9: a resumed run's stored dt and frames give back the same layout despite round-off)
    steps_per_frame = relax_every * max(1, math.ceil(interval / (relax_every * dt) - 1e-9))
    if not p.dt:  # the automatic step shrinks so that the frames asked for end on t_end
        dt = interval / steps_per_frame
    frames = max(1, round(t_end / (steps_per_frame * dt)))
    check_steps(frames * steps_per_frame, dt, t_end)
    if frames < p.frames:
        report(f"{frames} frames, not the {p.frames} asked for: a frame ends on a relaxation, every "
               f"{relax_every} steps of dt = {dt:.4g}; with --set dt=auto every frame is written")  # fmt: skip
    return dt, relax_every, steps_per_frame, frames


def drag_coefficient(p, size: float) -> float:
    """ζ of the overdamped coupling: τ_m = ζ S² / (Y h), S the scene's size."""
    return p.tau_m * p.young * p.thickness / size**2


def quasi_static_coupling(shell, wave, ps: list, relax_every: int, size: float) -> QuasiStatic:
    """The scenes' QuasiStatic coupling from the parameters `ps` (one set, or one per batched world; relax_iterations
    auto: CG_BUDGET); overdamped: each world's ζ."""
    p = ps[0]
    budget = p.relax_iterations or CG_BUDGET[shell.device.is_cuda]
    drag = [drag_coefficient(q, size) for q in ps] if p.coupling == "overdamped" else 0.0
    return QuasiStatic(shell, wave, sensitive=p.sensitive, chemistry_steps=relax_every, tol=p.relax_tol or None,
                       max_iterations=budget, accept_unconverged=p.accept_unconverged, method=p.relax_method,
                       newton_steps=p.newton_steps, drag=drag)  # fmt: skip


class QuasiStaticWaveRun(WaveClock):
    """A telegraph wave on a quasi-static active shell: the oocyte, wave-guide and buckling scenes.

    `initial` is "gaussian" (origin, sigma) or "front" (origin, k, delta). Frames are written at
    multiples of `steps_per_frame × dt` up to `t_end` (with `adaptive_dt`, at the first step within
    half a coupled step of them). `self_contact` adds the SelfContact term; `adaptive_dt` steps on at
    0.9 × the bound where the moving surface lowers it below dt (docs/theory/scenes.md).
    """

    def __init__(self, name: str, mesh: Mesh, p, *, size: float, origin, initial: dict, t_end: float, rule: str = "3",
                 device=None, self_contact: bool = False, adaptive_dt: bool = False, profile=None, measure=None,
                 figures=None, report=print):  # fmt: skip
        self.name, self.mesh, self.p, self.initial = name, mesh, p, initial
        self.model = quasi_static_model(mesh, [p], size=size, rule=rule, device=device, self_contact=self_contact)
        self.shell = self.model.shell
        self.operator = self.model.operator()
        c0, v0 = initial_values(self.operator, origin, initial, gamma=p.gamma, size=size)
        dt, relax_every, self.steps_per_frame, self.frames = frame_clock(
            p, t_end, mean_edge(mesh), self.model.wave(self.operator, c0=c0).stable_dt, report)  # fmt: skip
        self.wave = self.model.wave(self.operator, c0=c0, v0=v0, dt=dt)
        self.coupled = quasi_static_coupling(self.shell, self.wave, [p], relax_every, size)
        self.resolved = as_dict(replace(p, dt=dt, relax_every=relax_every, frames=self.frames,
                                        relax_iterations=self.coupled.max_iterations))  # fmt: skip
        # the telegraph invariant from the state at t = 0 (on the equilibrium surface)
        self.invariant = (self.wave.total(), self.wave.total_rate(), p.alpha, dt)
        self.balance = ChemicalBalance(mesh, sensitive=p.sensitive, rule=rule, device=device, dtype=p.dtype)
        self.series = {"positions": (mesh.n_vertices, 3), "concentration": (mesh.n_vertices,),
                       "concentration_rate": (mesh.n_vertices,)}  # fmt: skip
        self.rest_mass, self.rest_area = self.operator.mass(), self.operator.area_elements()
        self.adaptive = bool(adaptive_dt)
        self.base_dt, self.relax_interval, self.frame_interval = dt, relax_every * dt, self.steps_per_frame * dt
        self.dt_changes = 0
        if self.adaptive:
            self.series["chemistry_dt"] = ()  # the step a frame's c_t belongs to (resume)
        self.series.update({COUNTER + name: () for name in self._counters()})  # the bookkeeping, for a resume
        self.size = size
        self.origin = np.asarray(origin, dtype=np.float64)
        # the relaxations a frame holds: the adaptive step's coupled steps are at least 2/3 of a relaxation interval
        relaxations = self.steps_per_frame // relax_every
        self.arrival = ArrivalTimes(self.wave.concentration(), 2 * relaxations + 2 if self.adaptive else relaxations)
        self.series.update(relaxation_count=(), relaxation_times=(self.arrival.slots,),
                           relaxation_concentration=(self.arrival.slots, mesh.n_vertices))  # for a resume
        self.profiles = []  # per frame: (time, profile along the scene's chosen curve), for figures
        self.concentrations = []  # per frame: the control concentrations, for the run's colour scale (run_range)
        self.time_unit = f"nondimensional time units (wave speed γ = {p.gamma:g} length units per time unit)"
        self._profile, self._measure, self._figures = profile, measure, {**(figures or {}), "frame": frame_png}
        self.snapshot = None  # (time, positions, c) of the frame nearest t_end / 3, for the rendered frame
        self.front_start = 0.0  # rest arc length of the wave front from the origin at t = 0

    def frame(self) -> dict:
        """The current frame: control positions, concentrations and the wave's rate c_t (control values)."""
        frame = {**self.coupled.state.to_frame(), **self.arrival.frame_samples()}
        if self.adaptive:
            frame["chemistry_dt"] = np.array(self.wave.dt)
        frame.update({COUNTER + name: np.array(value) for name, value in self._counters().items()})
        return frame

    def _counters(self) -> dict:
        counters = {**self.coupled.counters(), "chemistry_dt_changes": self.dt_changes}
        if self.shell.self_contact is not None:
            counters["self_contact_searches"] = self.shell.self_contact.searches
        return counters

    def advance_frame(self) -> None:
        """Coupled steps to the next multiple of the frame interval (within half a coupled step)."""
        end = (round(self.time / self.frame_interval) + 1) * self.frame_interval
        if self.adaptive and self.wave.dt < self.base_dt:
            recovered = min(self.base_dt, self.wave.safety * self.wave.stable_dt)
            if recovered > 1.5 * self.wave.dt:
                self._change_dt(recovered)
        while end - self.time > 0.5 * self.coupled.chemistry_steps * self.wave.dt:
            try:
                self.coupled.step()
            except TimeStepError:  # raised before the wave stepped: nothing moved
                if not self.adaptive:
                    raise
                self._change_dt(self.wave.safety * self.wave.stable_dt)
                continue
            except BlowUpError as error:
                raise self._diagnosed(error) from None
            self.arrival.update(self.wave.concentration(), self.wave.time)

    def _diagnosed(self, error: BlowUpError) -> BlowUpError:
        """The blow-up, with the cause named where the surface is not resolved: a vertex's lumped mass
        grown far past its rest value, or a point where the limit surface is singular (its area
        element below J_FLOOR of the rest one). Both are folds sharper than the mesh, where each
        relaxation pumps energy into the wave."""
        if not self.p.sensitive or isinstance(error, FoldError):
            return error
        growth = self.operator.mass() / self.rest_mass
        vertex = int(np.argmax(growth))
        shrink = self.operator.area_elements() / self.rest_area
        point = int(np.argmin(shrink))
        if growth[vertex] >= UNRESOLVED_MASS_GROWTH:
            where = f"vertex {vertex}'s lumped mass is {growth[vertex]:.0f}× its rest value"
        elif shrink[point] < J_FLOOR:
            triangle = point // self.operator.tables.points_per_triangle
            where = (f"the limit surface is singular in triangle {triangle} (area element {shrink[point]:.1e} of "
                     "its rest value)")  # fmt: skip
        else:
            return error
        return BlowUpError(f"{error}. The surface is not resolved there: {where}, a fold sharper than the mesh; "
                           "refine the mesh (--set level)", error.time, error.steps)  # fmt: skip

    def _change_dt(self, dt: float, recentre: bool = True) -> None:
        self.wave.change_dt(dt, recentre=recentre)
        self.coupled.chemistry_steps = max(1, round(self.relax_interval / dt))
        self.dt_changes += 1

    def restore(self, frame: dict) -> None:
        """Continue from a saved frame (HDF5 resume): positions, c, c_t, the time, (adaptive) dt and the
        bookkeeping."""
        self.coupled.state.assign_frame(frame)
        self.coupled.restore(frame["positions"])
        if self.adaptive:
            if float(frame["chemistry_dt"]) != self.wave.dt:
                self._change_dt(float(frame["chemistry_dt"]), recentre=False)  # c_t already belongs to it
            self.wave.steps = int(round(float(frame["time"]) / self.base_dt))
        else:
            self.wave.steps = int(round(frame["time"] / self.wave.dt))
        self.wave.time = float(frame["time"])  # as the uninterrupted run summed it
        stored = {name[len(COUNTER):]: value for name, value in frame.items() if name.startswith(COUNTER)}
        if stored and np.isfinite(list(stored.values())).all():  # files from before the bookkeeping: afresh
            self.coupled.restore_counters(stored)
            self.dt_changes = int(stored["chemistry_dt_changes"])
            if self.shell.self_contact is not None:
                self.shell.self_contact.searches = int(stored["self_contact_searches"])

    def record(self, time: float, frame: dict, stored: bool = False) -> None:
        """Note a written frame for the figures (and, for frames read back on resume, the arrival times'
        samples)."""
        if stored:
            self.arrival.replay(time, frame)
        else:
            self.arrival.framed()
        self.concentrations.append(np.array(frame["concentration"]))
        self.balance.record(time, frame["positions"], frame["concentration"], telegraph_total(*self.invariant, time))
        if self._profile is not None:
            self.profile_time = time
            self.profiles.append((time, self._profile(self, frame["positions"])))
        target = self.frames * self.frame_interval / 3
        if self.snapshot is None or abs(time - target) < abs(self.snapshot[0] - target):
            self.snapshot = (time, np.array(frame["positions"]), np.array(frame["concentration"]))

    def measurements(self) -> dict:
        x = self.coupled.positions()
        out = {"time": self.time, "volume": self.shell.volume(x),
               **relaxation_measurements(self.coupled), **self.balance.measurements()}  # fmt: skip
        if self.adaptive:
            out["chemistry_dt_changes"], out["chemistry_dt"] = self.dt_changes, self.wave.dt
        if self.shell.self_contact is not None:
            out["self_contact_pairs"] = self.shell.self_contact.pairs() // 2
            out["self_contact_searches"] = self.shell.self_contact.searches
        if self._measure is not None:
            out.update(self._measure(self))
        return out

    def figures(self, stem: str) -> list:
        """Write the scene's figures as STEM_NAME.png; returns their paths."""
        paths = []
        for name, draw in self._figures.items():
            paths.append(f"{stem}_{name}.png")
            draw(self, paths[-1])
        return paths


def relaxation_measurements(coupled: QuasiStatic, world: int = 0) -> dict:
    """A world's relaxation bookkeeping over the run (its measurements)."""
    counters = coupled.counters(world)
    return {"relax_iterations_mean": coupled.relax_iterations_mean(world),
            "unconverged_relaxations": counters["unconverged_relaxations"],
            "newton_finishes": counters["newton_finishes"], "round_off_relaxations": counters["round_off_relaxations"]}  # fmt: skip


def sphere_wave_run(name: str, p, *, mesh=None, device=None, seed=0, initial=None, report=print, profile=None,
                    measure=None, figures=None, end_fraction=1.0, self_contact=False, adaptive_dt=False):  # fmt: skip
    """A telegraph wave from the north pole of a quasi-static sphere (oocytes, buckling); `t_end` 0
    ends at `end_fraction` of the pole-to-pole time π R / γ."""
    R = p.radius
    mesh = scene_mesh(mesh, lambda: icosphere(R, p.level), report, size=("level", p.level, icosphere), device=device)
    pole = np.array([0.0, 0.0, R])
    if initial is None:
        initial = {"kind": "gaussian", "sigma": p.width / R, "distance": "arc"}
    mesh = imperfect(mesh, p.noise * R, seed)  # an imperfection of the rest shape (perturbed positions alone relax back)
    return QuasiStaticWaveRun(name, mesh, p, size=R, origin=pole, initial=initial,
                              t_end=p.t_end or end_fraction * math.pi * R / p.gamma, device=device,
                              self_contact=self_contact, adaptive_dt=adaptive_dt, profile=profile or oocyte_profile,
                              measure=measure or oocyte_measurements, figures=figures or {"kymograph": kymograph_png},
                              report=report)  # fmt: skip


def box_wave_run(name: str, p, make_box, origins: dict, *, faces=None, fronts=None, mesh=None, device=None,
                 report=print):  # fmt: skip
    """A telegraph wave on a quasi-static box (cube or prism) from a face centre, an edge or a vertex.
    With the box's `faces` and exact `fronts` (wavewarp.unfolding) the run also measures and draws
    the imprint on the face opposite the origin (`imprint_measurements`, `imprint_png`)."""
    L = p.edge
    mesh = scene_mesh(mesh, lambda: make_box(L, p.divisions), report, size=("divisions", p.divisions, make_box),
                      device=device)  # fmt: skip
    origin = np.asarray(origins[p.origin], dtype=np.float64) * L
    initial = {"kind": "gaussian", "sigma": p.width / L}
    measure, figures = box_wave_measurements, {"arrival": arrival_map_png}
    on_box = fronts is not None and np.all(np.abs(face_heights(mesh.vertices, faces(L)).max(axis=0)) < 1e-9 * L)
    if on_box:  # not a --mesh of another shape
        measure = lambda run: {**box_wave_measurements(run), **imprint_measurements(run, faces, fronts)}  # noqa: E731
        figures["imprint"] = lambda run, path: imprint_png(run, path, faces, fronts)
    return QuasiStaticWaveRun(name, mesh, p, size=L, origin=origin, initial=initial, t_end=p.t_end or 2.2 * L / p.gamma,
                              rule=p.rule, device=device, measure=measure, figures=figures, report=report)  # fmt: skip
