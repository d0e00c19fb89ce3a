"""CUDA kernels compiled ahead of time into Warp's kernel cache, on any machine (NVRTC; no GPU needed).

A fresh GPU machine otherwise compiles every kernel module a run launches before its first step (about two
minutes for a walker and its gradient on an H200), and every worker of a sweep with its own cache does the same.
`precompile([90])` writes each module's sm_90 code where Warp's loader looks for it (`WARP_CACHE_PATH`), for the
launch configurations the code uses: the module default of 256 threads a block, and the force kernel's own
(`kernels.shell.FORCE_BLOCK`). The regular-patch force kernels that large float32 shells launch (Shell's
regular_patches="auto": "vector" on sm_90 and later, "held" before), made per rule, are compiled for the rules the
scenes use (`RULES`), with the vector atomics' fold and the same shells' volume-moment kernel. Copied or shared with
the GPU machines, the cache turns their compiles into loads.
"""

from __future__ import annotations

import importlib
import pkgutil

import warp as wp

from . import kernels
from .kernels import warp_modules
from .kernels.regular import fold_padded_forces_kernel, regular_forces_kernel, regular_volume_kernel
from .patches import regular_patch_basis

RULES = ("3", "3x4")  # the scenes' quadrature rules (walkers and quick runs "3"; cube and prism wave guides "3x4")


def kernel_modules() -> list:
    """The Python modules of `wavewarp.kernels` that build their kernels when imported (not those built on demand)."""
    return [importlib.import_module(f"{kernels.__name__}.{m.name}") for m in pkgutil.iter_modules(kernels.__path__)
            if m.name not in kernels.BUILT_ON_DEMAND]  # fmt: skip


def precompile(archs, modules=None, report=print) -> list:
    """Compile every Warp module of `modules` (Python modules of `wavewarp.kernels`; default all) for each CUDA
    architecture in `archs` (compute capability × 10) as cubins into the kernel cache; the artifacts' paths."""
    wp.init()
    paths = []
    for module in kernel_modules() if modules is None else modules:
        for compiled in warp_modules(module):
            paths += wp.compile_aot_module(compiled, arch=list(archs), use_ptx=False)
            report(f"{compiled.name}: sm_{', sm_'.join(map(str, archs))}")
    if modules is None:
        for kernel in regular_kernels() + [fold_padded_forces_kernel]:
            paths += wp.compile_aot_module(kernel.module, arch=list(archs), use_ptx=False)
            report(f"{kernel.module.name}: sm_{', sm_'.join(map(str, archs))}")
    return paths


def regular_kernels(rules=RULES) -> list:
    """The regular-patch kernels a Shell of these rules launches by default (float32): forces holding positions, with
    vector atomics and without, and the volume moments."""
    return [kernel for rule in rules for kernel in (
        regular_forces_kernel(*regular_patch_basis(rule), wp.float32, True, True),
        regular_forces_kernel(*regular_patch_basis(rule), wp.float32, True, False),
        regular_volume_kernel(*regular_patch_basis(rule), wp.float32))]  # fmt: skip
