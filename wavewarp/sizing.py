"""The size guard: the memory a scene run needs, estimated from its level or divisions before the
mesh exists, against what the machine has (docs/theory/scenes.md, "Sizes")."""

from __future__ import annotations

from .device import resolve_device
from .mesh import cube, icosphere, prism

BASE_BYTES = 400e6  # the interpreter with Warp, NumPy, matplotlib and USD loaded, a level-3 run
BYTES_PER_TRIANGLE = 8192  # about twice the steepest growth measured (cube-waves: 3.8 KB per triangle)


def icosphere_triangles(level: int) -> int:
    return 20 * 4 ** int(level)


def cube_triangles(divisions: int) -> int:
    return 12 * int(divisions) ** 2


def prism_triangles(divisions: int) -> int:
    return 8 * int(divisions) ** 2


TRIANGLES = {icosphere: icosphere_triangles, cube: cube_triangles, prism: prism_triangles}


def run_bytes(triangles: int) -> float:
    """Host memory (bytes) a scene run of `triangles` control triangles needs: an upper estimate."""
    return BASE_BYTES + BYTES_PER_TRIANGLE * triangles


def host_available() -> float | None:
    """Bytes the host can still give (MemAvailable of /proc/meminfo); None where unknown."""
    try:
        with open("/proc/meminfo") as info:
            for line in info:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_run_size(name: str, value: int, generator, *, device=None) -> None:
    """Refuse a run whose mesh would not fit, before `generator` (icosphere, cube, prism) builds it:
    the parameter `name` = `value` (level, divisions) gives its triangles. The message gives the
    estimate, what is available, and the largest value that fits. On a GPU the device's free memory
    counts too."""
    triangles, step = TRIANGLES[generator], 1 if generator is icosphere else 2
    resolved = resolve_device(device)
    limits = [("this machine's available memory", host_available())]
    if resolved.is_cuda:
        limits.append((f"the free memory of {resolved.alias}", float(resolved.free_memory)))
    for where, available in limits:
        if available is None or run_bytes(triangles(value)) <= available:
            continue
        fits = value
        while fits - step >= 0 and run_bytes(triangles(fits)) > available:
            fits -= step
        largest = (f"the largest {name} that fits is {fits} ({triangles(fits):,} triangles)"
                   if run_bytes(triangles(fits)) <= available else f"no {name} fits")  # fmt: skip
        raise ValueError(f"{name}={value} makes {triangles(value):,} triangles and needs about "
                         f"{run_bytes(triangles(value)) / 1e9:,.1f} GB, more than {where} "
                         f"({available / 1e9:,.1f} GB): {largest}")  # fmt: skip
