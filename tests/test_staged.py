"""Koiter forces with each block's patch vertices staged in shared memory (kernels/staged.py): the
per-block tables against a direct set computation, the forces against the atomic scatter's; the atomic
scatter launched in other blocks (force_block) and with its registers capped (force_registers) against its default
launch."""

import numpy as np
import pytest
import warp as wp
from meshes import random_genus0

from wavewarp.mesh import Mesh, icosphere
from wavewarp.patches import block_unions, build_patch_tables
from wavewarp.shell import Shell

ACTIVE = dict(thickness=0.06, young=3.0, AC=0.4, AI=0.7, volume_penalty=3.0, dtype="float64")


@pytest.mark.parametrize("block", [1, 5, 32, 1000])
def test_each_row_is_its_blocks_union_of_patches_and_maps_every_entry_back(block):
    mesh = random_genus0(24, 3).subdivided(1)  # valences 3 to 8: patches of 9 to 14 vertices
    tables = build_patch_tables(mesh.triangles, mesh.n_vertices)
    unions = block_unions(tables, block, multiple=8)
    starts = tables.patch_start
    n_blocks = -(-tables.n_triangles // block)
    assert unions.block_vertices.shape == (n_blocks, unions.capacity) and unions.capacity % 8 == 0
    sizes = []
    for b in range(n_blocks):
        triangles = range(b * block, min((b + 1) * block, tables.n_triangles))
        union = sorted({int(v) for t in triangles for v in tables.patch_vertices[starts[t] : starts[t + 1]]})
        row = unions.block_vertices[b]
        assert list(row[: len(union)]) == union and np.all(row[len(union) :] == union[0])
        sizes.append(len(union))
        for t in triangles:
            entries = slice(starts[t], starts[t + 1])
            assert np.array_equal(row[unions.patch_local[entries]], tables.patch_vertices[entries])
    assert unions.capacity == -(-max(sizes) // 8) * 8


def test_staged_forces_and_energy_equal_the_atomic_scatters_on_the_cpu(rng):
    mesh = random_genus0(24, 3).subdivided(1)
    x = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape)
    c = rng.random(mesh.n_vertices)
    atomic = Shell(mesh, **ACTIVE, regular_patches="general", device="cpu")  # the staged kernel's per-triangle code
    staged = Shell(mesh, **ACTIVE, staged_block=1, device="cpu")
    # one lane per block on the CPU: the same sums in the same order, bit for bit
    assert np.array_equal(staged.forces(x, c), atomic.forces(x, c))
    assert staged.energy(x, c) == atomic.energy(x, c)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="blocks of many lanes need CUDA")
@pytest.mark.parametrize("block", [1, 7, 64, 256])
def test_staged_forces_of_batched_worlds_equal_the_atomic_scatters_on_cuda(block, rng):
    base = icosphere(3.0, 2)
    worlds = [Mesh(base.vertices + 0.02 * rng.normal(size=base.vertices.shape), base.triangles) for _ in range(3)]
    mesh = Mesh.union(worlds)
    # away from the rest shape: forces at rest are a near-cancellation, whose rounding depends on the compiled code
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    options = dict(ACTIVE, AC=[0.1, 0.2, 0.3], device="cuda:0")
    atomic = Shell(mesh, **options).forces(x, c)
    staged = Shell(mesh, **options, staged_block=block).forces(x, c)
    np.testing.assert_allclose(staged, atomic, rtol=0, atol=1e-12 * np.abs(atomic).max())


def test_the_force_launchs_block_size_leaves_the_cpu_forces_as_they_are(rng):
    mesh = random_genus0(24, 3).subdivided(1)
    x = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape)
    c = rng.random(mesh.n_vertices)
    default, large = Shell(mesh, **ACTIVE, device="cpu"), Shell(mesh, **ACTIVE, force_block=256, device="cpu")
    assert default.force_block == 64 and large.force_block == 256 and large.twin("float32").force_block == 256
    assert np.array_equal(large.forces(x, c), default.forces(x, c))
    capped = Shell(mesh, **ACTIVE, force_registers=64, device="cpu")
    assert capped.twin("float64").force_registers == 64
    assert np.array_equal(capped.forces(x, c), default.forces(x, c))


@pytest.mark.skipif(not wp.is_cuda_available(), reason="the block size and the register cap matter on CUDA only")
@pytest.mark.parametrize("launch", [dict(force_block=32), dict(force_block=128), dict(force_block=256),
                                    dict(force_registers=64), dict(force_registers=96)])
def test_forces_launched_in_other_blocks_or_fewer_registers_equal_the_default_launchs_on_cuda(launch, rng):
    mesh = icosphere(3.0, 3)
    x, c = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape), rng.random(mesh.n_vertices)
    default = Shell(mesh, **ACTIVE, device="cuda:0").forces(x, c)
    other = Shell(mesh, **ACTIVE, **launch, device="cuda:0").forces(x, c)
    np.testing.assert_allclose(other, default, rtol=0, atol=1e-12 * np.abs(default).max())


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(force_block=100), "force_block must be one of 32, 64"),
        (dict(force_block=512), "force_block must be one of"),
        (dict(force_block=True), "force_block must be one of"),
        (dict(force_registers=16), "force_registers must be a whole number of registers from 24 to 255"),
        (dict(force_registers=300), "force_registers must be"),
        (dict(force_registers=64.0), "force_registers must be"),
        (dict(force_registers=True), "force_registers must be"),
        (dict(staged_block=4, device="cpu"), "staged_block = 4 on the CPU"),
        (dict(staged_block=0), "staged_block must be a whole number"),
        (dict(staged_block=True), "staged_block must be a whole number"),
        (dict(staged_block=1, deterministic=True), "choose one"),
    ],
)
def test_bad_staging_is_refused_with_the_fix(options, message):
    with pytest.raises(ValueError, match=message):
        Shell(icosphere(1.0, 1), **dict(dict(ACTIVE, device="cpu"), **options))
