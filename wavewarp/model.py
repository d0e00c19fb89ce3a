"""The static model of a simulation (NVIDIA Newton's vocabulary), built once by a `ModelBuilder`
that adds only the terms a scene needs, then frozen.

    builder = ModelBuilder(mesh, device="cpu", dtype="float32")
    builder.add_koiter(thickness=0.5, young=1.0, AC=0.5, AI=0.5)     # or add_bilayer(...)
    builder.add_volume(penalty=...)                                   # μV (V − V̄)²
    builder.add_telegraph(gamma=1.0, alpha=0.001, sensitive=True)    # or add_fitzhugh_nagumo(...)
    model = builder.finalize()

A `Model` holds the mesh, the device and dtype, the names of its terms, the `Shell` that evaluates
the elastic, volume and self-contact terms (docs/theory/shell.md), the chemistry's description,
and the walkers' gravity and ground (docs/theory/dynamics.md). Solvers take what they need from
it: `model.operator(x)` builds the Laplace–Beltrami operator on the rest surface (or on positions x),
`model.chemistry_solver(operator)` the wave's solver on it, `model.wave(operator, c0=...)` a
ready-to-run wave stepper (solver, state, time step), `model.mechanics(...)` the shell dynamics'
solver.

Batched worlds: on a `Mesh.union` of N meshes of one topology the model holds N shells that never
interact; add_koiter/add_bilayer and add_volume then take one value per world or one for all
(docs/theory/batches.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .checks import plain, positive
from .chemistry import FitzHughNagumoSolver, TelegraphSolver
from .dynamics import Ground, InertialSolver, OverdampedDynamics, OverdampedSolver, ShellDynamics
from .implicit_dynamics import ImplicitOverdampedDynamics, ImplicitOverdampedSolver
from .laplace import LaplaceBeltrami
from .mesh import Mesh
from .self_contact import SelfContact
from .shell import Shell, per_world
from .waves import FitzHughNagumo, Telegraph


@dataclass(frozen=True)
class Chemistry:
    """The wave: `kind` "telegraph" (gamma, alpha) or "fitzhugh-nagumo" (gamma, nu, kappa, epsilon,
    scheme); on the deformed shell (`sensitive`) or the rest shell (the insensitive twin)."""

    kind: str
    parameters: dict
    sensitive: bool = True
    mass_corrections: int = 0
    transport: str = "conservative"


@dataclass(frozen=True)
class Model:
    """A built simulation model: frozen (its fields cannot be rebound); `terms` names what it holds."""

    mesh: Mesh
    device: object
    dtype: str
    rule: str
    terms: tuple
    shell: Shell | None
    chemistry: Chemistry | None
    gravity: float = 0.0
    density: float | None = None
    ground: Ground | None = None

    def operator(self, x=None, *, assembled: bool = True) -> LaplaceBeltrami:
        """The Laplace–Beltrami operator of the model's mesh and quadrature on positions x (None: the rest
        surface). `assembled=False` applies K matrix-free (cheaper where the surface moves every step)."""
        return LaplaceBeltrami(self.mesh, x, rule=self.rule, assembled=assembled, device=self.device, dtype=self.dtype)

    def _chemistry_options(self) -> dict:
        chemistry = self.chemistry
        return {**chemistry.parameters, "mass_corrections": chemistry.mass_corrections, "transport": chemistry.transport}

    def chemistry_solver(self, operator: LaplaceBeltrami):
        """The wave's solver (`TelegraphSolver` or `FitzHughNagumoSolver`) on `operator`."""
        kind = TelegraphSolver if self.chemistry.kind == "telegraph" else FitzHughNagumoSolver
        return kind(operator, **self._chemistry_options())

    def wave(self, operator: LaplaceBeltrami, **options):
        """A ready-to-run wave (`Telegraph` or `FitzHughNagumo`: solver, state, time step) on `operator`;
        `options` are the stepper's (c0, v0 or w0, dt, ...)."""
        kind = Telegraph if self.chemistry.kind == "telegraph" else FitzHughNagumo
        return kind(operator, **self._chemistry_options(), **options)

    def mechanics(self, *, overdamped: bool = False, implicit: bool = False, **options):
        """The shell dynamics' solver with the model's gravity and ground: inertial (options: damping) or
        overdamped (options: drag), with `implicit` its backward-Euler step (options: drag, tol, max_iterations)."""
        if implicit and not overdamped:
            raise ValueError("implicit=True is the overdamped mechanics' backward-Euler step: give overdamped=True too")
        kind = ImplicitOverdampedSolver if implicit else OverdampedSolver if overdamped else InertialSolver
        return kind(self.shell, density=self.density, gravity=self.gravity, ground=self.ground, **options)

    def dynamics(self, *, overdamped: bool = False, implicit: bool = False, **options):
        """Ready-to-run shell dynamics (`ShellDynamics`, `OverdampedDynamics`, or with `implicit` the backward-Euler
        `ImplicitOverdampedDynamics`: solver, state, time step) with the model's gravity and ground; `options` are
        the stepper's (damping or drag, x0, dt, safety, ...)."""
        if implicit and not overdamped:
            raise ValueError("implicit=True is the overdamped mechanics' backward-Euler step: give overdamped=True too")
        kind = ImplicitOverdampedDynamics if implicit else OverdampedDynamics if overdamped else ShellDynamics
        return kind(self.shell, density=self.density, gravity=self.gravity, ground=self.ground, **options)


@dataclass
class ModelBuilder:
    """Adds terms to a model of `mesh` on `device` in `dtype` (quadrature `rule`); `finalize()` builds it."""

    mesh: Mesh
    device: object = None
    dtype: str = "float32"
    rule: str = "3"
    _terms: list = field(default_factory=list)
    _shell: dict | None = None
    _volume: float = 0.0
    _self_contact: dict | None = None
    _chemistry: Chemistry | None = None
    _gravity: tuple = (0.0, None)
    _ground: Ground | None = None

    def _add(self, name: str) -> None:
        if name in self._terms:
            raise ValueError(f"the model has a {name} term already")
        self._terms.append(name)

    def add_koiter(self, *, thickness, young, poisson=0.33, AC=0.0, AI=0.0):
        """The Koiter shell with the paper's active reference ā = e^{-AC c} ā⁰, b̄ = (1 - AI c) b̄⁰."""
        return self._add_shell("koiter", thickness=thickness, young=young, poisson=poisson, AC=AC, AI=AI)

    def add_bilayer(self, *, thickness, young, poisson=0.33, AC=0.0, AI=0.0, radius=None):
        """The Koiter shell with the supplement's bilayer reference (radius R of A = (AC/2 - AI)/R)."""
        return self._add_shell("bilayer", thickness=thickness, young=young, poisson=poisson, AC=AC, AI=AI,
                               bilayer_radius=radius)  # fmt: skip

    def _add_shell(self, model: str, **options):
        if self._shell is not None:
            raise ValueError("the model has a shell already (add_koiter or add_bilayer, once)")
        self._add(model)
        self._shell = {"model": model, **options}
        return self

    def add_volume(self, penalty):
        """The volume constraint μV (V - V̄)², V̄ the rest volume (batched worlds: one μV ≥ 0 per world, or one)."""
        self._add("volume")
        if np.ndim(penalty) == 0:
            self._volume = positive("penalty", penalty)
        else:
            self._volume = per_world("penalty", penalty, self.mesh.worlds)
            if np.any(self._volume < 0) or not np.any(self._volume > 0):
                raise ValueError(f"penalty must be >= 0 in every world and > 0 in one, got {plain(penalty)!r}")
        return self

    def add_self_contact(self, **options):
        """Self-contact between layers that meet (wavewarp.SelfContact's options)."""
        self._add("self_contact")
        self._self_contact = options
        return self

    def add_telegraph(self, *, gamma, alpha=0.001, sensitive=True, mass_corrections=0, transport="conservative"):
        """The telegraph wave c_tt + α c_t = γ² Δ c."""
        return self._add_chemistry(Chemistry("telegraph", {"gamma": gamma, "alpha": alpha}, sensitive, mass_corrections,
                                             transport))  # fmt: skip

    def add_fitzhugh_nagumo(self, *, gamma=0.2, nu=-0.01, kappa=1e-4, epsilon=0.005, scheme="explicit", sensitive=True,
                            mass_corrections=0, transport="conservative"):  # fmt: skip
        """The FitzHugh–Nagumo medium c_t = γ² Δ c + c(1-c)(c-ν) - w, w_t = ε (c - κ w)."""
        parameters = {"gamma": gamma, "nu": nu, "kappa": kappa, "epsilon": epsilon, "scheme": scheme}
        return self._add_chemistry(Chemistry("fitzhugh-nagumo", parameters, sensitive, mass_corrections, transport))

    def add_chemistry(self, kind: str, **parameters):
        """`add_telegraph` (kind "telegraph") or `add_fitzhugh_nagumo` (kind "fitzhugh-nagumo")."""
        adders = {"telegraph": self.add_telegraph, "fitzhugh-nagumo": self.add_fitzhugh_nagumo}
        if kind not in adders:
            raise ValueError(f"chemistry kind must be one of {', '.join(adders)}, got {kind!r}")
        return adders[kind](**parameters)

    def _add_chemistry(self, chemistry: Chemistry):
        self._add("chemistry")
        self._chemistry = chemistry
        return self

    def add_gravity(self, *, g, density):
        """Gravity g along -z on the surface density ρ (the lumped mass ρ ∫ N_I dω̄⁰)."""
        self._add("gravity")
        self._gravity = (float(g), positive("density", density))
        return self

    def add_ground(self, ground: Ground):
        """The ground z = 0 with damped contact and regularised Coulomb friction."""
        if not isinstance(ground, Ground):
            raise ValueError(f"ground must be a wavewarp.Ground, got {type(ground).__name__}")
        self._add("ground")
        self._ground = ground
        return self

    def finalize(self) -> Model:
        """Build the terms (the shell's tables and rest forms, self-contact's tables) and freeze the model."""
        shell = None
        if self._shell is not None:
            options = dict(self._shell)
            shell = Shell(self.mesh, options.pop("thickness"), options.pop("young"), volume_penalty=self._volume,
                          rule=self.rule, device=self.device, dtype=self.dtype, **options)  # fmt: skip
            if self._self_contact is not None:
                shell.self_contact = SelfContact(shell, **self._self_contact)
        elif np.any(self._volume) or self._self_contact is not None:
            raise ValueError("volume and self-contact terms act on a shell: add_koiter or add_bilayer first")
        g, density = self._gravity
        return Model(self.mesh, self.device, self.dtype, self.rule, tuple(self._terms), shell, self._chemistry,
                     gravity=g, density=density, ground=self._ground)  # fmt: skip
