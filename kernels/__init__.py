"""Warp kernels and @wp.func helpers of wavewarp (installed as `wavewarp.kernels`)."""

import functools

import warp as wp

SCALARS = (wp.float32, wp.float64)
BUILT_ON_DEMAND = ("regular", "staged")  # modules whose kernels are made when first asked for (per rule, per tile shape)


def _element(role: str, scalar):
    return {
        "scalar": scalar,
        "vec3": wp.types.vector(3, scalar),
        "vec6": wp.types.vector(6, scalar),
        "mat22": wp.types.matrix((2, 2), scalar),
        "mat33": wp.types.matrix((3, 3), scalar),
    }[role]


def scalar_of(array: wp.array):
    """The scalar type of an array's elements (float32 or float64, of scalars, vectors or matrices)."""
    return getattr(array.dtype, "_wp_scalar_type_", array.dtype)


def declare_overloads(kernel, **roles):
    """Register a generic kernel's float32 and float64 overloads up front.

    `roles` maps each `Any` argument to "ROLE" (a value), "ROLE[]" (1-D array) or "ROLE[,]"
    (2-D array), ROLE one of scalar, vec3, vec6, mat22, mat33. With every overload known when the
    module first loads, Warp compiles each module once instead of once per new overload.
    """
    for scalar in SCALARS:
        types = {}
        for name, role in roles.items():
            base = role.rstrip("[,]")
            element = _element(base, scalar)
            if role.endswith("[,]"):
                types[name] = wp.array2d(dtype=element)
            elif role.endswith("[]"):
                types[name] = wp.array(dtype=element)
            else:
                types[name] = element
        wp.overload(kernel, types)
    return kernel


@functools.cache
def register_capped(kernel, registers: int):
    """`kernel` compiled for CUDA with at most `registers` a thread (`__maxnreg__`: what does not fit spills to
    local memory, and more warps fit on an SM), in a module of its own, with the original's overloads. The same
    code; the CPU ignores the cap."""
    capped = wp.kernel(kernel.func, module="unique", cuda_max_registers=registers)
    for overload in kernel.overloads.values():
        wp.overload(capped, dict(overload.adj.arg_types))
    return capped


def warp_modules(module) -> list:
    """The Warp modules of a Python module of kernels: its own, and those of its kernels compiled in a module of
    their own (`@wp.kernel(module="unique")`)."""
    own = {k.module.name: k.module for k in vars(module).values()
           if isinstance(k, wp.Kernel) and k.func.__module__ == module.__name__}  # fmt: skip
    return [wp.get_module(module.__name__)] + [m for name, m in own.items() if name != module.__name__]
