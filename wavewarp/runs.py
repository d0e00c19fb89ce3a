"""What every scene run shares: the scene's mesh, its clock, seeded imperfections, the transport choice.

A run (wavewarp/quasistatic.py, wavewarp/walker.py) is what a scene's `build` returns and the
driver (wavewarp/driver.py) steps: `series` (the HDF5 frames' names and shapes), `frames`,
`frame()`, `advance_frame()`, `restore(frame)`, `record(time, frame, stored)`, `measurements()`,
`figures(stem)`, plus `mesh`, `shell`, `operator`, `concentrations` (every frame's, for the colour
scale) and `resolved` (the parameters with every automatic value resolved, stored with the trajectory).
"""

from __future__ import annotations

import numpy as np

from .chemistry import TRANSPORTS
from .mesh import Mesh
from .parameters import param
from .sizing import check_run_size


def transport_parameter():
    """The scenes' `transport` parameter (docs/theory/transport.md)."""
    return param("conservative", "how the chemical moves with a deforming shell: conservative keeps each vertex's "
                 "amount M c; material keeps the control values", choices=TRANSPORTS, legacy="material")  # fmt: skip


def scene_mesh(mesh: Mesh | None, build_default, report=print, *, size: tuple, device=None) -> Mesh:
    """The scene's own mesh, `build_default()` once `size` = (parameter name, value, generator) passed
    the size guard, or `--mesh` refined once where a triangle has two extraordinary vertices."""
    if mesh is None:
        check_run_size(*size, device=device)
        mesh = build_default()
    if mesh.needs_refinement:
        report("the mesh has triangles with two extraordinary vertices: refined once by Loop subdivision")
        mesh = mesh.refined_for_patches()  # renumbered for locality, as the generators' meshes
    return mesh


def mean_edge(mesh: Mesh) -> float:
    return float(np.mean(np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1)))


def seeded_noise(mesh: Mesh, amplitude: float, seed: int) -> np.ndarray:
    """Positions perturbed by `amplitude` × a standard normal per coordinate (to break symmetry).
    The draws go to the vertices in the lexicographic order of their positions, so that a point's
    perturbation does not depend on how the mesh numbers its vertices (`Mesh.reordered`)."""
    draws = np.random.default_rng(seed).standard_normal(mesh.vertices.shape)
    noise = np.empty_like(draws)
    noise[np.lexsort(mesh.vertices.T[::-1])] = draws
    return mesh.vertices + amplitude * noise


def imperfect(mesh: Mesh, amplitude: float, seed: int) -> Mesh:
    """The mesh with its positions perturbed by `seeded_noise` (itself where `amplitude` is 0)."""
    return Mesh(seeded_noise(mesh, amplitude, seed), mesh.triangles) if amplitude > 0 else mesh


class WaveClock:
    """A run's time and step count are its wave's."""

    @property
    def time(self) -> float:
        return self.wave.time

    @property
    def steps(self) -> int:
        return self.wave.steps
