"""Koiter shell mechanics (docs/theory/shell.md, docs/theory/scenes.md): energy, exact forces and quasi-static relaxation.

`Shell` holds the static model on one device (patch tables, rest geometry ā⁰ and b̄⁰ at the
quadrature points, moduli, V̄) and evaluates, for positions x and control concentrations c,

    E = E_S + E_B + μV (V - V̄)²   with   ā = e^{-AC c} ā⁰,  b̄ = (1 - AI c) b̄⁰   (paper Eq. 2)

and F = -∂E/∂x, either hand-derived (`gradient="analytic"`, one pass for energy and forces)
or by Warp's automatic differentiation of the energy kernel (`gradient="autodiff"`, the
reference path). Device-level methods (`*_device`) take and fill Warp arrays without
host round-trips, for steppers; the NumPy methods are the public API.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import warp as wp

from .checks import finite, plain, positive
from .device import deterministic_default, mat22, numpy_dtype, reduction_threads, world_sums
from .geometry import SurfaceTables, checked_positions, evaluate
from .kernels import one_device_methods, register_capped
from .kernels.adjoint import eval_shell_rates
from .kernels.adjoint_rest import eval_rest_forms_rate, eval_volume_target_rate
from .kernels.reduce import REDUCTION_BLOCK
from .kernels.regular import fold_padded_forces_kernel, regular_forces_kernel, regular_volume_kernel
from .kernels.staged import staged_shell_forces_kernel
from .kernels.shell import (
    FORCE_BLOCK,
    MAX_PATCH,
    VolumeMoments,
    bilayer_reference_kernel,
    gather_forces_kernel,
    koiter_energy_kernel,
    koiter_reference_kernel,
    negate_kernel,
    shell_force_jets_kernel,
    shell_forces_kernel,
    sum_kernel,
    volume_centroid_forces_kernel,
    volume_energy_kernel,
    volume_kernel,
    volume_terms_kernel,
)
from .mesh import Mesh
from .patches import block_unions, regular_patch_basis
from .relax import NEWTON_STEPS, relax
from .self_contact import SelfContact

MODELS = ("koiter", "bilayer")
GRADIENTS = ("analytic", "autodiff")
REGULAR_PATCHES = ("auto", "vector", "held", "compiled", "general")  # the atomic scatter's kernels (regular_patches)
HELD_FROM_TRIANGLES = 2**18  # "auto" holds regular patches from here (float32, CUDA): 1.08× at 327,680 on an H200
VECTOR_FROM_TRIANGLES = 2**16  # "auto" adds them with vector atomics from here (float32, sm_90 on), H200:
# the general kernel 1.13× faster at 20,480 triangles, the vector kernel 1.42× faster at 81,920
VECTOR_ATOMICS_ARCH = 90  # red.global.v4.f32.add: compute capability 9.0 on
FORCE_BLOCKS = (32, 64, 96, 128, 160, 192, 224, 256)  # threads a block of the force launch (each compiles its own variant)


def per_world(name: str, value, worlds: int, check=finite) -> np.ndarray:
    """A parameter of batched worlds: one value for every world or one per world, each `check`ed."""
    values = np.atleast_1d(np.asarray(value, dtype=object))
    if values.ndim != 1 or len(values) not in (1, worlds):
        raise ValueError(f"{name} must be one number or a list of {worlds} (one per world), got {plain(value)!r}")
    return np.array([check(name, v) for v in np.broadcast_to(values, (worlds,))], dtype=np.float64)


def world_value(values: np.ndarray):
    """A per-world parameter as users read it: a float where every world shares it, else the array."""
    return float(values[0]) if np.all(values == values[0]) else values.copy()


class KoiterReference:
    """The active reference of paper Eq. 2: ā = e^{-AC c} ā⁰, b̄ = (1 - AI c) b̄⁰; `couplings` the
    device arrays of AC and AI, one per world."""

    name = "koiter"
    kernel = koiter_reference_kernel

    def __init__(self, couplings: list):
        self.couplings = couplings

    def launch(self, shell, c: wp.array) -> None:
        """Fill the shell's reference arrays at every quadrature point from control values c."""
        wp.launch(self.kernel, dim=shell.tables.n_quadrature_points,
                  inputs=[c, *shell.tables.weighted_patch(), shell.rest_metric, shell.rest_curvature, *self.couplings,
                          shell.worlds],
                  outputs=shell.reference_arrays(), device=shell.device)  # fmt: skip


class BilayerReference(KoiterReference):
    """The supplement's bilayer: ā = Λ² ā⁰ with Λ² = e^{-AC c}, b̄ = Λ b̄⁰ - A c ā⁰, A = (AC/2 - AI)/R
    (R the sphere's radius), so AI > 0 bends a sphere as the Koiter reference does; `couplings` the
    device arrays of AC and A, one per world."""

    name = "bilayer"
    kernel = bilayer_reference_kernel


def auto_regular_patches(cuda_arch: int | None, scalar, n_triangles: int) -> str:
    """Shell's regular_patches="auto" on a CUDA device of compute capability `cuda_arch` × 0.1 (None: the CPU):
    for float32, "vector" from VECTOR_FROM_TRIANGLES triangles on sm_90 and later, "held" from HELD_FROM_TRIANGLES
    before, where each measured faster than the general kernel; "general" otherwise (BENCHMARKS.md, Speed)."""
    if cuda_arch is None or scalar != wp.float32:
        return "general"
    if cuda_arch >= VECTOR_ATOMICS_ARCH:
        return "vector" if n_triangles >= VECTOR_FROM_TRIANGLES else "general"
    return "held" if n_triangles >= HELD_FROM_TRIANGLES else "general"


def resolved_regular_patches(regular_patches: str, cuda_arch: int | None, scalar, n_triangles: int) -> str:
    """The kernel a Shell's `regular_patches` choice launches: "auto" decided, and "vector" in float64 (which has
    no vector atomics) "held"."""
    if regular_patches == "auto":
        return auto_regular_patches(cuda_arch, scalar, n_triangles)
    return "held" if regular_patches == "vector" and scalar != wp.float32 else regular_patches


@one_device_methods("energy_device", "forces_device", "volume_gradient_device")
class Shell:
    """Active Koiter shell on the Loop limit surface of `mesh` (its vertices are the rest state).

    thickness h, young Y, poisson ν ∈ (-1, 0.5); AC, AI the active metric and curvature
    couplings; volume_penalty μV; model "koiter" or "bilayer" (bilayer_radius R sets
    A = (AC/2 - AI)/R, default the radius of the sphere with the rest area); rule the quadrature;
    gradient "analytic" or "autodiff"; deterministic=True sums forces in a fixed order (None: as
    `wavewarp.device.set_deterministic` chose); staged_block=B stages each B consecutive triangles' patch
    vertices in shared memory for the force kernel (one global read and atomic per vertex and block;
    CUDA, B = 1 on the CPU, where Warp runs a tile kernel's block as one lane); force_block, the threads
    of a block of the (atomic) force kernel's CUDA launch: a multiple of 32 up to 256 (the kernel's
    ~160 registers a thread let three 64-thread blocks run on an SM where one of 256 does: 64, the
    default, is the fastest measured); force_registers=N caps that kernel's registers a thread on CUDA
    (24–255; None: the compiler's choice), the rest spilling to local memory. regular_patches: "compiled"
    sends the regular triangles (every corner of valence 6) to a kernel with their patch basis compiled in
    as constants (kernels/regular.py) and the others to the general kernel; "held" does the same holding
    each patch's positions in registers across its points; "vector" holds them too and adds each vertex's
    force as one 16-byte vector atomic (sm_90 on; float32: in float64 it is "held") into a padded accumulator
    folded into the forces after; "general" sends every triangle to the general kernel; "auto", the default,
    is for float32 on CUDA "vector" from `VECTOR_FROM_TRIANGLES` triangles (all worlds) on sm_90 and later,
    "held" from `HELD_FROM_TRIANGLES` before, and "general" otherwise (the split's extra launches cost more
    than they save on small shells; the CPU and float64 gain nothing). The choice concerns the atomic scatter
    (not the staged or deterministic kernels) and, any but "general", the volume moments (one triangle an item,
    regular ones from literals: `regular_volume_kernel`).

    Batched worlds: on a `Mesh.union`, thickness, young, AC, AI, volume_penalty and bilayer_radius
    take one value per world (or one for all); ν is shared. Worlds never interact.
    """

    def __init__(self, mesh: Mesh, thickness, young, poisson=0.33, AC=0.0, AI=0.0, volume_penalty=0.0,
                 model="koiter", *, rule="3", gradient="analytic", deterministic=None, bilayer_radius=None,
                 staged_block=None, force_block=FORCE_BLOCK, force_registers=None, regular_patches="auto",
                 device=None, dtype="float32"):  # fmt: skip
        if not isinstance(mesh, Mesh):
            raise ValueError(f"mesh must be a wavewarp.mesh.Mesh, got {type(mesh).__name__}")
        self.mesh = mesh
        worlds = mesh.worlds
        self._thickness = per_world("thickness", thickness, worlds, positive)
        self._young = per_world("young", young, worlds, positive)
        self.poisson = finite("poisson", poisson)
        if not -1.0 < self.poisson < 0.5:
            raise ValueError(f"poisson must lie in (-1, 0.5), got {plain(poisson)!r}")
        self._AC, self._AI = per_world("AC", AC, worlds), per_world("AI", AI, worlds)
        self._volume_penalty = per_world("volume_penalty", volume_penalty, worlds)
        if np.any(self._volume_penalty < 0):
            raise ValueError(f"volume_penalty must be >= 0, got {plain(volume_penalty)!r}")
        if model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        if gradient not in GRADIENTS:
            raise ValueError(f"gradient must be one of {', '.join(GRADIENTS)}, got {gradient!r}")
        if worlds > 1 and gradient != "analytic":
            raise ValueError("batched worlds take gradient='analytic' (the autodiff path sums one world)")
        self.thickness, self.young = world_value(self._thickness), world_value(self._young)
        self.AC, self.AI = world_value(self._AC), world_value(self._AI)
        self.volume_penalty = world_value(self._volume_penalty)
        self.has_volume = bool(np.any(self._volume_penalty > 0))  # some world has the volume term
        self.model, self.gradient, self.deterministic = model, gradient, deterministic_default(deterministic)

        self.rule = str(rule)
        self.tables = SurfaceTables.of(mesh, self.rule, device=device, dtype=dtype)
        self.device, self.scalar, self.vec3 = self.tables.device, self.tables.scalar, self.tables.vec3
        self._real = numpy_dtype(self.scalar)
        patch = int(np.diff(self.tables.host.patch_start).max())
        if patch > MAX_PATCH:
            raise ValueError(f"the mesh has a vertex of valence {patch - 6}; the force kernel handles valences up to "
                             f"{MAX_PATCH - 6}: remesh to lower it")  # fmt: skip
        n_q = self.tables.n_quadrature_points
        rest = evaluate(self.tables, self.tables.positions())
        self.rest_metric, self.rest_curvature = rest["metric"], rest["curvature"]
        areas = rest["area"].numpy().astype(np.float64).reshape(worlds, -1).sum(axis=1)
        self.rest_area = world_value(areas)
        if bilayer_radius is None:
            bilayer_radius = np.sqrt(areas / (4 * math.pi))
        self._bilayer_radius = per_world("bilayer_radius", bilayer_radius, worlds, positive)
        self.bilayer_radius = world_value(self._bilayer_radius)
        self.reference = (KoiterReference(self.world_arrays(self._AC, self._AI)) if model == "koiter" else
                          BilayerReference(self.world_arrays(self._AC, (self._AC / 2 - self._AI) / self._bilayer_radius)))
        nu = self.poisson
        stretching, bending = self._young * self._thickness / (8 * (1 - nu**2)), self._young * self._thickness**3 / (24 * (1 - nu**2))
        self.moduli = (world_value(stretching), world_value(bending))  # the stretching and bending moduli
        self._moduli = self.world_arrays(stretching, bending)
        m22 = mat22(self.scalar)
        with wp.ScopedDevice(self.device):
            self._penalty = wp.array(self._volume_penalty, dtype=wp.float64)
            self._target = wp.zeros(worlds, dtype=wp.float64)
            self.ref_metric = wp.empty(n_q, dtype=m22)
            self.ref_metric_inv = wp.empty(n_q, dtype=m22)
            self.ref_curvature = wp.empty(n_q, dtype=m22)
            self.ref_weight = wp.empty(n_q, dtype=self.scalar, requires_grad=False)
            self._energy = wp.zeros(1, dtype=wp.float64, requires_grad=True)
            self._moments = wp.zeros(worlds, dtype=VolumeMoments, requires_grad=True)
            self._no_points = (wp.empty(0, dtype=self.vec3),) * 2  # rates_device without per-point outputs
            self._energy_density = wp.zeros(n_q, dtype=wp.float64, requires_grad=True)
            self._moment_terms = wp.zeros(max(n_q, mesh.n_vertices), dtype=VolumeMoments, requires_grad=True)
            self._c = wp.zeros(mesh.n_vertices, dtype=self.scalar)
            self._x = wp.zeros(mesh.n_vertices, dtype=self.vec3, requires_grad=True)
            self._forces = wp.zeros(mesh.n_vertices, dtype=self.vec3)
            if self.deterministic:
                self._jets = wp.zeros((n_q, 6), dtype=self.vec3)
        self.staged_block = staged_block
        self._staged = None if staged_block is None else self._staged_tables(staged_block)
        if isinstance(force_block, bool) or force_block not in FORCE_BLOCKS:
            raise ValueError(f"force_block must be one of {', '.join(map(str, FORCE_BLOCKS))} threads, got {force_block!r}")
        self.force_block = int(force_block)
        if force_registers is not None and (isinstance(force_registers, bool) or not isinstance(force_registers, int)
                                            or not 24 <= force_registers <= 255):  # fmt: skip
            raise ValueError(f"force_registers must be a whole number of registers from 24 to 255, or None (the "
                             f"compiler's choice), got {force_registers!r}")  # fmt: skip
        self.force_registers = force_registers
        self._force_kernel = (shell_forces_kernel if force_registers is None
                              else register_capped(shell_forces_kernel, force_registers))  # fmt: skip
        if regular_patches not in REGULAR_PATCHES:
            raise ValueError(f"regular_patches must be one of {', '.join(REGULAR_PATCHES)}, got {regular_patches!r}")
        self.regular_patches = regular_patches  # as asked: a twin of another dtype decides "auto" for itself
        arch = self.device.arch if self.device.is_cuda else None
        self.regular_kernel = resolved_regular_patches(regular_patches, arch, self.scalar, mesh.n_triangles)
        self._force_launches = self._force_kernel_launches(self.regular_kernel)
        self._padded_forces = (wp.zeros(mesh.n_vertices, dtype=wp.vec4f, device=self.device)
                               if self.regular_kernel == "vector" else None)  # the vector atomics' accumulator
        self._volume_kernel = (volume_kernel if self.regular_kernel == "general"
                               else regular_volume_kernel(*regular_patch_basis(self.rule), self.scalar))  # fmt: skip
        self._listeners = []  # weak references to the solvers' notify_model_changed (captured graphs to drop)
        self.rest_volume = self._volume_of(self.tables.positions())
        lengths = np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1)
        self.edge_length = float(np.mean(lengths))  # ℓ̄ over every world
        self.world_edge_lengths = np.array([np.mean(world) for world in np.split(lengths, worlds)])  # each world's
        self.update_reference(self._c)  # the rest reference (c = 0) until a wave sets one: no array read unset
        self._relaxation = None  # relax's device buffers and captured loop (wavewarp/relax.py), built on first use
        self._newton = None  # the Newton finish's Hessian pattern and buffers (wavewarp/newton.py), on first use
        self.newton_steps = 0  # Newton steps of the last relaxation
        self._self_contact = None  # a SelfContact term (wavewarp/self_contact.py), when the scene needs one
        self._terms = ()  # further energy terms of a relaxation (wavewarp/resting_ground.py)

    @property
    def worlds(self) -> int:
        return self.mesh.worlds

    def world_arrays(self, *values) -> list:
        """Per-world parameters as device arrays of the shell's scalar (launch arguments)."""
        return [wp.array(np.asarray(v, dtype=self._real), dtype=self.scalar, device=self.device) for v in values]

    def twin(self, dtype: str):
        """The same shell (terms, options, V̄) in another dtype on the same device: the Newton finish of a
        float32 shell works on its float64 twin. Self-contact and `terms` are not copied."""
        twin = Shell(self.mesh, self._thickness, self._young, self.poisson, self._AC, self._AI, self._volume_penalty,
                     self.model, rule=self.rule, gradient=self.gradient, deterministic=self.deterministic,
                     bilayer_radius=self._bilayer_radius, staged_block=self.staged_block,
                     force_block=self.force_block, force_registers=self.force_registers,
                     regular_patches=self.regular_patches, device=self.device, dtype=dtype)  # fmt: skip
        twin.rest_volume = self.rest_volume
        return twin

    def _force_kernel_launches(self, regular_patches: str) -> list:
        """The atomic scatter's launches, (kernel, triangle list) each: regular triangles to the compiled-basis
        kernel and the others to the general one, or every triangle to the general one."""
        host = self.tables.host
        regular = (host.triangle_type == 0) if regular_patches != "general" else np.zeros(host.n_triangles, bool)
        launches = []
        with wp.ScopedDevice(self.device):
            if regular.any():  # patch type 0 is the regular patch
                kernel = regular_forces_kernel(*regular_patch_basis(self.rule), self.scalar,
                                               regular_patches in ("held", "vector"), regular_patches == "vector")
                launches.append((kernel, wp.array(np.flatnonzero(regular), dtype=wp.int32)))
            if not regular.all():
                launches.append((self._force_kernel, wp.array(np.flatnonzero(~regular), dtype=wp.int32)))
        return launches

    def _staged_tables(self, block) -> dict:
        """The staged force kernel's launch: its kernel, blocks, per-block vertex unions and local patch table."""
        if isinstance(block, bool) or not isinstance(block, (int, np.integer)) or block < 1:
            raise ValueError(f"staged_block must be a whole number of triangles per block >= 1, got {block!r}")
        if self.device.is_cpu and block != 1:
            raise ValueError(f"staged_block = {block} on the CPU: Warp runs a tile kernel's block as one lane there; "
                             "use staged_block=1 (or run on CUDA)")  # fmt: skip
        if self.deterministic:
            raise ValueError("staged_block adds forces with atomics; deterministic=True gathers them in a fixed order: "
                             "choose one")  # fmt: skip
        unions = block_unions(self.tables.host, int(block), multiple=1 if block == 1 else 32)
        with wp.ScopedDevice(self.device):
            return dict(kernel=staged_shell_forces_kernel(unions.capacity), block=unions.block,
                        blocks=len(unions.block_vertices), patch_local=wp.array(unions.patch_local, dtype=wp.int32),
                        block_vertices=wp.array(unions.block_vertices, dtype=wp.int32))  # fmt: skip

    def listen(self, notify) -> None:
        """Call `notify()` (a bound method, held weakly) whenever V̄ or the set of terms changes: the
        solvers' captured graphs hold them as launch arguments and must be captured anew."""
        self._listeners.append(weakref.WeakMethod(notify))

    def notify_model_changed(self) -> None:
        """Tell every listening solver that the model changed (V̄, a term, a term's tables)."""
        live = [reference for reference in self._listeners if reference() is not None]
        self._listeners = live
        for reference in live:
            reference()()

    @property
    def rest_volume(self):
        """V̄ of the volume term μV (V − V̄)²: the rest shape's volume unless set (a pressure load); one
        per world (an array) for batched worlds that differ. A new value reaches every stepper's next step."""
        return world_value(self._rest_volume)

    @rest_volume.setter
    def rest_volume(self, volume) -> None:
        self._rest_volume = per_world("rest_volume", volume, self.worlds)
        self._target.assign(self._rest_volume)
        self.notify_model_changed()

    @property
    def self_contact(self):
        """The shell's SelfContact term (wavewarp/self_contact.py), or None (the default)."""
        return self._self_contact

    @self_contact.setter
    def self_contact(self, term) -> None:
        if term is not None and (not isinstance(term, SelfContact) or term.shell is not self):
            raise ValueError("self_contact must be None or a SelfContact built for this shell")
        self._self_contact = term
        self.notify_model_changed()  # captured loops hold the old set of terms

    @property
    def terms(self) -> tuple:
        """Further energy terms, built for this shell, each adding its forces and energy density with
        `add_forces(x, forces, energy_density)` and told by `begin_step(x)` where each of QuasiStatic's load
        steps starts (wavewarp.RestingGround); () by default."""
        return self._terms

    @terms.setter
    def terms(self, terms) -> None:
        terms = tuple(terms)
        for term in terms:
            if getattr(term, "shell", None) is not self or not all(callable(getattr(term, name, None))
                                                                   for name in ("add_forces", "begin_step")):
                raise ValueError(f"each of the shell's terms must be built for this shell (such as "
                                 f"RestingGround(shell, ...)), got {type(term).__name__}")  # fmt: skip
        self._terms = terms
        self.notify_model_changed()

    # ---------------------------------------------------------------- device-level API
    def _s(self, value) -> object:
        return self.scalar(value)

    def reference_arrays(self) -> list:
        """ā, ā⁻¹, b̄ and the reference area weight at every quadrature point."""
        return [self.ref_metric, self.ref_metric_inv, self.ref_curvature, self.ref_weight]

    def update_reference(self, c: wp.array) -> None:
        """Active reference ā, ā⁻¹, b̄, dω̄ at every quadrature point from control values c (`self.reference`:
        a KoiterReference or a BilayerReference)."""
        self._c_host = None  # the NumPy API's cached c no longer describes the reference
        self.reference_c = c  # the Newton finish's float64 twin copies it (wavewarp/newton.py)
        self.reference.launch(self, c)

    def _volume_of(self, x: wp.array):
        """The enclosed volume (one per world: an array for batched worlds)."""
        self._launch_volume(x, differentiable=False)
        m = self._moments.numpy().astype(np.float64)
        volumes = m[:, 3] - np.einsum("wi,wi->w", m[:, 4:7], m[:, :3]) / self.mesh.vertices_per_world
        return float(volumes[0]) if self.worlds == 1 else volumes

    def _sum(self, values: wp.array, total: wp.array, differentiable: bool) -> None:
        """total[w] = Σ of world w's values (total[0] = Σ values where total holds one entry): block
        reductions per world (their blocks add atomically, in any order; one block per world for
        deterministic shells), or same-address atomics into total[0] where Warp's tape must follow."""
        if differentiable:
            total.zero_()
            wp.launch(sum_kernel, dim=len(values), inputs=[values], outputs=[total], device=self.device)
        else:
            world_sums(values, total, self.worlds, self.deterministic)

    def _launch_volume(self, x: wp.array, differentiable: bool) -> None:
        """The volume moments [S, V₀, Σx] (kernels/shell.py `volume_kernel`) into self._moments: per-item
        terms and a differentiable sum, or one block-reducing pass (one block for deterministic shells)."""
        t = self.tables
        patch = [x, *t.weighted_patch()]
        n = len(self._moment_terms)
        if differentiable:
            wp.launch(volume_terms_kernel, dim=n, inputs=patch, outputs=[self._moment_terms], device=self.device)
            self._sum(self._moment_terms, self._moments, differentiable)
            return
        self._moments.zero_()
        if self._volume_kernel is volume_kernel:
            items = n // self.worlds  # one point or vertex an item
        else:  # one triangle or vertex an item
            items = max(self.mesh.n_triangles, self.mesh.n_vertices) // self.worlds
        threads = reduction_threads(items, self.deterministic)  # per world: no block straddles two worlds
        wp.launch(self._volume_kernel, dim=threads * self.worlds, inputs=patch + [self.worlds, items, threads],
                  outputs=[self._moments], block_dim=REDUCTION_BLOCK, device=self.device)  # fmt: skip

    def _elastic_inputs(self, x: wp.array, moduli=None) -> list:
        t = self.tables
        stretching, bending = self._moduli if moduli is None else moduli
        return [x, *t.patch(), *self.reference_arrays(), stretching, bending, self._s(self.poisson), self.worlds]

    def energy_device(self, x: wp.array, energy: wp.array) -> None:
        """energy[0] = E(x) at the current reference (float64; differentiable with wp.Tape)."""
        wp.launch(koiter_energy_kernel, dim=self.tables.n_quadrature_points, inputs=self._elastic_inputs(x),
                  outputs=[self._energy_density], device=self.device)  # fmt: skip
        if self.self_contact is not None:
            self.self_contact.add_forces(x, None, self._energy_density)
        for term in self._terms:
            term.add_forces(x, None, self._energy_density)
        self._sum(self._energy_density, energy, differentiable=True)
        if self.has_volume:
            self._launch_volume(x, differentiable=self.worlds == 1)  # the autodiff path has one world
            wp.launch(volume_energy_kernel, dim=self.worlds,
                      inputs=[self._moments, self.mesh.vertices_per_world, self._target, self._penalty],
                      outputs=[energy], device=self.device)  # fmt: skip

    def forces_device(self, x: wp.array, forces: wp.array, energy: wp.array | None = None) -> None:
        """forces = -∂E/∂x and, when given, energy = E at the current reference (both overwritten): energy[0]
        the total, or, for an array of one entry per batched world, each world's energy.

        No host round-trip: capturable in a CUDA graph (dynamics).
        """
        if self.gradient == "autodiff":
            self._autodiff_forces(x, forces, self._energy if energy is None else energy)
            return
        self._force_terms(x, forces, energy, None, self._target, self._penalty, self.has_volume)

    def volume_gradient_device(self, x: wp.array, gradient: wp.array) -> None:
        """gradient = ∂V/∂x: the volume term's forces at pressure -1 (μV = 1/2, V̄ = V + 1), no elastic terms."""
        zero = self.world_arrays(np.zeros(self.worlds))[0]
        with wp.ScopedDevice(self.device):
            target = wp.array(np.atleast_1d(self._volume_of(x)) + 1.0, dtype=wp.float64)
            penalty = wp.full(self.worlds, 0.5, dtype=wp.float64)
        self._force_terms(x, gradient, None, (zero, zero), target, penalty, True, contact=False)

    def rates_device(self, x: wp.array, direction: wp.array, rates: wp.array, by_concentration=None,
                     ramp: float = 1.0) -> None:  # fmt: skip
        """rates[0] = (Ė_S, Ė_B, Ė_V, ∂(Ė_S + Ė_B)/∂AC, ∂(Ė_S + Ė_B)/∂AI) as x moves along `direction`, at the current
        reference, Koiter's or the bilayer's (one world; kernels/adjoint.py `shell_rates_kernel`): the shell's
        parameters' share of a gradient. `by_concentration`: two per-quadrature-point arrays (start, end) that gain
        -∂Ė/∂c_q, (1 - ramp) and ramp of it: the reference's concentrations' adjoint."""
        if self.has_volume:
            self._launch_volume(x, differentiable=False)
        by_concentration = self._no_points if by_concentration is None else by_concentration
        eval_shell_rates(x, direction, self.reference_c, self.tables.weighted_patch(), self.reference_arrays(),
                         [self.rest_metric, self.rest_curvature], list(self._moduli), self.poisson, self.AC, self.AI,
                         self.bilayer_radius if self.model == "bilayer" else 0.0,
                         [self._moments, self._target, self._penalty], rates, by_concentration, ramp)  # fmt: skip

    def rest_forms_rates_device(self, x: wp.array, direction: wp.array, metric_hat: wp.array,
                                curvature_hat: wp.array) -> None:  # fmt: skip
        """metric_hat_q −= ∂Ė/∂ā⁰_q and curvature_hat_q −= ∂Ė/∂b̄⁰_q at every quadrature point as x moves along
        `direction`, at the current reference (one world; kernels/adjoint_rest.py): the rest forms' share of a
        gradient."""
        bilayer_A = (self.AC / 2 - self.AI) / self.bilayer_radius if self.model == "bilayer" else None
        eval_rest_forms_rate(x, direction, self.reference_c, self.tables.patch(), self.reference_arrays(),
                             list(self._moduli), self.poisson, self.AC, self.AI, bilayer_A, metric_hat,
                             curvature_hat)  # fmt: skip

    def volume_target_rate_device(self, rates: wp.array, out: wp.array) -> None:
        """out[0] −= ∂Ė/∂V̄ (one world) from `rates_device`'s sums."""
        eval_volume_target_rate(rates, out)

    def _force_terms(self, x, forces, energy, moduli, target, penalty, with_volume: bool, contact: bool = True) -> None:
        """forces_device with the elastic moduli (None: the shell's), the per-world volume targets and
        penalties (float64 device arrays) given, and the volume term where `with_volume`."""
        t = self.tables
        volume = [self._moments, target, penalty]
        if with_volume:
            self._launch_volume(x, differentiable=False)  # V for the pressure, S and x̄ for the centroid term
            if not self.deterministic:  # the atomic scatter adds onto the centroid term
                wp.launch(volume_centroid_forces_kernel, dim=len(forces), inputs=volume + [self.worlds],
                          outputs=[forces], device=self.device)  # fmt: skip
        elif not self.deterministic:
            forces.zero_()  # the atomic scatter adds; the deterministic gather writes
        inputs = self._elastic_inputs(x, moduli) + [t.weights, *volume, int(energy is not None)]
        if self._staged is not None:
            staged = self._staged
            inputs[2] = staged["patch_local"]  # in place of patch_vertices: each entry's place in its block's union
            wp.launch_tiled(staged["kernel"], dim=[staged["blocks"]], block_dim=staged["block"],
                            inputs=inputs + [self._energy_density, staged["block_vertices"], forces],
                            device=self.device)  # fmt: skip
        elif not self.deterministic:
            stretching, bending = self._moduli if moduli is None else moduli
            for kernel, triangles in self._force_launches:
                arguments = (inputs + [triangles] if kernel is self._force_kernel else  # the regular kernel: no tables
                             [x, t.patch_start, t.patch_vertices, triangles, *self.reference_arrays(), stretching,
                              bending, self._s(self.poisson), self.worlds, *volume, int(energy is not None)])  # fmt: skip
                added = forces if kernel is self._force_kernel or self._padded_forces is None else self._padded_forces
                wp.launch(kernel, dim=len(triangles), inputs=arguments, outputs=[self._energy_density, added],
                          block_dim=self.force_block, device=self.device)  # fmt: skip
            if self._padded_forces is not None:
                wp.launch(fold_padded_forces_kernel, dim=len(forces), inputs=[self._padded_forces], outputs=[forces],
                          device=self.device)  # fmt: skip
        else:
            wp.launch(shell_force_jets_kernel, dim=t.n_quadrature_points, inputs=inputs,
                      outputs=[self._energy_density, self._jets], device=self.device)  # fmt: skip
            wp.launch(gather_forces_kernel, dim=self.mesh.n_vertices,
                      inputs=[self._jets, *t.vertex_entries(), t.patch_start, t.triangle_type, t.basis,
                              t.points_per_triangle, *volume, self.worlds],
                      outputs=[forces], device=self.device)  # fmt: skip
        if contact and self.self_contact is not None:
            self.self_contact.add_forces(x, forces, None if energy is None else self._energy_density)
        for term in self._terms if contact else ():
            term.add_forces(x, forces, None if energy is None else self._energy_density)
        if energy is not None:
            self._sum(self._energy_density, energy, differentiable=False)
            if with_volume:
                wp.launch(volume_energy_kernel, dim=self.worlds, inputs=[self._moments, self.mesh.vertices_per_world,
                                                                         *volume[1:]],
                          outputs=[energy], device=self.device)  # fmt: skip

    def _autodiff_forces(self, x: wp.array, forces: wp.array, energy: wp.array) -> None:
        xg = wp.clone(x, requires_grad=True)
        energy.requires_grad = True
        tape = wp.Tape()
        with tape:
            self.energy_device(xg, energy)
        tape.backward(loss=energy)
        wp.launch(negate_kernel, dim=len(forces), inputs=[xg.grad], outputs=[forces], device=self.device)
        tape.zero()

    # ---------------------------------------------------------------- NumPy API
    def _set(self, x, c, search: bool = True) -> wp.array:
        x = checked_positions(x, self.mesh.n_vertices)
        c = self.checked_concentrations(c)
        self._x.assign(x.astype(self._real))
        if self._c_host is None or not np.array_equal(c, self._c_host):
            self._c.assign(c.astype(self._real))
            self.update_reference(self._c)
            self._c_host = c.copy()
        if search and self.self_contact is not None:
            self.self_contact.search(self._x)  # relax searches itself
        return self._x

    def checked_concentrations(self, c) -> np.ndarray:
        """(V,) finite float64 control concentrations (a scalar fills every vertex), or ValueError."""
        c = np.asarray(c, dtype=np.float64)
        if c.shape == ():
            c = np.full(self.mesh.n_vertices, float(c))
        if c.shape != (self.mesh.n_vertices,):
            raise ValueError(f"c must have shape ({self.mesh.n_vertices},) for this mesh, got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError(f"c[{int(np.flatnonzero(~np.isfinite(c))[0])}] is not finite (NaN or Inf)")
        return c

    def energy(self, x, c=0.0) -> float:
        """Total energy E_S + E_B + E_V at positions x (V, 3) and control concentrations c (V,)."""
        xw = self._set(x, c)
        self.energy_device(xw, self._energy)
        return float(self._energy.numpy()[0])

    def forces(self, x, c=0.0) -> np.ndarray:
        """(V, 3) forces, exactly -∂energy/∂x."""
        xw = self._set(x, c)
        self.forces_device(xw, self._forces, self._energy)
        return self._forces.numpy().astype(np.float64)

    def volume(self, x) -> float:
        """Volume enclosed by the limit surface at positions x."""
        return self._volume_of(self.tables.positions(checked_positions(x, self.mesh.n_vertices)))

    def force_scale(self):
        """Y h ℓ̄: the force on a vertex from a unit strain over one mean control edge ℓ̄ (one per batched
        world where they differ)."""
        return world_value(self._young * self._thickness * self.world_edge_lengths)

    def relax(self, x0, c=0.0, tol=None, max_iterations=20000, callback=None, method="auto",
              newton_steps=NEWTON_STEPS) -> np.ndarray:  # fmt: skip
        """Quasi-static equilibrium from x0 under concentrations c (docs/theory/shell.md).

        Stops when max_I |F_I| <= tol · Y h ℓ̄ (tol is a strain-like number; default 1e-5 in
        float32, ten times its measured round-off floor, and 1e-9 in float64). `method`: "ncg",
        preconditioned nonlinear conjugate gradients with an Armijo line search (at most
        `max_iterations`); "newton", Levenberg–Marquardt Newton steps on the sparse Hessian (at
        most `newton_steps`); "auto", CG, and Newton from where CG stopped if it spent its
        budget (docs/theory/shell.md). The energy falls monotonically. Raises RelaxationError saying how
        far it got when it does not converge. Batched worlds relax together by nonlinear CG, each with
        its own line search and convergence test ("auto" has no Newton finish there); the error's
        `.worlds` names those that did not converge.
        """
        if tol is None:
            tol = 1e-5 if self.scalar == wp.float32 else 1e-9
        tol = positive("tol", tol)
        xw = self._set(x0, c, search=False)
        return relax(self, xw, tol, int(max_iterations), callback, method=method, newton_steps=int(newton_steps))
