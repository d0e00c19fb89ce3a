"""Warp kernels and @wp.func helpers of wavewarp (installed as `wavewarp.kernels`)."""

import functools
import inspect

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


def _devices(value, found: list) -> None:
    """Append the devices of `value`: a Warp array's, each of a list's or tuple's, an object's `device`."""
    if isinstance(value, wp.array):
        found.append(value.device)
    elif isinstance(value, (list, tuple)):
        for item in value:
            _devices(item, found)
    else:
        device = getattr(value, "device", None)
        if hasattr(device, "is_cuda"):
            found.append(device)


def check_one_device(where: str, **named) -> None:
    """ValueError, in one line, unless the Warp arrays (and objects with a device) among `named` lie on one
    device: Warp launches across devices without a check, and such a launch crashes the process or poisons
    the CUDA context for every later launch."""
    places = {}
    for name, value in named.items():
        found = []
        _devices(value, found)
        for device in found:
            places.setdefault(device.alias, name)
    if len(places) > 1:
        listed = "; ".join(f"{name} on {alias}" for alias, name in places.items())
        raise ValueError(f"{where}: its arrays lie on different devices ({listed}): build them all on one device "
                         "(device=...), or copy them there (wp.clone(array, device=...))")


def one_device(launcher):
    """Decorator of a launcher: a call whose arrays lie on different devices is refused (`check_one_device`, the
    arguments named) before anything is launched. Called from the host as the launches are recorded: inside a
    captured graph the check costs nothing at replay."""
    signature = inspect.signature(launcher)

    @functools.wraps(launcher)
    def checked(*args, **kwargs):
        found = []
        _devices(args, found)
        _devices(tuple(kwargs.values()), found)
        if found and any(device is not found[0] for device in found):
            check_one_device(launcher.__name__, **signature.bind(*args, **kwargs).arguments)
        return launcher(*args, **kwargs)

    return checked


def one_device_methods(*names):
    """Class decorator: `one_device` on the methods `names` of a class whose instances have a `device` (theirs
    counts with the arrays passed)."""
    def decorate(cls):
        for name in names:
            setattr(cls, name, one_device(getattr(cls, name)))
        return cls

    return decorate
