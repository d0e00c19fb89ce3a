"""CUDA kernels compiled ahead of time into a kernel cache (wavewarp/precompile.py), on this CPU-only machine:
each cubin lands where Warp's loader looks for it on an sm_90 GPU — the cache folder named by the module's content
hash for the launch's block size — so a GPU machine given the cache loads instead of compiling."""

import os
import subprocess
import sys

import pytest
import warp as wp

from wavewarp.cli import main
from wavewarp.kernels import reduce as kernels_reduce
from wavewarp.kernels.shell import FORCE_BLOCK, shell_forces_kernel


def expected_cubin(cache, module, block_dim=None) -> str:
    """Where Warp looks for `module`'s sm_90 cubin in a cache (WARP_CACHE_PATH = `cache`) at a launch of `block_dim`
    threads a block (None: the module's default)."""
    name = module.get_module_identifier(block_dim=block_dim)
    return os.path.join(cache, wp.config.version, name, f"{name}.sm90.cubin")


def run_precompile(cache, code):
    environment = dict(os.environ, WARP_CACHE_PATH=str(cache))
    subprocess.run([sys.executable, "-c", code], check=True, env=environment, capture_output=True)


def test_a_precompiled_module_lands_where_the_loader_looks(tmp_path):
    run_precompile(tmp_path, "from wavewarp.kernels import reduce\nfrom wavewarp.precompile import precompile\n"
                             "precompile([90], [reduce])")  # fmt: skip
    assert os.path.isfile(expected_cubin(tmp_path, wp.get_module(kernels_reduce.__name__)))


@pytest.mark.slow
def test_the_force_kernel_is_precompiled_for_its_own_launch(tmp_path):
    """The force kernel compiles alone, for its 64-thread launch (not the module default of 256 threads)."""
    run_precompile(tmp_path, "from wavewarp.kernels import shell\nfrom wavewarp.precompile import precompile\n"
                             "precompile([90], [shell])")  # fmt: skip
    assert os.path.isfile(expected_cubin(tmp_path, shell_forces_kernel.module, FORCE_BLOCK))
    assert os.path.isfile(expected_cubin(tmp_path, wp.get_module("wavewarp.kernels.shell")))


def test_precompile_refuses_an_architecture_given_as_a_name(capsys):
    assert main(["precompile", "--arch", "9"]) == 2
    assert "give compute capabilities × 10" in capsys.readouterr().err
