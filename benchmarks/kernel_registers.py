"""Registers per thread of the CUDA kernels and the occupancy they allow, read from the compiled code
(no GPU needed: Warp compiles the modules ahead of time with NVRTC).

    wavewarp bench kernel_registers --arch 90 --out benchmarks/results

Each kernel module of `wavewarp.kernels` (those built on demand aside; with the modules of its kernels
compiled alone) is compiled for sm_ARCH to a cubin; each kernel's register count is its EIATTR_REGCOUNT entry in the cubin's .nv.info section, its
dtype read from its first array argument in the generated CUDA source. The occupancy of a launch of
`block` threads: an SM holds 65,536 registers, allocated per warp in units of 256, and at most 64 warps
and 32 blocks (compute capability 8.0–9.0); shared memory is not counted (these kernels use none, the
staged kernels aside). Writes kernel_registers_smARCH.json.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import struct
import sys
import tempfile
from datetime import date

import warp as wp

from wavewarp import kernels
from wavewarp.io import write_json
from wavewarp.kernels import warp_modules

REGISTERS_PER_SM, WARPS_PER_SM, BLOCKS_PER_SM, ALLOCATION_UNIT = 65536, 64, 32, 256
REGCOUNT, SVAL_FORMAT = 0x2F, 0x04  # EIATTR_REGCOUNT; an entry with a 4-byte size and a value
BLOCKS = (64, 128, 256)


def occupancy(registers: int, block: int) -> float:
    """Resident warps / 64 for blocks of `block` threads at `registers` per thread."""
    per_warp = -(-registers * 32 // ALLOCATION_UNIT) * ALLOCATION_UNIT
    warps_per_block = -(-block // 32)
    blocks = min(REGISTERS_PER_SM // (per_warp * warps_per_block), WARPS_PER_SM // warps_per_block, BLOCKS_PER_SM)
    return blocks * warps_per_block / WARPS_PER_SM


def cubin_registers(data: bytes) -> dict:
    """{function name: registers per thread} from a cubin's EIATTR_REGCOUNT entries."""
    section_offset = struct.unpack_from("<Q", data, 0x28)[0]
    entry_size, count, names_index = struct.unpack_from("<HHH", data, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, section_offset + k * entry_size) for k in range(count)]

    def text(table, offset):
        start = sections[table][4] + offset
        return data[start : data.index(b"\0", start)].decode()

    names = [text(names_index, s[0]) for s in sections]
    symbols, strings = names.index(".symtab"), names.index(".strtab")
    symbol_name = [text(strings, struct.unpack_from("<I", data, sections[symbols][4] + 24 * k)[0])
                   for k in range(sections[symbols][5] // 24)]  # fmt: skip
    registers = {}
    for section, name in zip(sections, names):
        if name != ".nv.info":
            continue
        offset, end = section[4], section[4] + section[5]
        while offset < end:
            form, attribute, size = struct.unpack_from("<BBH", data, offset)
            if form == SVAL_FORMAT and attribute == REGCOUNT:
                function, value = struct.unpack_from("<II", data, offset + 4)
                registers[symbol_name[function]] = value
            offset += 4 + (size if form == SVAL_FORMAT else 0)
    return registers


def kernel_dtypes(source: str) -> dict:
    """{CUDA function name: "float32" | "float64" | "-"} from the generated source's first array argument."""
    dtypes = {}
    for match in re.finditer(r'extern "C" __global__ void (\w+_cuda_kernel_forward)\(([^)]*)\)', source):
        found = re.search(r"wp::(float32|float64)", match.group(2))
        dtypes[match.group(1)] = found.group(1) if found else "-"
    return dtypes


def module_rows(module, arch: int, folder: str) -> list:
    registers, dtypes = {}, {}
    for index, compiled in enumerate(warp_modules(module)):
        out = os.path.join(folder, str(index))
        paths = wp.compile_aot_module(compiled, arch=arch, module_dir=out, use_ptx=False)
        registers.update(cubin_registers(paths[0].read_bytes()))
        source = next(p for p in os.listdir(out) if p.endswith(".cu") and compiled.name in p)
        with open(os.path.join(out, source)) as f:
            dtypes.update(kernel_dtypes(f.read()))
    rows = []
    for function, dtype in sorted(dtypes.items(), key=lambda item: (item[0].rsplit("_", 4)[0], item[1])):
        kernel = re.sub(r"_[0-9a-f]{8}_cuda_kernel_forward$", "", function)
        rows.append({"module": module.__name__.rsplit(".", 1)[-1], "kernel": kernel, "dtype": dtype,
                     "registers": registers[function],
                     **{f"occupancy_block_{b}": occupancy(registers[function], b) for b in BLOCKS}})  # fmt: skip
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench kernel_registers", description=__doc__.split("\n\n")[0])
    parser.add_argument("--arch", type=int, default=90, help="compute capability × 10 (90: H100, H200)")
    parser.add_argument("--modules", nargs="+", default=None, help="kernel modules (default: all built at import)")
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    built = [m.name for m in pkgutil.iter_modules(kernels.__path__) if m.name not in kernels.BUILT_ON_DEMAND]
    names = args.modules or built
    unknown = [m for m in names if m not in built]
    if unknown:
        parser.error(f"--modules: no kernel module {', '.join(unknown)} (there are {', '.join(built)})")
    wp.init()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name in names:
            module = importlib.import_module(f"wavewarp.kernels.{name}")
            rows += module_rows(module, args.arch, os.path.join(folder, name))
    print(f"{'kernel':<42} {'dtype':<8} registers  " + "  ".join(f"occupancy@{b}" for b in BLOCKS))
    for row in rows:
        print(f"{row['module'] + '.' + row['kernel']:<42} {row['dtype']:<8} {row['registers']:>9}  "
              + "  ".join(f"{row[f'occupancy_block_{b}']:>12.1%}" for b in BLOCKS))  # fmt: skip
    result = {"benchmark": "kernel_registers", "date": date.today().isoformat(), "arch": f"sm_{args.arch}",
              "warp": wp.config.version, "rows": rows}  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"kernel_registers_sm{args.arch}.json")
    write_json(path, result)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
