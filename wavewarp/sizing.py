"""The size guard: the memory a scene run needs, estimated from its level or divisions before the
mesh exists, against what the process may use (docs/theory/scenes.md, "Sizes"): the machine's available
memory, the address-space limit (ulimit -v, RLIMIT_AS) and the cgroup's (a container's) memory limit.
Also the runs whose step count, output or baked USD surface is absurd, refused with the estimate."""

from __future__ import annotations

import math
import os
import resource
import shutil

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


def _meminfo_available() -> float | None:
    try:
        with open("/proc/meminfo") as info:
            for line in info:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _address_space_left() -> float | None:
    """RLIMIT_AS less the address space this process uses (VmSize); None without a limit."""
    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/status") as status:
            used = next(float(line.split()[1]) * 1024 for line in status if line.startswith("VmSize:"))
    except (OSError, StopIteration):
        used = 0.0
    return max(0.0, limit - used)


def _read_number(path: str) -> float | None:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    return float(text) if text.isdigit() else None  # "max": no limit


def cgroup_left(root: str = "/sys/fs/cgroup", membership: str = "/proc/self/cgroup") -> float | None:
    """The memory this process's cgroup (and each cgroup above it) may still take: limit less usage, the
    smallest; None without a limit. cgroup v2 (memory.max, memory.current) and v1 (memory.limit_in_bytes,
    memory.usage_in_bytes; its "no limit" is a number near 2⁶³)."""
    try:
        with open(membership) as f:
            lines = f.read().splitlines()
    except OSError:
        return None
    left = []
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":
            base, files = root, ("memory.max", "memory.current")
        elif "memory" in controllers.split(","):
            base, files = os.path.join(root, "memory"), ("memory.limit_in_bytes", "memory.usage_in_bytes")
        else:
            continue
        parts = [part for part in path.split("/") if part]
        for depth in range(len(parts), -1, -1):
            folder = os.path.join(base, *parts[:depth])
            limit, usage = (_read_number(os.path.join(folder, name)) for name in files)
            if limit is not None and limit < 2**60:
                left.append(max(0.0, limit - (usage or 0.0)))
    return min(left) if left else None


def memory_limits() -> list:
    """[(what, bytes this process may still use)] for each limit that applies."""
    found = [("this machine's available memory", _meminfo_available()),
             ("this process's address-space limit (ulimit -v) less what it uses", _address_space_left()),
             ("the memory limit of this process's cgroup (container) less what it uses", cgroup_left())]
    return [(what, value) for what, value in found if value is not None]


def host_available() -> float | None:
    """Bytes this process can still get: the smallest of `memory_limits`; None where none is known."""
    limits = memory_limits()
    return min(value for _, value in limits) if limits else None


def binding_limit() -> str:
    """Which of `memory_limits` is the smallest (what a refusal names)."""
    limits = memory_limits()
    return min(limits, key=lambda item: item[1])[0] if limits else "this machine's available memory"


def check_run_size(name: str, value: int, generator, *, device=None) -> None:
    """Refuse a run whose mesh would not fit, before `generator` (icosphere, cube, prism) builds it:
    the parameter `name` = `value` (level, divisions) gives its triangles. The message gives the
    estimate, what is available, and the largest value that fits. On a GPU the device's free memory
    counts too."""
    triangles, step = TRIANGLES[generator], 1 if generator is icosphere else 2
    resolved = resolve_device(device)
    limits = [(binding_limit(), host_available())]
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


MAX_STEPS = 10**9  # time steps of one run: more is weeks of computing on any device


def check_steps(steps: float, dt: float, t_end: float) -> None:
    """Refuse a run of more than MAX_STEPS time steps of `dt` to `t_end`, before anything is allocated."""
    if steps > MAX_STEPS:
        raise ValueError(f"dt={dt:g} makes {steps:.3g} time steps to t_end={t_end:g}, more than {MAX_STEPS:.0e} (weeks "
                         "of computing): a larger dt, or --set dt=auto")


BYTES_PER_BAKED_TRIANGLE = 400  # building a baked surface: 350 bytes per refined triangle measured at its peak


def check_bake_size(triangles: int, levels: int) -> None:
    """Refuse `--usd-bake-levels` whose refined surface would not fit in memory, before it is built."""
    available = host_available()
    need = BYTES_PER_BAKED_TRIANGLE * triangles * 4**levels
    if available is None or need <= available:
        return
    fits = max(0, int(math.log(max(available / (BYTES_PER_BAKED_TRIANGLE * triangles), 1.0), 4)))
    raise ValueError(f"--usd-bake-levels {levels} makes {triangles * 4**levels:,} triangles and needs about "
                     f"{need / 1e9:,.1f} GB, more than {binding_limit()} ({available / 1e9:,.1f} GB): the largest "
                     f"that fits is {fits}" + ("" if fits else " (none: --usd-surface loop)"))


USD_BYTES_PER_POINT = 28  # a frame's points (3 float32), field (float32) and colour (3 float32) in the USD stage


def check_output_size(frames: int, series: dict, points: int, folder: str) -> None:
    """Refuse a run whose `frames` (the first included) of HDF5 `series` (name -> per-frame shape) and USD
    `points` would not fit on the disk of `folder`, or the USD stage (held in memory until the file is
    saved) in memory; the message gives the estimate."""
    per_frame = 8 * (1 + sum(math.prod(shape) for shape in series.values()))
    usd = frames * points * USD_BYTES_PER_POINT
    disk, memory = frames * per_frame + usd, usd + frames * points * 8  # (the run keeps each frame's c too)
    free = shutil.disk_usage(folder).free
    available = host_available()
    for need, have, where in ((disk, free, f"the {free / 1e9:,.1f} GB free in {folder}"),
                              (memory, available, f"{binding_limit()} ({(available or 0) / 1e9:,.1f} GB)")):
        if have is not None and need > have:
            raise ValueError(f"{frames:,} frames of {points:,} points take about {need / 1e9:,.1f} GB, more than "
                             f"{where}: fewer frames (--set frames=N)")
