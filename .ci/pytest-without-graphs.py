"""pytest with wavewarp's CUDA graph capture off: every step launched one by one (`wavewarp.device.run_steps`).

compute-sanitizer cannot follow the conditional graphs of `wp.capture_while` (the relaxation's and the implicit
solves' device-side loops): under memcheck and racecheck a captured loop reports an illegal address and poisons the
CUDA context, while the same kernels launched one by one are clean (NVIDIA/warp#1406). `.ci/gpu-check` runs the
sanitizers through this file so that they see every kernel; the suite itself runs with the graphs.
Usage: python .ci/pytest-without-graphs.py PYTEST-ARGUMENTS...
"""

import sys

import pytest
import wavewarp.device

captured = wavewarp.device.run_steps


def run_steps(step, steps, *, capture, **options):
    return captured(step, steps, capture=False, **options)


for module in list(sys.modules.values()):  # the modules imported with the package hold their own name for it
    if getattr(module, "run_steps", None) is captured:
        module.run_steps = run_steps
sys.exit(pytest.main(sys.argv[1:]))
