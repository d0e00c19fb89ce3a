"""Scenes (SPEC §6, §9): typed parameters that `--set` overrides, and the quasi-static wave run.

A scene script (`scenes/NAME.py`) defines `NAME`, `DESCRIPTION`, `PARAMETERS` (name -> Param,
each with its default and the reason for it), `QUICK` (overrides for `--quick`) and
`build(p, *, mesh, device, seed)` returning a run object with `series`, `frame()`,
`advance_frame()`, `restore(frame)` and `measurements()`. Scenes build only the terms they use.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import os
import pkgutil
from dataclasses import dataclass

import numpy as np

from .balance import ChemicalBalance
from .coupled import QuasiStatic
from .laplace import J_FLOOR, LaplaceBeltrami
from .mesh import Mesh
from .relax import NEWTON_STEPS
from .self_contact import SelfContact
from .shell import Shell
from .unfolding import first_arrival
from .initial import gaussian_pulse, steady_front
from .chemistry import TRANSPORTS, telegraph_total
from .waves import BlowUpError, Telegraph, TimeStepError


class SceneError(ValueError):
    """A scene name, parameter or value that cannot be used; the message lists what is valid."""


@dataclass(frozen=True)
class Param:
    """One scene parameter: its default (which fixes its type), why, and what values are valid.
    `legacy`: the value a trajectory written before the parameter existed ran with (used on resume)."""

    default: object
    help: str
    choices: tuple = ()
    positive: bool = False
    minimum: float | None = None
    legacy: object = None

    def parse(self, name: str, text):
        kind = type(self.default)
        try:
            if kind is bool:
                value = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}[str(text).lower()]
            elif kind is int:
                value = int(text)
            elif kind is float:
                value = float(text)
                if not math.isfinite(value):
                    raise ValueError
            else:
                value = str(text)
        except (KeyError, ValueError):
            expected = {bool: "true or false", int: "an integer", float: "a finite number"}.get(kind, "text")
            raise SceneError(f"bad value for {name}: {text!r} (expected {expected})") from None
        if self.choices and value not in self.choices:
            raise SceneError(f"bad value for {name}: {value!r} (one of {', '.join(map(str, self.choices))})")
        if self.positive and not value > 0:
            raise SceneError(f"bad value for {name}: {value!r} (must be > 0)")
        if self.minimum is not None and value < self.minimum:
            raise SceneError(f"bad value for {name}: {value!r} (must be >= {self.minimum})")
        return value


def resolve(parameters: dict, quick: dict | None = None, overrides=()) -> dict:
    """Defaults, then `quick`, then NAME=VALUE `overrides`; an unknown name or bad value raises SceneError."""
    values = {name: param.default for name, param in parameters.items()}
    values.update(quick or {})
    for item in overrides:
        name, sep, text = str(item).partition("=")
        name = name.strip()
        if not sep:
            raise SceneError(f"--set needs NAME=VALUE, got {item!r}")
        if name not in parameters:
            raise SceneError(f"unknown parameter {name!r}; valid: {', '.join(sorted(parameters))}")
        values[name] = parameters[name].parse(name, text.strip())
    return values


def resumed(parameters: dict, stored: dict) -> dict:
    """The parameters of a run resumed from a trajectory that stored `stored`: a parameter newer than
    the file takes the value such files ran with (`Param.legacy`), else its default."""
    values = resolve(parameters)
    values.update({name: param.legacy for name, param in parameters.items() if param.legacy is not None})
    return {**values, **stored}


def scene_descriptions() -> dict[str, str]:
    """Scene name -> one-line description, from the modules of `wavewarp.scenes`."""
    from . import scenes

    found = {}
    for info in pkgutil.iter_modules(scenes.__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"wavewarp.scenes.{info.name}")
        name = getattr(module, "NAME", info.name.replace("_", "-"))
        found[name] = getattr(module, "DESCRIPTION", "")
    return dict(sorted(found.items()))


def load_scene(name_or_path: str):
    """The scene module: a name from `wavewarp.scenes` or the path of a scene script."""
    if name_or_path.endswith(".py") or os.sep in name_or_path:
        if not os.path.isfile(name_or_path):
            raise SceneError(f"scene script {name_or_path!r} does not exist")
        spec = importlib.util.spec_from_file_location("wavewarp_user_scene", name_or_path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    else:
        known = scene_descriptions()
        if name_or_path not in known:
            raise SceneError(f"unknown scene {name_or_path!r}; valid: {', '.join(known)}")
        module = importlib.import_module(f"wavewarp.scenes.{name_or_path.replace('-', '_')}")
    for attribute in ("NAME", "PARAMETERS", "build"):
        if not hasattr(module, attribute):
            raise SceneError(f"scene {name_or_path!r} defines no {attribute}")
    return module


# ---------------------------------------------------------------- parameters shared by the telegraph scenes

TRANSPORT = Param("conservative", "how the chemical moves with a deforming shell (sensitive runs): conservative "
                  "keeps each vertex's amount M c, so ∫ c dω obeys the equation (SPEC §5); material keeps the "
                  "control values, which does not conserve it (docs/chemistry.md)", choices=TRANSPORTS,
                  legacy="material")  # fmt: skip

TELEGRAPH_PARAMETERS = {
    "young": Param(1.0, "Y sets the unit of stress (quasi-static: only ratios matter)", positive=True),
    "poisson": Param(0.33, "Poisson ratio, as in SPEC §9's Shell default"),
    "gamma": Param(1.0, "wave speed γ; with the size it sets the time unit", positive=True),
    "alpha": Param(0.001, "telegraph dissipation α (SPEC §5)", minimum=0.0),
    "dt": Param(0.0, "time step; 0 = 0.4 × the rest surface's stability bound (room for the contraction "
                "the wave drives: e^{-AC c} shrinks lengths, and the guard refuses dt past the moving bound), "
                "then adjusted (at most 5% up, else down) so that the last frame lands on t_end",
                minimum=0.0),  # fmt: skip
    "frames": Param(48, "frames written between t = 0 and t_end", minimum=1),
    "sensitive": Param(True, "true: the wave runs on the deformed shell; false: on the rest shell (the twin)"),
    "transport": TRANSPORT,
    "mass_corrections": Param(0, "0 = lumped mass (SPEC §5); 2 = more accurate wave shapes (docs/chemistry.md)",
                              minimum=0),  # fmt: skip
    "relax_every": Param(0, "chemistry steps per relaxation; 0 = as many as keep the wave within half a "
                         "control edge between relaxations (quasi-static: τ_mech ≪ τ_wave)", minimum=0),  # fmt: skip
    "relax_tol": Param(0.0, "relaxation tolerance (a residual strain, Shell.relax); 0 = the dtype's default", minimum=0.0),
    "relax_iterations": Param(0, "CG iteration budget per relaxation; where CG spends it, Newton steps finish "
                              "(relax_method auto); 0 = 2,000 on a CPU, 20,000 on a GPU, where a CG iteration costs "
                              "~1/6 as much against the same host factorization (docs/shell.md)", minimum=0),  # fmt: skip
    "newton_steps": Param(NEWTON_STEPS, "Newton steps a finish may take (a snap-through took 132–137)", minimum=1),
    "relax_method": Param("auto", "auto: CG, then a Newton finish where CG spends its budget (the late oocytes' "
                          "nearly singular Hessian, docs/shell.md); ncg: CG only; newton: Newton only",
                          choices=("auto", "ncg", "newton")),  # fmt: skip
    "overdamped": Param(False, "true: a relaxation that spends its budget is accepted (the paper's overdamped "
                        "update; counted in --json) instead of stopping the run"),  # fmt: skip
    "dtype": Param("float32", "float32 (default; checked against float64 in tests) or float64",
                   choices=("float32", "float64")),  # fmt: skip
}


def parameters_with(**scene) -> dict:
    """TELEGRAPH_PARAMETERS updated with a scene's own parameters."""
    return {**TELEGRAPH_PARAMETERS, **scene}


def scene_mesh(mesh: Mesh | None, build_default, report=print) -> Mesh:
    """The scene's own mesh, or `--mesh` refined once where a triangle has two extraordinary vertices."""
    mesh = build_default() if mesh is None else mesh
    if mesh.needs_refinement:
        report("the mesh has triangles with two extraordinary vertices: refined once by Loop subdivision")
        mesh = mesh.refined_for_patches()  # renumbered for locality, as the generators' meshes
    return mesh


def mean_edge(mesh: Mesh) -> float:
    return float(np.mean(np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1)))


class WaveClock:
    """A run's time and step count are its wave's."""

    @property
    def time(self) -> float:
        return self.wave.time

    @property
    def steps(self) -> int:
        return self.wave.steps


# relax_iterations 0: CG's budget before the Newton finish, by device (is_cuda). Measured on the
# default ascidian: a CPU finish after 2,000 takes ~20 s where CG to 20,000 took ~190 s; on the H100
# the float32 run kept 26 frames in 311 s with 20,000 and 22 in 559 s with 2,000 (docs/shell.md)
CG_BUDGET = {False: 2000, True: 20000}
UNRESOLVED_MASS_GROWTH = 50.0  # a vertex's lumped mass over its rest value past which a blow-up is named a fold
# sharper than the mesh (level-4 buckling, H100: at most 5.5× over its 3-fold fold to t = 15.2, ~1000× at the blow-up)


class QuasiStaticWaveRun(WaveClock):
    """A telegraph wave on a quasi-static active shell: the oocyte, wave-guide and buckling scenes.

    `initial` is "gaussian" (origin, sigma) or "front" (origin, k, delta). Frames are written
    at multiples of `steps_per_frame × dt` up to `t_end` (with `adaptive_dt`, at the first step
    within half a coupled step of them). Parameters `self_contact` and `adaptive_dt`, where a scene
    has them, add the SelfContact term and the adaptive chemistry step (docs/scenes.md).
    """

    def __init__(self, name: str, mesh: Mesh, p: dict, *, size: float, origin, initial: dict, t_end: float,
                 rule: str = "3", device=None, profile=None, measure=None, figures=None):  # fmt: skip
        self.name, self.mesh, self.p = name, mesh, p
        dtype = p["dtype"]
        self.shell = Shell(mesh, thickness=p["thickness"], young=p["young"], poisson=p["poisson"], AC=p["AC"],
                           AI=p["AI"], volume_penalty=p["mu_v"] * p["young"] * p["thickness"] / size**4, rule=rule,
                           device=device, dtype=dtype)  # fmt: skip
        if p.get("self_contact"):
            try:
                self.shell.self_contact = SelfContact(self.shell)
            except ValueError as error:  # too coarse a mesh: name the scene's switches
                raise ValueError(f"{error}: raise --set level, or --set self_contact=false") from None
        self.operator = LaplaceBeltrami(mesh, rule=rule, device=device, dtype=dtype)
        if initial["kind"] == "gaussian":
            c0, v0 = gaussian_pulse(self.operator, origin, initial["sigma"], gamma=p["gamma"], radius=size,
                                    distance=initial.get("distance", "chord"))  # fmt: skip
        else:
            c0, v0 = steady_front(self.operator, origin, k=initial["k"], delta=initial["delta"], gamma=p["gamma"])
        probe = Telegraph(self.operator, p["gamma"], p["alpha"], c0=c0, mass_corrections=p["mass_corrections"])
        dt = p["dt"] or 0.4 * probe.stable_dt
        relax_every = p["relax_every"] or max(1, int(0.5 * mean_edge(mesh) / (p["gamma"] * dt)))
        # (1e-9: a resumed run's stored dt and frames give back the same layout despite round-off)
        self.steps_per_frame = relax_every * max(1, math.ceil(t_end / p["frames"] / (relax_every * dt) - 1e-9))
        self.frames = max(1, round(t_end / (self.steps_per_frame * dt)))
        if not p["dt"]:  # the automatic step lands the last frame on t_end: stretched by at most 5%, else shrunk
            if t_end / (self.steps_per_frame * dt) > 1.05 * self.frames:
                self.frames += 1
            dt = t_end / (self.frames * self.steps_per_frame)
        self.wave = Telegraph(self.operator, p["gamma"], p["alpha"], c0=c0, v0=v0, dt=dt,
                              mass_corrections=p["mass_corrections"], transport=p["transport"])  # fmt: skip
        budget = p["relax_iterations"] or CG_BUDGET[self.shell.device.is_cuda]
        self.coupled = QuasiStatic(self.shell, self.wave, sensitive=p["sensitive"], chemistry_steps=relax_every,
                                   tol=p["relax_tol"] or None, max_iterations=budget, overdamped=p["overdamped"],
                                   method=p["relax_method"], newton_steps=p["newton_steps"])  # fmt: skip
        self.resolved = {**p, "dt": dt, "relax_every": relax_every, "frames": self.frames, "relax_iterations": budget}
        # the telegraph invariant from the state at t = 0 (on the equilibrium surface)
        self.invariant = (self.wave.total(), self.wave.total_rate(), p["alpha"], dt)
        self.balance = ChemicalBalance(mesh, sensitive=p["sensitive"], rule=rule, device=device, dtype=dtype)
        self.series = {"positions": (mesh.n_vertices, 3), "concentration": (mesh.n_vertices,),
                       "concentration_rate": (mesh.n_vertices,)}  # fmt: skip
        # adaptive_dt: below a bound that the moving surface lowered, step at safety × the bound,
        # relaxing at the same time interval; the scene's dt returns at a frame where the bound allows
        self.rest_mass, self.rest_area = self.operator.mass(), self.operator.area_elements()
        self.adaptive = bool(p.get("adaptive_dt"))
        self.base_dt, self.relax_interval, self.frame_interval = dt, relax_every * dt, self.steps_per_frame * dt
        self.dt_changes = 0
        if self.adaptive:
            self.series["chemistry_dt"] = ()  # the step a frame's c_t belongs to (resume)
        self.field_range = (0.0, 1.0)
        self.size = size
        self.origin = np.asarray(origin, dtype=np.float64)
        self.arrival = ArrivalTimes(self.wave.concentration())
        self.profiles = []  # per frame: (time, profile along the scene's chosen curve), for figures
        self._profile, self._measure, self._figures = profile, measure, {**(figures or {}), "frame": frame_png}
        self.snapshot = None  # (time, positions, c) of the frame nearest t_end / 3, for the rendered frame
        self.front_start = 0.0  # rest arc length of the wave front from the origin at t = 0

    def frame(self) -> dict:
        """The current frame: control positions, concentrations and the wave's rate c_t (control values)."""
        frame = {"positions": self.coupled.positions(), "concentration": self.wave.concentration(),
                 "concentration_rate": self.wave.velocity()}  # fmt: skip
        if self.adaptive:
            frame["chemistry_dt"] = np.array(self.wave.dt)
        return frame

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
        relaxation pumps energy into the wave (docs/scenes.md "Open")."""
        if not self.p["sensitive"]:
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
        """Continue from a saved frame (HDF5 resume): positions, c, c_t, the time and (adaptive) dt."""
        real = self.shell._real
        self.coupled.restore(frame["positions"])
        self.wave.c.assign(np.asarray(frame["concentration"]).astype(real))
        self.wave.v.assign(np.asarray(frame["concentration_rate"]).astype(real))
        if self.adaptive:
            if float(frame["chemistry_dt"]) != self.wave.dt:
                self._change_dt(float(frame["chemistry_dt"]), recentre=False)  # c_t already belongs to it
            self.wave.time = float(frame["time"])
            self.wave.steps = int(round(self.wave.time / self.base_dt))
            return
        self.wave.steps = int(round(frame["time"] / self.wave.dt))
        self.wave.time = self.wave.steps * self.wave.dt

    def record(self, time: float, frame: dict, stored: bool = False) -> None:
        """Note a written frame for the figures (and, for frames read back on resume, the arrival times)."""
        if stored:
            self.arrival.update(frame["concentration"], time)
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
               "relax_iterations_mean": float(np.mean(self.coupled.relax_iterations)),
               "unconverged_relaxations": self.coupled.unconverged,
               "newton_finishes": self.coupled.newton_finishes,
               "round_off_relaxations": self.coupled.round_off_stops, **self.balance.measurements()}  # fmt: skip
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


SPHERE_PARAMETERS = parameters_with(
    radius=Param(10.0, "R (the paper gives none for oocytes): with the paper's pulse width below the pulse "
                 "is R/7 wide, a narrow Gaussian that level 4 resolves (R = 25 needs level 6)", positive=True),
    thickness=Param(0.5, "h (absolute); h/R = 0.05 at the default R (SPEC §6)", positive=True),
    width=Param(math.sqrt(2.0), "pulse width σR in length units: the paper's σ² = 2/R² (SPEC §5)", positive=True),
    level=Param(4, "icosphere level: 5120 triangles, 2.3 control edges per pulse width at R = 10 (level 5 on a GPU: 4.6)",
                minimum=1),
    # SPEC §5; BENCHMARKS.md "Accuracy", level 4: front speed −0.25% and pulse shape 1.5% (lumped: −2.4%, 9.2%)
    mass_corrections=Param(2, "0 = lumped mass (SPEC §5); 2 = the accurate wave shapes and speed of the "
                           "benchmarks (docs/chemistry.md)", minimum=0),  # fmt: skip
    t_end=Param(0.0, "end time; 0 = π R / γ, the wave's pole-to-pole time", minimum=0.0),
    noise=Param(0.0, "random perturbation / R of the rest shape's control points (seeded by --seed): an "
                "imperfection that breaks the symmetry", minimum=0.0),  # fmt: skip
)


def sphere_wave_run(name: str, p: dict, *, mesh=None, device=None, seed=0, initial=None, report=print,
                    profile=None, measure=None, figures=None, end_fraction=1.0):  # fmt: skip
    """A telegraph wave from the north pole of a quasi-static sphere (oocytes, buckling); `t_end` 0
    ends at `end_fraction` of the pole-to-pole time π R / γ."""
    from .mesh import icosphere

    R = p["radius"]
    mesh = scene_mesh(mesh, lambda: icosphere(R, p["level"]), report)
    pole = np.array([0.0, 0.0, R])
    if initial is None:
        initial = {"kind": "gaussian", "sigma": p["width"] / R, "distance": "arc"}
    if p["noise"] > 0:  # an imperfection of the rest shape: perturbed positions alone relax back at t = 0
        mesh = Mesh(seeded_noise(mesh, p["noise"] * R, seed), mesh.triangles)
    return QuasiStaticWaveRun(name, mesh, p, size=R, origin=pole, initial=initial, t_end=p["t_end"] or end_fraction * math.pi * R / p["gamma"],
                              device=device, profile=profile or oocyte_profile, measure=measure or oocyte_measurements,
                              figures=figures or {"kymograph": kymograph_png})  # fmt: skip


BOX_PARAMETERS = parameters_with(
    edge=Param(20.0, "L: all edges of the box; L = 20 h (SPEC §6)", positive=True),
    thickness=Param(1.0, "h (absolute); L = 20 h at the default L (SPEC §6)", positive=True),
    width=Param(math.sqrt(2.0), "pulse width in length units, as the oocytes' (SPEC §5)", positive=True),
    # SPEC §7 (eikonal); BENCHMARKS.md "Accuracy": lumped front speed 0.53% off the net's (16 divisions: 2.2%)
    divisions=Param(24, "control squares per face edge (even): 1.7 control edges per pulse width at L = 20",
                    minimum=2),
    t_end=Param(0.0, "end time; 0 = 2.2 L / γ: past the face opposite the origin, until the fronts that meet "
                "there have peaked (the imprint's arrival times need the peaks)", minimum=0.0),
    AC=Param(0.2, "metric coupling (SPEC §6)"),
    AI=Param(0.0, "curvature coupling (SPEC §6)"),
    mu_v=Param(0.0, "volume penalty μV in units of Y h / L⁴ (SPEC §6: none)", minimum=0.0),
    rule=Param("3x4", "quadrature: the 3-point rule on 4 sub-triangles integrates the rounded box edges "
               "(docs/geometry.md: rule '3' misses 3% of the Gauss-Bonnet integral on a cube)"),
)


def box_faces(mesh: Mesh):
    """The planar faces of a box control mesh: (unit normal, offset) per coplanar triangle group."""
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    faces = []
    for n, p in zip(normals, a):
        if not any(np.allclose(n, m, atol=1e-9) for m, _ in faces):
            faces.append((n, float(n @ p)))
    return faces


def unfolded_net(run):
    """Rest vertex positions unfolded into the plane of the face holding the origin (that face and
    the faces sharing an edge with it), as in Fig. 2b; NaN elsewhere or when the origin lies on
    an edge or vertex. Returns (points (V, 3) in the origin face's plane, mask, its normal)."""
    x = run.mesh.vertices
    scale = np.abs(x).max()
    faces = box_faces(run.mesh)
    on = np.array([np.abs(x @ n - d) < 1e-9 * scale for n, d in faces])  # (faces, V)
    holding = [k for k, (n, d) in enumerate(faces) if abs(run.origin @ n - d) < 1e-9 * scale]
    out = np.full_like(x, np.nan)
    if len(holding) != 1:
        return out, np.zeros(len(x), dtype=bool), None
    k0 = holding[0]
    n0 = faces[k0][0]
    out[on[k0]] = x[on[k0]]
    for k, (n, _) in enumerate(faces):
        shared = on[k] & on[k0]
        if k == k0 or shared.sum() < 2:
            continue
        edge = np.cross(n, n0)
        edge /= np.linalg.norm(edge)
        angle = math.atan2(np.cross(n, n0) @ edge, n @ n0)
        K = np.array([[0, -edge[2], edge[1]], [edge[2], 0, -edge[0]], [-edge[1], edge[0], 0]])
        R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K  # Rodrigues: R n = n0
        anchor = x[np.flatnonzero(shared)[0]]
        mine = on[k] & ~on[k0]
        out[mine] = anchor + (x[mine] - anchor) @ R.T
    return out, ~np.isnan(out[:, 0]), n0


def box_wave_measurements(run) -> dict:
    """Arrival times against the distance in the unfolded net (eikonal |∇T| = 1/γ, Fig. 2b): the
    speed (slope⁻¹) and the largest deviation from the line in units of the control edge's
    crossing time; the same fit against the straight chord, which must fit worse."""
    net, mask, _ = unfolded_net(run)
    L = run.size
    distance = np.linalg.norm(net - run.origin, axis=1)
    arrival = run.arrival.time
    probe = mask & (arrival > 0) & (distance > 0.15 * L) & (distance < 0.9 * L)
    if probe.sum() < 10:
        return {"wave_speed": None, "eikonal_deviation": None, "chord_deviation": None}
    edge_time = mean_edge(run.mesh) / run.p["gamma"]

    def fit(d):
        slope, offset = np.polyfit(d[probe], arrival[probe], 1)
        return 1 / slope, float(np.abs(arrival[probe] - slope * d[probe] - offset).max() / edge_time)

    speed, deviation = fit(distance)
    chord = np.linalg.norm(run.mesh.vertices - run.origin, axis=1)
    return {"wave_speed": float(speed), "eikonal_deviation": deviation, "chord_deviation": fit(chord)[1]}


def arrival_map_png(run, path) -> None:
    """Fig. 2b: arrival times on the unfolded net with the eikonal circles s = γ t superposed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import write_png

    net, mask, n0 = unfolded_net(run)
    arrival = run.arrival.time
    reached = mask & (arrival > 0)
    fig, ax = plt.subplots(figsize=(5.5, 5))
    if reached.any():
        u = np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n0, u)
        plane = np.stack([(net - run.origin) @ u, (net - run.origin) @ v], axis=1)
        ax.scatter(plane[mask, 0], plane[mask, 1], c="0.85", s=4)
        shown = ax.scatter(plane[reached, 0], plane[reached, 1], c=arrival[reached], s=6, cmap="viridis")
        fig.colorbar(shown, label="arrival time (half-maximum of c)")
        for t in np.linspace(0, arrival[reached].max(), 7)[1:]:
            ax.add_patch(plt.Circle((0, 0), run.p["gamma"] * t, fill=False, color="k", lw=1.0, ls="--"))
    ax.set_aspect("equal")
    ax.set_title(f"{run.name} from the {run.p.get('origin', 'origin')}: arrival on the unfolded net\n"
                 "(dashed: eikonal circles s = γ t)")  # fmt: skip
    fig.tight_layout()
    write_png(fig, path)


def face_heights(x, corners: dict) -> np.ndarray:
    """(faces, V) signed heights of points `x` above the planes of a convex box's faces (name ->
    corners, counter-clockwise from outside): all ≤ 0 inside, the largest 0 on the surface."""
    normals = [np.cross(c[1] - c[0], c[2] - c[0]) for c in corners.values()]
    return np.array([(x - c[0]) @ (n / np.linalg.norm(n)) for c, n in zip(corners.values(), normals)])


def face_grid(corners, n: int):
    """An n × n grid over a planar face's bounding rectangle. Returns the in-plane axes (2, 3) (from
    corners[0]), the grid's in-plane coordinates gu, gv (n, n), its points (n², 3) and which of them
    lie inside the face (corners counter-clockwise)."""
    u = (corners[1] - corners[0]) / np.linalg.norm(corners[1] - corners[0])
    v = corners[2] - corners[0] - ((corners[2] - corners[0]) @ u) * u
    axes = np.stack([u, v / np.linalg.norm(v)])
    c = (corners - corners[0]) @ axes.T
    gu, gv = np.meshgrid(*(np.linspace(low, high, n) for low, high in zip(c.min(axis=0), c.max(axis=0))))
    inside = np.ones(n * n, dtype=bool)
    for a, b in zip(c, np.roll(c, -1, axis=0)):  # the face lies left of each edge
        inside &= (b[0] - a[0]) * (gv.ravel() - a[1]) - (b[1] - a[1]) * (gu.ravel() - a[0]) > 1e-9 * np.ptp(c)
    return axes, gu, gv, corners[0] + np.stack([gu.ravel(), gv.ravel()], axis=1) @ axes, inside


def opposite_face(run, faces, fronts):
    """The face where the wave ends, holding the surface point farthest from the origin (on a
    61 × 61 grid per face). Returns its name, its corners and the mask of the mesh's vertices on it."""
    corners = faces(run.size)

    def farthest(name):
        _, _, _, points, inside = face_grid(corners[name], 61)
        return first_arrival(fronts(points[inside], run.origin, run.size, face=name))[0].max()

    name = max(corners, key=farthest)
    on = np.abs(face_heights(run.mesh.vertices, {name: corners[name]})[0]) < 1e-9 * run.size
    return name, corners[name], on


def imprint_measurements(run, faces, fronts) -> dict:
    """The imprint on the face opposite the origin (SPEC §7, Fig. 2): `imprint_fold`, how many fronts
    (unfolded images of the origin) of the exact geodesic field arrive first somewhere on its
    vertices; `imprint_deviation`, the largest |arrival − (d/γ + fitted offset)| there in
    control-edge crossing times, d the exact distance; the same for the straight chord and, per
    front, for the exact field without that front (`imprint_without_front`), which must fit worse."""
    name, _, on = opposite_face(run, faces, fronts)
    x, arrival = run.mesh.vertices[on], run.arrival.time[on]
    each = fronts(x, run.origin, run.size, face=name)
    distance, first = first_arrival(each)
    out = {"imprint_face": name, "imprint_fold": len(np.unique(first)), "imprint_deviation": None,
           "imprint_chord_deviation": None, "imprint_without_front": None}  # fmt: skip
    if np.any(arrival <= 0):  # the wave has not crossed the whole face yet
        return out
    edge_time = mean_edge(run.mesh) / run.p["gamma"]

    def deviation(d):
        residual = arrival - d / run.p["gamma"]
        return float(np.abs(residual - residual.mean()).max() / edge_time)

    without = {f: deviation(np.min([each[g] for g in each if g != f], axis=0)) for f in np.unique(first)}
    return {**out, "imprint_deviation": deviation(distance),
            "imprint_chord_deviation": deviation(np.linalg.norm(x - run.origin, axis=1)),
            "imprint_without_front": without}  # fmt: skip


def imprint_png(run, path, faces, fronts) -> None:
    """Arrival times on the face opposite the origin, with the borders of the exact first-arrival regions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import write_png

    name, corners, on = opposite_face(run, faces, fronts)
    axes, gu, gv, points, inside = face_grid(corners, 160)  # even: no sample on a mirror line, where fronts tie
    plane = (run.mesh.vertices - corners[0]) @ axes.T
    arrival, triangles = run.arrival.time, run.mesh.triangles
    fig, ax = plt.subplots(figsize=(5.5, 5))
    shown = on[triangles].all(axis=1) & (arrival[triangles] > 0).all(axis=1)
    if shown.any():
        reached = arrival[on & (arrival > 0)]
        filled = ax.tripcolor(plane[:, 0], plane[:, 1], triangles[shown], arrival, shading="gouraud",
                              vmin=reached.min(), vmax=reached.max())  # fmt: skip
        fig.colorbar(filled, label="arrival time (half the first peak of c)")
    first = np.full(len(points), "", dtype=object)
    first[inside] = first_arrival(fronts(points[inside], run.origin, run.size, face=name))[1]
    for front in np.unique(first[inside]):
        ax.contour(gu, gv, np.where(inside, first == front, np.nan).astype(float).reshape(gu.shape), levels=[0.5],
                   colors="w", linewidths=1.2)  # fmt: skip
    ax.set_aspect("equal")
    ax.set_title(f"{run.name} from the {run.p.get('origin', 'origin')}: arrival on the {name} face\n"
                 f"white: the {len(np.unique(first[inside]))} exact first-arrival regions", fontsize=10)  # fmt: skip
    fig.tight_layout()
    write_png(fig, path)


def box_wave_run(name: str, p: dict, make_box, origins: dict, *, faces=None, fronts=None, mesh=None, device=None,
                 report=print):  # fmt: skip
    """A telegraph wave on a quasi-static box (cube or prism) from a face centre, an edge or a vertex.
    With the box's `faces` and exact `fronts` (wavewarp.unfolding) the run also measures and draws
    the imprint on the face opposite the origin (`imprint_measurements`, `imprint_png`)."""
    L = p["edge"]
    divisions = p["divisions"] + p["divisions"] % 2
    mesh = scene_mesh(mesh, lambda: make_box(L, divisions), report)
    origin = np.asarray(origins[p["origin"]], dtype=np.float64) * L
    initial = {"kind": "gaussian", "sigma": p["width"] / L}
    measure, figures = box_wave_measurements, {"arrival": arrival_map_png}
    on_box = fronts is not None and np.all(np.abs(face_heights(mesh.vertices, faces(L)).max(axis=0)) < 1e-9 * L)
    if on_box:  # not a --mesh of another shape
        measure = lambda run: {**box_wave_measurements(run), **imprint_measurements(run, faces, fronts)}
        figures["imprint"] = lambda run, path: imprint_png(run, path, faces, fronts)
    return QuasiStaticWaveRun(name, mesh, p, size=L, origin=origin, initial=initial, t_end=p["t_end"] or 2.2 * L / p["gamma"],
                              rule=p["rule"], device=device, measure=measure, figures=figures)  # fmt: skip


class ArrivalTimes:
    """Per vertex, when the first front arrived: the first crossing of half its first peak (the
    first local maximum of the vertex's control concentration above 1% of the initial peak; the
    larger peaks where fronts cross later do not count), interpolated between the samples taken
    at every relaxation (as the arrival checks of tests/test_waves.py). `time` is 0 where no front
    has (clearly) arrived: no such peak before the last sample, or c was above half of it at t = 0."""

    def __init__(self, c0: np.ndarray):
        self._times, self._values = [0.0], [np.asarray(c0, dtype=np.float64).copy()]

    def update(self, c: np.ndarray, time: float) -> None:
        self._times.append(float(time))
        self._values.append(np.asarray(c, dtype=np.float64).copy())

    @property
    def time(self) -> np.ndarray:
        values, times = np.array(self._values), np.array(self._times)
        falls = (values[:-1] >= values[1:]) & (values[:-1] > 0.01 * values[0].max())
        falls[:1] = False  # falling from t = 0 is the initial pulse, not an arrival
        columns = np.arange(values.shape[1])
        peak = values[np.argmax(falls, axis=0), columns]
        valid = falls.any(axis=0) & (values[0] < 0.5 * peak)
        j = np.maximum(np.argmax(values >= 0.5 * peak, axis=0), 1)
        before, after = values[j - 1, columns], values[j, columns]
        fraction = np.clip((0.5 * peak - before) / np.where(after > before, after - before, 1.0), 0.0, 1.0)
        arrival = times[j - 1] + fraction * (times[j] - times[j - 1])
        return np.where(valid, arrival, 0.0)


def sphere_wave_measurements(run, theta_range=(math.pi / 4, 3 * math.pi / 4), rings=12) -> dict:
    """Wave speed and rotational symmetry of a pulse from the pole (SPEC §7, Fig. 1c).

    Arrival times against the rest arc length R θ on θ in `theta_range`: the speed is the slope's
    inverse, `speed_nonlinearity` the largest deviation from the line over the time to cross the
    range, and `arrival_spread` the largest standard deviation of the arrival times within a
    latitude ring, over the time the wave takes to cross one ring.
    """
    R = run.size
    rest = run.mesh.vertices
    theta = np.arccos(np.clip(rest @ run.origin / (np.linalg.norm(rest, axis=1) * np.linalg.norm(run.origin)), -1, 1))
    arrival = run.arrival.time
    window = (theta > theta_range[0]) & (theta < theta_range[1])
    probe = (arrival > 0) & window
    if probe.sum() < 10 or probe.sum() < window.sum():  # the front has not crossed the whole window yet
        return {"wave_speed": None, "speed_nonlinearity": None, "arrival_spread": None}
    s, t = R * theta[probe], arrival[probe]
    slope, offset = np.polyfit(s, t, 1)
    crossing = slope * (s.max() - s.min())
    edges = np.linspace(*theta_range, rings + 1)
    ring = np.digitize(theta[probe], edges) - 1
    spread = max(float(np.std(t[ring == k])) for k in range(rings) if np.sum(ring == k) > 2)
    return {"wave_speed": float(1 / slope), "speed_nonlinearity": float(np.abs(t - (slope * s + offset)).max() / crossing),
            "arrival_spread": spread / (crossing / rings)}  # fmt: skip


def asymmetry_measurements(run) -> dict:
    """The shell's largest shape asymmetry over the frames (shape_asymmetry: in R, and its mode),
    `axisymmetric_until`, the last frame time before one passes AXISYMMETRY_TOLERANCE (None if the
    first does), and `asymmetric_between`, the first and last frame times past it (None if none is)."""
    times = [t for t, _ in run.profiles]
    values = [value[1] for _, value in run.profiles]
    if not values:
        return {"shape_asymmetry": None, "shape_asymmetry_mode": None, "axisymmetric_until": None,
                "asymmetric_between": None}  # fmt: skip
    k = int(np.argmax([amplitude for amplitude, _, _ in values]))
    broken = [j for j, (amplitude, _, _) in enumerate(values) if amplitude > AXISYMMETRY_TOLERANCE]
    until = times[-1] if not broken else (times[broken[0] - 1] if broken[0] > 0 else None)
    between = [times[broken[0]], times[broken[-1]]] if broken else None
    return {"shape_asymmetry": values[k][0], "shape_asymmetry_mode": values[k][1], "axisymmetric_until": until,
            "asymmetric_between": between}  # fmt: skip


def oocyte_profile(run, x) -> tuple:
    """A frame's figures and checks: the meridian's curvature radius (the kymograph's row) and the
    shell's shape asymmetry."""
    return meridian_curvature_radius(run, x), shape_asymmetry(run, x)


def oocyte_measurements(run) -> dict:
    return {**sphere_wave_measurements(run), **asymmetry_measurements(run)}


def meridian_curvature_radius(run, x, bins=90) -> np.ndarray:
    """The local mean-curvature radius 1/H along the meridian through the origin (x > 0 half-plane
    containing the polar axis), in `bins` bins of the rest polar angle: the kymograph's rows."""
    from .geometry import limit_surface

    surface = limit_surface(run.mesh, x, device=run.operator.device, dtype="float64")
    rest = limit_surface(run.mesh, device=run.operator.device, dtype="float64").points
    axis = run.origin / np.linalg.norm(run.origin)
    side = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    width = 0.5 * mean_edge(run.mesh)
    near = np.abs(rest @ side) < width
    in_plane = np.cross(side, axis)
    theta = np.arctan2(rest @ in_plane, rest @ axis) % (2 * np.pi)  # 0 at the origin, π at the antipode
    theta = np.where(theta > np.pi, 2 * np.pi - theta, theta)
    index = np.minimum((theta[near] / np.pi * bins).astype(int), bins - 1)
    curvature = np.bincount(index, surface.mean_curvature[near] * surface.area[near], bins)
    area = np.bincount(index, surface.area[near], bins)
    with np.errstate(divide="ignore", invalid="ignore"):
        return area / curvature  # 1/H, area-weighted H in each bin


def kymograph_png(run, path) -> None:
    """Fig. 1c: 1/H along the meridian (rest arc length) against time, written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import write_png

    times = [t for t, _ in run.profiles]
    image = np.array([profile[0] for _, profile in run.profiles]) / run.size
    fig, ax = plt.subplots(figsize=(6, 4.5))
    extent = (0, math.pi * run.size, times[-1] if times else 1, times[0] if times else 0)
    shown = ax.imshow(image, aspect="auto", extent=extent, cmap="RdBu", vmin=0.0, vmax=2.0)
    fig.colorbar(shown, label="local mean-curvature radius 1/H, in R")
    ax.set_xlabel("arc length from the wave's origin along a meridian (rest shell)")
    ax.set_ylabel("time")
    ax.set_title(f"{run.name}: curvature kymograph (paper Fig. 1c)")
    fig.tight_layout()
    write_png(fig, path)


def frame_png(run, path) -> None:
    """A rendered frame: the limit surface (control triangles at the limit points) coloured by c."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from .geometry import limit_positions
    from .io import write_png
    from .usd import colour_map

    time, x, c = run.snapshot
    points = limit_positions(run.mesh, x, device=run.operator.device, dtype="float64")
    field = run.operator.field_values(c)
    triangles = run.mesh.triangles
    colours = colour_map(field[triangles].mean(axis=1), 0.0, max(float(field.max()), 1e-12))  # this frame's range
    normals = np.cross(points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]])
    light = np.clip(0.35 + 0.65 * normals @ np.array([0.4, -0.5, 0.77]) / np.linalg.norm(normals, axis=1), 0.2, 1.0)
    fig = plt.figure(figsize=(5, 5))
    ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Poly3DCollection(points[triangles], facecolors=colours * light[:, None], edgecolors="none"))
    low, high = points.min(axis=0), points.max(axis=0)
    centre, half = 0.5 * (low + high), 0.5 * np.max(high - low)
    for setter, k in ((ax.set_xlim, 0), (ax.set_ylim, 1), (ax.set_zlim, 2)):
        setter(centre[k] - half, centre[k] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=15, azim=-60)
    ax.set_axis_off()
    ax.set_title(f"{run.name}, t = {time:.3g} (colour: c from 0 to {field.max():.2g})")
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def polar_coordinates(run) -> tuple:
    """Per rest vertex: its polar angle θ from the wave's origin about the sphere's centre, and its
    azimuth φ about that axis."""
    rest = run.mesh.vertices
    axis = run.origin / np.linalg.norm(run.origin)
    theta = np.arccos(np.clip(rest @ axis / np.linalg.norm(rest, axis=1), -1, 1))
    side = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    return theta, np.arctan2(rest @ np.cross(axis, side), rest @ side)


def ring_modes(radial: np.ndarray, offset: np.ndarray, phi: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """Amplitudes of the azimuthal modes `modes` of `radial` on a latitude ring (its vertices at
    polar offsets `offset` from the ring's centre and azimuths `phi`), less the ring's axisymmetric
    profile across the band (a quadratic in the offset): its slope and curvature would leak into the
    modes of the ring's irregularly placed vertices."""
    trend = np.vander(offset, 3)
    radial = radial - trend @ np.linalg.lstsq(trend, radial, rcond=None)[0]
    return np.abs(np.exp(-1j * np.outer(modes, phi)) @ radial) * 2 / len(radial)


def symmetry_number(run, x, threshold=0.1) -> tuple:
    """(n, amplitude): the dominant azimuthal mode m ≥ 2 of the radial displacement on the latitude
    ring at the wave front (rest polar angle γ t / R, one control edge wide), less its axisymmetric
    trend across the ring, and its amplitude in units of h; n = 0 while every mode is below
    `threshold` h (axisymmetric). A tenth of h: on shells that do not buckle the icosphere's imprint,
    the seeded imperfection and the irregular ring's residual read up to 0.03 h (docs/scenes.md)."""
    R, rest = run.size, run.mesh.vertices
    theta, phi = polar_coordinates(run)
    front = min((run.front_start + run.p["gamma"] * run.profile_time) / R, math.pi)
    ring = np.abs(theta - front) < 0.5 * mean_edge(run.mesh) / R
    if ring.sum() < 8:
        return 0, 0.0
    radial = np.linalg.norm(np.asarray(x)[ring], axis=1) - np.linalg.norm(rest[ring], axis=1)
    modes = np.arange(2, max(3, ring.sum() // 2))
    amplitude = ring_modes(radial, theta[ring] - front, phi[ring], modes) / run.p["thickness"]
    k = int(np.argmax(amplitude))
    return (int(modes[k]) if amplitude[k] > threshold else 0), float(amplitude[k])


# a shell reads as axisymmetric while every ring mode is below this fraction of R: the icosphere's
# imprint reads up to 0.03% on the oocytes, a buckled ascidian 5% and more (docs/scenes.md)
AXISYMMETRY_TOLERANCE = 0.01


def shape_asymmetry(run, x) -> tuple:
    """(amplitude / R, m, θ): the largest azimuthal mode 1 ≤ m ≤ 8 of the change in distance from the
    centroid (so rigid motion reads nothing), over the latitude rings (one control edge wide) about the
    wave's axis, each less its axisymmetric profile across the ring; θ is that ring's rest polar
    angle. m = 1 is a lopsided shell."""
    R, rest, x = run.size, run.mesh.vertices, np.asarray(x)
    theta, phi = polar_coordinates(run)
    radial = np.linalg.norm(x - np.mean(x, axis=0), axis=1) - np.linalg.norm(rest - rest.mean(axis=0), axis=1)
    width = mean_edge(run.mesh) / R
    best = (0.0, 0, 0.0)
    for centre in np.arange(width, math.pi - 0.5 * width, width):
        ring = np.abs(theta - centre) < 0.5 * width
        if ring.sum() < 4 * 8:  # m ≤ 8 with four vertices per wavelength
            continue
        amplitude = ring_modes(radial[ring], theta[ring] - centre, phi[ring], np.arange(1, 9)) / R
        k = int(np.argmax(amplitude))
        if amplitude[k] > best[0]:
            best = (float(amplitude[k]), k + 1, float(centre))
    return best


def buckling_measurements(run) -> dict:
    n = [int(value[0]) for _, value in run.profiles]
    times = [t for t, _ in run.profiles]
    k = int(np.argmax(n)) if n else 0
    return {"symmetry_numbers": n, "n_max": n[k] if n else 0, "t_n_max": times[k] if n else None,
            "t_front_at_equator": (0.5 * math.pi * run.size - run.front_start) / run.p["gamma"]}  # fmt: skip


def buckling_png(run, path) -> None:
    """Fig. S1a: the buckling symmetry number n at the wave front against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import write_png

    fig, ax = plt.subplots(figsize=(5.8, 3.8))
    times = [t for t, _ in run.profiles]
    ax.plot(times, [value[0] for _, value in run.profiles], "o-", label="n")
    ax.axvline((0.5 * math.pi * run.size - run.front_start) / run.p["gamma"], color="0.5", ls="--",
               label="front at the equator")  # fmt: skip
    ax.set_xlabel("time")
    ax.set_ylabel("symmetry number n at the front")
    amplitude = ax.twinx()  # the dominant mode's amplitude: n counts from a tenth of h
    amplitude.plot(times, [value[1] for _, value in run.profiles], color="C1", lw=1, label="its amplitude / h")
    amplitude.set_ylabel("amplitude / h", color="C1")
    ax.set_title(f"{run.name}: n-fold buckling (supplement Fig. S1a)")
    handles = [h for axis in (ax, amplitude) for h in axis.get_legend_handles_labels()[0]]
    amplitude.legend(handles, [h.get_label() for h in handles], loc="center right", fontsize=8)
    fig.tight_layout()
    write_png(fig, path)


def seeded_noise(mesh: Mesh, amplitude: float, seed: int) -> np.ndarray:
    """Positions perturbed by `amplitude` × a standard normal per coordinate (to break symmetry).
    The draws go to the vertices in the lexicographic order of their positions, so that a point's
    perturbation does not depend on how the mesh numbers its vertices (`Mesh.reordered`)."""
    draws = np.random.default_rng(seed).standard_normal(mesh.vertices.shape)
    noise = np.empty_like(draws)
    noise[np.lexsort(mesh.vertices.T[::-1])] = draws
    return mesh.vertices + amplitude * noise
