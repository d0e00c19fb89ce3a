"""Self-contact (ours; the paper has none): keeps the layers of a folded or everted shell apart.

    shell.self_contact = SelfContact(shell)             # d = h, pressure D/d³ at r = d/2

The energy (kernels/self_contact.py) is a double integral over the limit surface's quadrature
points, so it is an exact term of the shell's energy: `Shell.forces` and `Shell.energy` include
it, and so do relaxations. Pairs are candidates from a hash grid within (1 + skin) d, searched
before every relaxation (outside its captured loop). Inside the loop a trial step that takes a
point half the skin from its place at the search is refused (its step halves), and once the
accepted positions have moved a quarter skin the loop stops for a new search and goes on; so no
pair within d is ever missed. Choices and measurements: docs/theory/shell.md.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .checks import positive
from .geometry import evaluate, quadrature_points, spread_quadrature_forces
from .kernels.self_contact import (
    moved_kernel,
    self_contact_candidates_kernel,
    self_contact_pressure_kernel,
)

GRID_CELLS = 128  # hash grid dimension per axis (points hash into it modulo the cell size)


class SelfContact:
    """Repulsion between parts of `shell` that are at least `exclusion` apart at rest (default 2 d:
    a fold with layers closer than d then always meets it) and come within `distance` d (default
    the thickness h: the mid-surfaces of two touching layers) in space.

    `pressure` is the push between two parallel layers at half the distance (default D/d³, D the
    bending stiffness: the pressure that bends the shell on the scale of d); it diverges as the
    layers close, so they cannot be pressed through each other. `skin` (in units of d) widens the
    candidate search so the list stays valid while points move less than half of it.
    """

    def __init__(self, shell, *, distance=None, pressure=None, exclusion=None, skin=1.0):
        self.shell = shell
        if shell.gradient == "autodiff":
            raise ValueError("self-contact needs the analytic gradient: build the Shell with gradient='analytic'")
        if shell.worlds > 1:
            raise ValueError("self-contact acts within one shell: batched worlds (a Mesh.union) would touch each other")
        self.distance = positive("distance", shell.thickness if distance is None else distance)
        bending = shell.young * shell.thickness**3 / (12 * (1 - shell.poisson**2))
        self.pressure = positive("pressure", bending / self.distance**3 if pressure is None else pressure)
        self.exclusion = positive("exclusion", 2 * self.distance if exclusion is None else exclusion)
        if self.exclusion < self.distance:
            raise ValueError(f"exclusion ({self.exclusion:g}) must be at least the contact distance "
                             f"({self.distance:g}), or neighbours on the sheet repel at rest")  # fmt: skip
        self.skin = positive("skin", skin)
        # two parallel layers at gap s push with 2π A s (d/s - 1)³ (continuum limit); = pressure at s = d/2
        self.strength = self.pressure / (math.pi * self.distance)
        t = shell.tables
        rest = evaluate(t, t.positions())
        self.rest_points, self.area = rest["points"], rest["area"]
        spacing = math.sqrt(float(np.mean(self.area.numpy())))
        if spacing > math.sqrt(3) * self.distance:  # a point through the widest gap stays within d of three
            raise ValueError(f"the quadrature points are {spacing:.3g} apart, more than √3 × the contact distance "
                             f"{self.distance:.3g}: layers could pass between them; refine the mesh")  # fmt: skip
        n_q, self.radius = t.n_quadrature_points, (1 + self.skin) * self.distance  # the candidate search's
        # one layer's points within the search radius, three layers' worth of room
        self.capacity = int(3 * math.pi * self.radius**2 / spacing**2) + 16
        with wp.ScopedDevice(shell.device):
            self.points = wp.zeros(n_q, dtype=shell.vec3)
            self.built = wp.zeros(n_q, dtype=shell.vec3)
            self.pressures = wp.zeros(n_q, dtype=shell.vec3)
            self.counts = wp.zeros(n_q, dtype=wp.int32)
            self.neighbours = wp.zeros((n_q, self.capacity), dtype=wp.int32)
            self.grid = wp.HashGrid(GRID_CELLS, GRID_CELLS, GRID_CELLS, dtype=shell.scalar)
        self.searches = 0  # candidate searches so far

    def search(self, x: wp.array) -> None:
        """Candidate pairs at positions x (one host read: a row that overflowed grows the table)."""
        s = self.shell.scalar
        quadrature_points(self.shell.tables, x, self.built)
        self.grid.build(self.built, self.radius)
        while True:
            wp.launch(self_contact_candidates_kernel, dim=len(self.built),
                      inputs=[wp.uint64(self.grid.id), self.built, self.rest_points, s(self.radius), s(self.exclusion)],
                      outputs=[self.neighbours, self.counts], device=self.shell.device)  # fmt: skip
            most = int(self.counts.numpy().max())
            if most <= self.capacity:
                break
            self.capacity = int(1.5 * most)
            self.neighbours = wp.zeros((len(self.built), self.capacity), dtype=wp.int32, device=self.shell.device)
            self.shell.notify_model_changed()  # captured loops read the old table
        self.searches += 1

    def mark_moved(self, flags: wp.array, far_slot: int, near_slot: int) -> None:
        """For the points of the last `add_forces`: flags[far_slot] = 1 when one is half the skin or
        more from its place at the last search, flags[near_slot] = 1 when a quarter (device only:
        the relaxation loop's guards, kernels/relax.py)."""
        s, skin = self.shell.scalar, self.skin * self.distance
        wp.launch(moved_kernel, dim=len(self.points), inputs=[self.points, self.built, s(0.5 * skin), s(0.25 * skin)],
                  outputs=[flags, far_slot, near_slot], device=self.shell.device)  # fmt: skip

    def add_forces(self, x: wp.array, forces: wp.array | None, energy_density: wp.array | None) -> None:
        """forces += -∂E/∂x over the current candidates (when given); energy_density[q] += q's share
        of E (when given). Device only (capturable)."""
        shell, t, s = self.shell, self.shell.tables, self.shell.scalar
        n_q = t.n_quadrature_points
        quadrature_points(t, x, self.points)
        wp.launch(self_contact_pressure_kernel, dim=n_q,
                  inputs=[self.points, self.area, self.neighbours, self.counts, s(self.distance), s(self.strength),
                          int(energy_density is not None)],
                  outputs=[self.pressures, shell._energy_density if energy_density is None else energy_density],
                  device=shell.device)  # fmt: skip
        if forces is not None:
            spread_quadrature_forces(t, self.pressures, self.area, forces, shell.deterministic)

    def pairs(self) -> int:
        """Candidate pairs (each counted from both ends) at the last search."""
        return int(self.counts.numpy().sum())
