"""Vector kernels of the nonlinear conjugate-gradient relaxation (docs/shell.md)."""

from typing import Any

import warp as wp

from . import declare_overloads


@wp.kernel
def step_kernel(x: wp.array(dtype=Any), direction: wp.array(dtype=Any), alpha: Any, out: wp.array(dtype=Any)):
    """out = x + α d."""
    i = wp.tid()
    out[i] = x[i] + alpha * direction[i]


@wp.kernel
def precondition_kernel(forces: wp.array(dtype=Any), inverse_stiffness: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    """s = P F with P the inverse of a per-vertex stiffness estimate."""
    i = wp.tid()
    out[i] = inverse_stiffness[i] * forces[i]


@wp.kernel
def direction_kernel(s: wp.array(dtype=Any), beta: Any, direction: wp.array(dtype=Any)):
    """d = s + β d."""
    i = wp.tid()
    direction[i] = s[i] + beta * direction[i]


@wp.kernel
def reductions_kernel(
    forces: wp.array(dtype=Any),
    s: wp.array(dtype=Any),
    s_old: wp.array(dtype=Any),
    direction: wp.array(dtype=Any),
    out: wp.array(dtype=Any),
):
    """out = [F·s, F·(s - s_old), F·d, max |F_i|] (out zeroed by the caller)."""
    i = wp.tid()
    f = forces[i]
    wp.atomic_add(out, 0, wp.dot(f, s[i]))
    wp.atomic_add(out, 1, wp.dot(f, s[i] - s_old[i]))
    wp.atomic_add(out, 2, wp.dot(f, direction[i]))
    wp.atomic_max(out, 3, wp.length(f))


@wp.kernel
def dot_kernel(a: wp.array(dtype=Any), b: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    """out[0] += Σ a_i·b_i (out zeroed by the caller)."""
    i = wp.tid()
    wp.atomic_add(out, 0, wp.dot(a[i], b[i]))


declare_overloads(step_kernel, x="vec3[]", direction="vec3[]", alpha="scalar", out="vec3[]")
declare_overloads(precondition_kernel, forces="vec3[]", inverse_stiffness="scalar[]", out="vec3[]")
declare_overloads(direction_kernel, s="vec3[]", beta="scalar", direction="vec3[]")
declare_overloads(reductions_kernel, forces="vec3[]", s="vec3[]", s_old="vec3[]", direction="vec3[]", out="scalar[]")
declare_overloads(dot_kernel, a="vec3[]", b="vec3[]", out="scalar[]")
