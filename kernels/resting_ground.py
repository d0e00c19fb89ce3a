"""A shell resting on the ground as energy terms of a relaxation (docs/theory/dynamics.md, "The quasi-static
limit"): at each quadrature point q of the limit surface, with rest area w_q = dω̄⁰_q,

    e_q = w_q [ k |z_q|³/3 (z_q < 0) − ρ g·p_q + μ N_q (√(|P_t(p_q − a_q)|² + ε²) − ε) ],

the area ground's penalty (its pressure k z²), gravity, and the incremental Coulomb friction of one load step:
a_q the point's anchor (where the last equilibrium left it) and N_q its pressure there, held fixed during the step.
"""

from typing import Any

import warp as wp

from . import declare_overloads


@wp.kernel
def resting_ground_kernel(
    points: wp.array(dtype=Any), area: wp.array(dtype=Any), anchors: wp.array(dtype=Any), loads: wp.array(dtype=Any),
    stiffness: Any, friction: Any, smoothing: Any, density: Any, gravity: Any, height: Any, with_energy: int,
    pressures: wp.array(dtype=Any), energy_density: wp.array(dtype=wp.float64),
):  # fmt: skip
    """pressures_q = −∂e_q/∂p_q / w_q (the force per rest area) and, with `with_energy`, energy_density_q += e_q."""
    q = wp.tid()
    p = points[q]
    zero = smoothing - smoothing
    z = p[2] - height
    depth = wp.max(-z, zero)
    d = p - anchors[q]
    slip = wp.sqrt(d[0] * d[0] + d[1] * d[1] + smoothing * smoothing)
    pull = friction * loads[q] / slip
    pressures[q] = density * gravity + type(p)(-pull * d[0], -pull * d[1], stiffness * depth * depth)
    if with_energy != 0:
        third = type(smoothing)(1.0 / 3.0)
        e = stiffness * depth * depth * depth * third - density * wp.dot(gravity, p) + friction * loads[q] * (slip - smoothing)
        energy_density[q] += wp.float64(e * area[q])


@wp.kernel
def ground_pressure_kernel(
    points: wp.array(dtype=Any), stiffness: Any, height: Any, loads: wp.array(dtype=Any), anchors: wp.array(dtype=Any),
):  # fmt: skip
    """A load step's start: each point's anchor (where it is) and its pressure there, k z² below the ground."""
    q = wp.tid()
    p = points[q]
    depth = wp.max(height - p[2], stiffness - stiffness)
    loads[q] = stiffness * depth * depth
    anchors[q] = p


declare_overloads(resting_ground_kernel, points="vec3[]", area="scalar[]", anchors="vec3[]", loads="scalar[]",
                  stiffness="scalar", friction="scalar", smoothing="scalar", density="scalar", gravity="vec3",
                  height="scalar", pressures="vec3[]")  # fmt: skip
declare_overloads(ground_pressure_kernel, points="vec3[]", stiffness="scalar", height="scalar", loads="scalar[]",
                  anchors="vec3[]")  # fmt: skip
