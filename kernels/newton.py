"""Kernels of the sparse Hessian by coloured central differences (docs/theory/shell.md#newton-finish).

Vertices of one colour share no force row (no triangle patch holds two of them and a third
vertex's patch neighbourhood meets at most one), so one pair of force evaluations per colour and
axis fills one column of every 3×3 block whose column vertex has that colour.
"""

import warp as wp


@wp.kernel
def perturb_kernel(x: wp.array(dtype=wp.vec3d), colour: wp.array(dtype=wp.int32), k: int, axis: int,
                   step: wp.float64, out: wp.array(dtype=wp.vec3d)):  # fmt: skip
    """out = x + step e_axis on the vertices of colour k, x elsewhere."""
    i = wp.tid()
    p = x[i]
    if colour[i] == k:
        p[axis] = p[axis] + step
    out[i] = p


@wp.kernel
def hessian_columns_kernel(
    forces_plus: wp.array(dtype=wp.vec3d),
    forces_minus: wp.array(dtype=wp.vec3d),
    block_row: wp.array(dtype=wp.int32),
    block_column: wp.array(dtype=wp.int32),
    colour: wp.array(dtype=wp.int32),
    k: int,
    axis: int,
    step: wp.float64,
    volume_gradient: wp.array(dtype=wp.vec3d),
    volume_coupling: wp.float64,
    blocks: wp.array3d(dtype=wp.float64),
):
    """Column `axis` of the blocks (J, I) with colour[I] = k: H_JI e_axis = -(F⁺_J − F⁻_J) / 2 step,
    less the volume term's rank-one share 2μV g_J Σ_{colour k} g_axis (`volume_coupling`), which
    reaches every row and is added back exactly by the solver."""
    b = wp.tid()
    if colour[block_column[b]] != k:
        return
    j = block_row[b]
    column = (forces_minus[j] - forces_plus[j]) / (wp.float64(2.0) * step) - volume_coupling * volume_gradient[j]
    for e in range(3):
        blocks[b, e, axis] = column[e]
