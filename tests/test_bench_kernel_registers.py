"""Registers per thread read from a cubin Warp compiled ahead of time (benchmarks/kernel_registers.py)."""

import os
import sys

import pytest
import warp as wp

from wavewarp.benchmarks.kernel_registers import cubin_registers, kernel_dtypes, occupancy
from wavewarp.kernels import register_capped

MODULE = '''
import warp as wp

@wp.kernel
def copy_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = a[i]

@wp.kernel
def many_live_values_kernel(a: wp.array(dtype=wp.float64), b: wp.array(dtype=wp.float64)):
    i = wp.tid()
    m = wp.matrix(shape=(6, 6), dtype=wp.float64)
    for r in range(6):
        for c in range(6):
            m[r, c] = a[(i + 6 * r + c) % a.shape[0]]
    p = m @ m @ m
    s = wp.float64(0.0)
    for r in range(6):
        for c in range(6):
            s += p[r, c] * wp.float64(r + c + 1)
    b[i] = s
'''


@pytest.mark.parametrize("registers, block, expected", [(157, 256, 8 / 64), (157, 128, 12 / 64), (157, 64, 12 / 64),
                                                         (254, 256, 8 / 64), (32, 256, 1.0), (40, 64, 50 / 64)])
def test_occupancy_counts_warps_of_whole_blocks(registers, block, expected):
    """157 registers: 160 × 32 = 5,120 a warp, 12 warps fit 65,536, so one block of 8 warps or three of 4;
    40 registers: 1,280 a warp, 51 warps fit, 25 blocks of 2."""
    assert occupancy(registers, block) == pytest.approx(expected)


def test_registers_are_read_for_every_kernel_of_a_compiled_module(tmp_path, monkeypatch):
    """A module of two kernels compiled for sm_90 by NVRTC (no GPU needed): both are found, a copy needs
    few registers, a 6×6 float64 matrix product many more."""
    (tmp_path / "register_probe.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    import register_probe

    paths = wp.compile_aot_module(register_probe, arch=90, module_dir=str(tmp_path / "out"), use_ptx=False)
    registers = cubin_registers(paths[0].read_bytes())
    source = next(p for p in os.listdir(tmp_path / "out") if p.endswith(".cu"))
    dtypes = kernel_dtypes((tmp_path / "out" / source).read_text())
    forward = {name: count for name, count in registers.items() if name.endswith("_cuda_kernel_forward")}
    assert set(forward) == set(dtypes) and len(forward) == 2
    copy = next(v for k, v in forward.items() if k.startswith("copy_kernel"))
    product = next(v for k, v in forward.items() if k.startswith("many_live_values_kernel"))
    assert 1 <= copy < 32 and copy * 2 < product <= 255
    assert sorted(dtypes.values()) == ["float32", "float64"]
    del sys.modules["register_probe"]


def test_a_register_cap_holds_in_the_compiled_code(tmp_path, monkeypatch):
    """`register_capped(kernel, 32)`: the 6×6 float64 product compiled for sm_90 in at most 32 registers a thread
    (the rest spilled), where uncapped it takes more."""
    (tmp_path / "capped_probe.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    import capped_probe

    def forward_registers(module, folder):
        paths = wp.compile_aot_module(module, arch=90, module_dir=str(tmp_path / folder), use_ptx=False)
        registers = cubin_registers(paths[0].read_bytes())
        return next(v for k, v in registers.items() if k.startswith("many_live_values_kernel") and "forward" in k)

    capped = register_capped(capped_probe.many_live_values_kernel, 32)
    assert forward_registers(capped.module, "capped") <= 32 < forward_registers(capped_probe, "free")
    del sys.modules["capped_probe"]
