"""The viscous drag of one overdamped step, as an energy term of the step's minimization (docs/theory/transport.md,
"Couplings"): at each quadrature point q of the limit surface, with rest area w_q = dω̄⁰_q,

    e_q = ½ (ζ / Δt) |p_q − a_q|² w_q,

a_q the point where the step started. Minimizing E + Σ e_q is the backward-Euler step of ζ ṗ = f per unit rest area.

The walkers' lumped form (docs/theory/dynamics.md, "Implicit overdamped mechanics") acts on the control points with
their lumped masses M_I: e_I = ½ (ζ M_I / Δt) |x_I − a_I|².
"""

from typing import Any

import warp as wp

from . import declare_overloads, one_device


@wp.kernel
def drag_kernel(
    points: wp.array(dtype=Any),
    anchors: wp.array(dtype=Any),
    area: wp.array(dtype=Any),
    coefficient: wp.array(dtype=Any),
    points_per_world: int,
    with_energy: int,
    pressures: wp.array(dtype=Any),
    energy_density: wp.array(dtype=wp.float64),
):
    """pressures_q = −(ζ/Δt)(p_q − a_q) (force per rest area) and, with `with_energy`, energy_density_q += e_q;
    ζ/Δt is q's world's `coefficient`."""
    q = wp.tid()
    d = points[q] - anchors[q]
    k = coefficient[q // points_per_world]
    pressures[q] = -k * d
    if with_energy != 0:
        half = type(k)(0.5)
        energy_density[q] += wp.float64(half * k * wp.dot(d, d) * area[q])


declare_overloads(
    drag_kernel, points="vec3[]", anchors="vec3[]", area="scalar[]", coefficient="scalar[]", pressures="vec3[]"
)


@one_device
def eval_drag(points, anchors, area, coefficient, with_energy: bool, pressures, energy_density) -> None:
    """Launch `drag_kernel` over the quadrature points (one coefficient per world, read on the device: capturable)."""
    wp.launch(
        drag_kernel,
        dim=len(points),
        inputs=[points, anchors, area, coefficient, len(points) // len(coefficient), int(with_energy)],
        outputs=[pressures, energy_density],
        device=points.device,
    )


@wp.kernel
def lumped_drag_kernel(
    x: wp.array(dtype=Any),
    anchors: wp.array(dtype=Any),
    stiffness: wp.array(dtype=Any),
    points_per_world: int,
    with_forces: int,
    with_energy: int,
    forces: wp.array(dtype=Any),
    energy_density: wp.array(dtype=wp.float64),
):
    """forces_I −= k_I (x_I − a_I) (with `with_forces`) and, with `with_energy`, ½ k_I |x_I − a_I|² added to an entry of
    the vertex's world in the per-point energy density (its world sum is what the energy reads); k_I = ζ M_I / Δt."""
    i = wp.tid()
    d = x[i] - anchors[i]
    k = stiffness[i]
    if with_forces != 0:
        forces[i] = forces[i] - k * d
    if with_energy != 0:
        vertices = x.shape[0] // (energy_density.shape[0] // points_per_world)
        w = i // vertices
        energy_density[w * points_per_world + i - w * vertices] += wp.float64(type(k)(0.5) * k * wp.dot(d, d))


declare_overloads(lumped_drag_kernel, x="vec3[]", anchors="vec3[]", stiffness="scalar[]", forces="vec3[]")


@one_device
def eval_lumped_drag(x, anchors, stiffness, points_per_world: int, with_forces: bool, with_energy: bool, forces,
                     energy_density) -> None:
    """forces −= k (x − a) (`with_forces`); ½ k |x − a|² into `energy_density` (`with_energy`); each array given either
    way (one left alone). Capturable."""
    wp.launch(
        lumped_drag_kernel,
        dim=len(x),
        inputs=[x, anchors, stiffness, points_per_world, int(with_forces), int(with_energy)],
        outputs=[forces, energy_density],
        device=x.device,
    )
