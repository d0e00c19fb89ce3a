"""The viscous drag of one overdamped step, as an energy term of the step's minimization (docs/theory/transport.md,
"Couplings"): at each quadrature point q of the limit surface, with rest area w_q = dω̄⁰_q,

    e_q = ½ (ζ / Δt) |p_q − a_q|² w_q,

a_q the point where the step started. Minimizing E + Σ e_q is the backward-Euler step of ζ ṗ = f per unit rest area.
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
