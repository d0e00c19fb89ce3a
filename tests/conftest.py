"""Shared fixtures: every kernel test runs on the CPU and, where CUDA is present, on cuda:0. Under
pytest-xdist the controller first compiles wavewarp's kernel modules for the CPU, split over two
processes, so that the workers find them in the kernel cache instead of each compiling all of them."""

import os
import pkgutil
import subprocess
import sys

import numpy as np
import pytest
import warp as wp

from wavewarp import kernels
from wavewarp.device import init_warp

wp.config.log_level = wp.LOG_WARNING
init_warp()

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])


@pytest.fixture(params=DEVICES)
def device(request):
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(int(os.environ.get("WAVEWARP_TEST_SEED", "20261123")))


COMPILE_GROUPS = (("contact", "laplace", "newton", "reduce"),
                  ("shell", "relax", "waves", "dynamics", "limit_surface", "self_contact"))  # about 25 s and 32 s;
# a kernel module named in neither is compiled with the first group (those built on demand compile on first use)


def pytest_sessionstart(session):
    """Before xdist starts its workers (its own hook runs last): the kernel modules, compiled once."""
    if hasattr(session.config, "workerinput") or not session.config.pluginmanager.hasplugin("xdist"):
        return
    if not getattr(session.config.option, "numprocesses", None):
        return
    compile_one = ("import sys, warp as wp, importlib; from wavewarp.device import init_warp; init_warp(); "
                   "[wp.load_module(importlib.import_module('wavewarp.kernels.' + name), device='cpu') "
                   "for name in sys.argv[1:]]")  # fmt: skip
    named = {name for group in COMPILE_GROUPS for name in group}
    others = tuple(m.name for m in pkgutil.iter_modules(kernels.__path__)
                   if m.name not in named and m.name not in kernels.BUILT_ON_DEMAND)  # fmt: skip
    groups = (COMPILE_GROUPS[0] + others, *COMPILE_GROUPS[1:])
    jobs = [subprocess.Popen([sys.executable, "-c", compile_one, *group], stdout=subprocess.DEVNULL) for group in groups]
    for job in jobs:
        job.wait()
