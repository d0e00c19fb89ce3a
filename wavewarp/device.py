"""Device and dtype choices shared by every computing class (docs/theory/scenes.md)."""

from __future__ import annotations

import importlib
import os
import pkgutil
import platform
import sys
import tempfile

import numpy as np
import warp as wp

from . import kernels
from .kernels import warp_modules
from .kernels.reduce import REDUCTION_BLOCK, whole_blocks, world_sum_kernel

DTYPES = {"float32": wp.float32, "float64": wp.float64}
# atomic updates one thread may record in deterministic mode, per kernel module: a patch scatters 18
# values per target; assembling K or M a patch's 18 × 18 pairs, the Newton Hessian's blocks per point
DETERMINISTIC_RECORDS = {"default": 64, "laplace": 1024, "newton": 4096}


NO_CUDA_DRIVER = "Could not find or load the NVIDIA CUDA driver"


def init_warp() -> None:
    """Initialise Warp once, without its native warning on machines with no CUDA driver: a CPU
    run does not need one, and asking for CUDA there gets resolve_device's error instead."""
    if getattr(init_warp, "done", False):
        return
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        printed = captured.read().decode(errors="replace").splitlines()
    kept = [line for line in printed if NO_CUDA_DRIVER not in line]
    if kept:
        print("\n".join(kept), file=sys.stderr)
    init_warp.done = True


def set_deterministic(on: bool) -> None:
    """Bit-exact repeated runs on a GPU (a CPU run is deterministic either way), for what is built
    after the call: the shell's forces and the Laplace–Beltrami actions gather in a fixed order,
    block reductions run in one block, and, where CUDA is present, the remaining atomics use Warp's
    run-to-run deterministic mode (every kernel module of wavewarp and every module created later;
    without CUDA the modules keep their options: the CPU's atomics are ordered already, and the
    modules need not be compiled a second time)."""
    mode = wp.DeterministicMode.RUN_TO_RUN if on else wp.DeterministicMode.NOT_GUARANTEED
    wp.config.deterministic, wp.config.deterministic_max_records = mode, DETERMINISTIC_RECORDS["default"] if on else 0
    init_warp()
    if not wp.is_cuda_available():
        return
    for info in pkgutil.iter_modules(kernels.__path__):
        records = DETERMINISTIC_RECORDS.get(info.name, DETERMINISTIC_RECORDS["default"]) if on else 0
        for compiled in warp_modules(importlib.import_module(f"{kernels.__name__}.{info.name}")):
            wp.set_module_options({"deterministic": mode, "deterministic_max_records": records}, module=compiled)


def deterministic_default(deterministic=None) -> bool:
    """`deterministic` as given, or (None) whether `set_deterministic(True)` is in force: what the
    computing classes choose their fixed-order gathers and single-block reductions by."""
    if deterministic is None:
        return wp.config.deterministic != wp.DeterministicMode.NOT_GUARANTEED
    return bool(deterministic)


def resolve_device(device=None) -> wp.context.Device:
    """Warp device for "cpu", "cuda", "cuda:N"; None picks CUDA when present, else the CPU."""
    init_warp()
    if device is None:
        return wp.get_device("cuda:0" if wp.is_cuda_available() else "cpu")
    available = ", ".join(d.alias for d in wp.get_devices())
    if str(device).startswith("cuda") and not wp.is_cuda_available():
        raise ValueError(f"device {device!r} is not available: no NVIDIA CUDA driver or GPU was found on this "
                         f"machine; available: {available}")  # fmt: skip
    try:
        return wp.get_device(device)
    except (RuntimeError, ValueError) as error:
        raise ValueError(f"device {device!r} is not available ({error}); available: {available}") from None


def device_tag(device) -> str:
    """The device's alias as a file-name part: "cpu", "cuda0"."""
    return device.alias.replace(":", "")


def describe_device(device) -> dict:
    """What a benchmark result records of the machine it ran on."""
    return {"device": device.alias, "device_name": device.name, "host": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "warp": wp.config.version}  # fmt: skip


def resolve_dtype(dtype="float32"):
    """Warp scalar type for "float32" / "float64" (NumPy and Warp float types accepted too)."""
    if dtype in (wp.float32, wp.float64):
        return dtype
    try:
        name = np.dtype(dtype).name
    except TypeError:
        name = str(dtype)
    if name not in DTYPES:
        raise ValueError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    return DTYPES[name]


def numpy_dtype(scalar) -> np.dtype:
    return np.dtype(np.float32 if scalar == wp.float32 else np.float64)


def vec3(scalar):
    return wp.types.vector(3, scalar)


def vec6(scalar):
    return wp.types.vector(6, scalar)


def mat22(scalar):
    return wp.types.matrix((2, 2), scalar)


def reduction_threads(n: int, deterministic=None) -> int:
    """Threads of a block-reduction launch over n items, each thread taking items t, t + threads, ...:
    whole blocks of REDUCTION_BLOCK, one item a thread; deterministic, one block (its shared-memory
    sum has a fixed order; the atomics that join several blocks' sums do not)."""
    if deterministic_default(deterministic):
        return int(REDUCTION_BLOCK)
    return whole_blocks(n)


def world_sums(values: wp.array, total: wp.array, worlds: int = 1, deterministic=None) -> None:
    """total[w] = Σ of world w's share of `values` (`worlds` equal blocks; total[0] = Σ values where
    total holds one entry), on the values' device: a block reduction per world (capturable in a
    CUDA graph), one block per world when deterministic."""
    total.zero_()
    threads = reduction_threads(len(values) // worlds, deterministic)
    wp.launch(world_sum_kernel, dim=threads * worlds, inputs=[values, worlds, threads], outputs=[total],
              block_dim=REDUCTION_BLOCK, device=values.device)  # fmt: skip


def run_steps(step, steps: int, *, device, graphs: dict, modules, capture: bool, graph_steps: int | None = None) -> None:
    """Call `step()` `steps` times on `device`; with `capture`, as graphs of at most `graph_steps` steps
    (None: one graph of all), each cached in `graphs` by its step count and launched as often as it
    fits (`modules`: every kernel module a step launches, loaded first). A graph keeps the launch
    arguments it was captured with: whoever changes them clears `graphs`."""
    with wp.ScopedDevice(device):
        if not capture:
            for _ in range(steps):
                step()
            return
        for length, repeats in graph_launches(steps, graph_steps):
            graph = graphs.get(length)
            if graph is None:
                for module in modules:  # with its kernels compiled alone, each for its own default launch
                    for compiled in warp_modules(module):
                        wp.load_module(compiled, device=device)
                with wp.ScopedCapture(device=device, force_module_load=False) as scope:
                    for _ in range(length):
                        step()
                graph = graphs[length] = scope.graph
            for _ in range(repeats):
                wp.capture_launch(graph)


def graph_launches(steps: int, graph_steps: int | None) -> list:
    """[(steps per graph, launches)] that make `steps` from graphs of at most `graph_steps` steps."""
    size = steps if graph_steps is None else min(steps, graph_steps)
    full, rest = divmod(steps, size) if size else (0, 0)
    return [(length, repeats) for length, repeats in ((size, full), (rest, 1)) if length and repeats]
