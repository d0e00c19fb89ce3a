"""Koiter shell forces on regular patches, their basis compiled in
(docs/theory/geometry.md#regular-patches-compiled-in).

A triangle whose three corners have valence 6 has a 12-vertex patch whose basis values at the quadrature
points are the same for every such triangle (patch type 0), so they need not be read from a table: the
kernel for one rule and dtype carries them as literals (`wp.static` over the unrolled loops), sums exactly
12 entries with no bound checks, and keeps 12 force rows instead of the general kernel's 18. Every
triangle of an icosphere but those around its 12 valence-5 vertices is regular; the others go through
`shell_forces_kernel`. One kernel per (basis, weights, scalar, hold_positions, vector_atomics), made on first use.

With vector_atomics (float32) each patch vertex's force is one 16-byte reduction (sm_90's
`red.global.v4.f32.add`) into a vec4 accumulator instead of three scalar atomics into the vec3 forces:
a third of the L2 atomic operations, each within one aligned sector. `fold_padded_forces_kernel` then
adds the accumulator into the forces and clears it. Below sm_90 and on the CPU the same accumulator
takes three scalar adds.

`regular_volume_kernel` sums the volume moments the same way: one triangle an item, a regular one from its
12 positions read once with the basis as literals.
"""

import functools

import warp as wp

from .limit_surface import point_volume_moments
from .reduce import block_add
from .shell import FORCE_BLOCK, VolumeMoments, jet_strains, strains_gradient_jet, world_volume_terms

REGULAR_PATCH = 12  # control vertices of a regular patch


@wp.func_native("""
#if defined(__CUDA_ARCH__) && (__CUDA_ARCH__ >= 900)
asm volatile("red.global.v4.f32.add [%0], {%1, %2, %3, %4};"
             :: "l"(forces.data + i), "f"(f[0]), "f"(f[1]), "f"(f[2]), "f"(0.0f) : "memory");
#else
wp::atomic_add(&forces.data[i].c[0], f[0]);
wp::atomic_add(&forces.data[i].c[1], f[1]);
wp::atomic_add(&forces.data[i].c[2], f[2]);
#endif
""")
def add_padded_force(forces: wp.array(dtype=wp.vec4f), i: int, f: wp.vec3f):
    """forces[i].xyz += f atomically: one 16-byte vector reduction on sm_90 and later, three scalar adds before."""
    ...


@wp.kernel(enable_backward=False)
def fold_padded_forces_kernel(padded: wp.array(dtype=wp.vec4f), forces: wp.array(dtype=wp.vec3f)):
    """forces[i] += padded[i].xyz, and padded[i] cleared for the next evaluation."""
    i = wp.tid()
    f = padded[i]
    forces[i] = forces[i] + wp.vec3f(f[0], f[1], f[2])
    padded[i] = wp.vec4f()


@functools.cache
def regular_forces_kernel(basis: tuple, weights: tuple, scalar, hold_positions: bool = False,
                          vector_atomics: bool = False):
    """The force kernel of regular triangles for a rule whose regular-patch basis is `basis` (P rows of 12
    entries [N, N,1, N,2, N,11, N,12, N,22], the rows of patch type 0) with quadrature `weights` (P), in
    `scalar` (wp.float32 or wp.float64). hold_positions: load the 12 relative positions once a triangle and
    keep them (36 more registers) instead of reading them again at every point. vector_atomics (float32 only):
    add the forces into a vec4 accumulator with `add_padded_force` (then `fold_padded_forces_kernel`). Launch
    over the regular triangles' list."""
    if vector_atomics and scalar != wp.float32:
        raise ValueError("vector atomics add float32 forces (sm_90's red.global.v4.f32.add): float64 has none")
    vec3, mat22 = wp.types.vector(3, scalar), wp.types.matrix((2, 2), scalar)
    out = wp.vec4f if vector_atomics else vec3  # the forces' element: the padded accumulator's with vector_atomics
    points = len(weights)

    @wp.kernel(module="unique", enable_backward=False)  # forces only: no adjoint to compile
    def regular_shell_forces(
        x: wp.array(dtype=vec3),
        patch_start: wp.array(dtype=wp.int32),
        patch_vertices: wp.array(dtype=wp.int32),
        regular: wp.array(dtype=wp.int32),
        ref_metric: wp.array(dtype=mat22),
        ref_metric_inv: wp.array(dtype=mat22),
        ref_curvature: wp.array(dtype=mat22),
        ref_weight: wp.array(dtype=scalar),
        stretching_modulus: wp.array(dtype=scalar),
        bending_modulus: wp.array(dtype=scalar),
        nu: scalar,
        worlds: int,
        moments: wp.array(dtype=VolumeMoments),
        target: wp.array(dtype=wp.float64),
        penalty: wp.array(dtype=wp.float64),
        with_energy: int,
        energy_density: wp.array(dtype=wp.float64),
        forces: wp.array(dtype=out),
    ):
        """`shell_forces_kernel` for triangle regular[i]: its points' energy densities (`with_energy`) and
        the forces -∂(E_S + E_B + E_V)/∂x on its 12 patch vertices, one atomic add each."""
        t = regular[wp.tid()]
        start = patch_start[t]
        w = t // ((patch_start.shape[0] - 1) // worlds)
        centroid, pressure = world_volume_terms(x, moments, target, penalty, worlds, w)
        stretching, bending = stretching_modulus[w], bending_modulus[w]
        origin = x[patch_vertices[start]]
        held = wp.matrix(shape=(REGULAR_PATCH, 3), dtype=scalar)  # relative positions, with hold_positions
        if wp.static(hold_positions):
            for k in range(1, REGULAR_PATCH):
                v = x[patch_vertices[start + k]] - origin
                for c in range(3):
                    held[k, c] = v[c]
        accumulated = wp.matrix(shape=(REGULAR_PATCH, 3), dtype=scalar)  # one row per patch vertex
        for point in range(wp.static(points)):
            q = t * wp.static(points) + point
            # the limit surface's jet at the point, relative to the first vertex (see `patch_jet`)
            p, x1, x2, x11, x12, x22 = vec3(), vec3(), vec3(), vec3(), vec3(), vec3()
            for k in range(1, REGULAR_PATCH):
                v = vec3()
                if wp.static(hold_positions):
                    v = vec3(held[k, 0], held[k, 1], held[k, 2])
                else:
                    v = x[patch_vertices[start + k]] - origin
                p += wp.static(scalar(basis[point][k][0])) * v
                x1 += wp.static(scalar(basis[point][k][1])) * v
                x2 += wp.static(scalar(basis[point][k][2])) * v
                x11 += wp.static(scalar(basis[point][k][3])) * v
                x12 += wp.static(scalar(basis[point][k][4])) * v
                x22 += wp.static(scalar(basis[point][k][5])) * v
            inv = ref_metric_inv[q]
            membrane, bend, n, j = jet_strains(x1, x2, x11, x12, x22, inv, ref_metric[q], ref_curvature[q])
            g, g1, g2, g11, g12, g22 = strains_gradient_jet(
                membrane, bend, inv, p + origin, x1, x2, x11, x12, x22, n, j, q, ref_weight[q], stretching, bending,
                nu, wp.static(scalar(weights[point])), centroid, pressure, with_energy, energy_density,
            )  # fmt: skip
            for k in range(REGULAR_PATCH):
                f = wp.static(scalar(basis[point][k][0])) * g + wp.static(scalar(basis[point][k][1])) * g1
                f += wp.static(scalar(basis[point][k][2])) * g2 + wp.static(scalar(basis[point][k][3])) * g11
                f += wp.static(scalar(basis[point][k][4])) * g12 + wp.static(scalar(basis[point][k][5])) * g22
                for c in range(3):
                    accumulated[k, c] = accumulated[k, c] - f[c]
        for k in range(REGULAR_PATCH):
            f = vec3(accumulated[k, 0], accumulated[k, 1], accumulated[k, 2])
            if wp.static(vector_atomics):
                add_padded_force(forces, patch_vertices[start + k], f)
            else:
                wp.atomic_add(forces, patch_vertices[start + k], f)

    wp.set_module_options({"block_dim": FORCE_BLOCK}, regular_shell_forces.module)  # compiled for the force launch
    return regular_shell_forces


@functools.cache
def regular_volume_kernel(basis: tuple, weights: tuple, scalar):
    """`volume_kernel` with one triangle an item: a regular triangle's points from its 12 positions read once and
    the basis as literals (`regular_forces_kernel`'s), any other triangle's through the basis table. The same
    launch and moments: `threads` per world (whole blocks) over max(triangles, vertices) items a world."""
    vec3 = wp.types.vector(3, scalar)
    points = len(weights)
    third_weights = [float(wp.dtype_to_numpy(scalar)(w)) / 3.0 for w in weights]  # w as the table holds it

    @wp.kernel(module="unique", enable_backward=False)  # the differentiable sum is `volume_terms_kernel`'s
    def regular_volume(
        x: wp.array(dtype=vec3),
        patch_start: wp.array(dtype=wp.int32),
        patch_vertices: wp.array(dtype=wp.int32),
        triangle_type: wp.array(dtype=wp.int32),
        basis_table: wp.array2d(dtype=wp.types.vector(6, scalar)),
        weights_table: wp.array(dtype=scalar),
        points_per_triangle: int,
        worlds: int,
        items: int,
        threads: int,
        moments: wp.array(dtype=VolumeMoments),
    ):
        """moments[w] += world w's [S, V₀, Σx] (`volume_kernel`), item i its triangle i and its vertex i."""
        w = wp.tid() // threads
        triangles = triangle_type.shape[0] // worlds
        vertices = x.shape[0] // worlds
        area_normal = wp.vec3d()
        moment = wp.float64(0.0)
        xi = wp.vec3d()
        for i in range(wp.tid() - w * threads, items, threads):
            t = w * triangles + i
            regular = False
            if i < triangles:
                regular = triangle_type[t] == 0
            if regular:
                start = patch_start[t]
                origin = x[patch_vertices[start]]
                held = wp.matrix(shape=(REGULAR_PATCH, 3), dtype=scalar)
                for k in range(1, REGULAR_PATCH):
                    v = x[patch_vertices[start + k]] - origin
                    for c in range(3):
                        held[k, c] = v[c]
                for point in range(wp.static(points)):
                    p, x1, x2 = vec3(), vec3(), vec3()
                    for k in range(1, REGULAR_PATCH):
                        v = vec3(held[k, 0], held[k, 1], held[k, 2])
                        p += wp.static(scalar(basis[point][k][0])) * v
                        x1 += wp.static(scalar(basis[point][k][1])) * v
                        x2 += wp.static(scalar(basis[point][k][2])) * v
                    a = wp.vec3d(wp.cross(x1, x2)) * wp.static(wp.float64(third_weights[point]))
                    area_normal += a
                    moment += wp.dot(wp.vec3d(p + origin), a)
            elif i < triangles:  # a patch of another valence: the table
                for point in range(points_per_triangle):
                    a, m = point_volume_moments(x, patch_start, patch_vertices, triangle_type, basis_table,
                                                weights_table, points_per_triangle, t * points_per_triangle + point)
                    area_normal += a
                    moment += m
            if i < vertices:
                xi += wp.vec3d(x[w * vertices + i])
        total = VolumeMoments(area_normal[0], area_normal[1], area_normal[2], moment, xi[0], xi[1], xi[2])
        block_add(moments, w, total)

    return regular_volume
