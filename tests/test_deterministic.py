"""Deterministic mode (wavewarp.device.set_deterministic; docs/theory/sweeps.md): the fixed-order
gathers and one-block reductions compute the sums the atomic scatters do (float64, to round-off),
every solver built after the switch uses them, and on a GPU two runs agree bit for bit."""

import importlib
import pkgutil

import numpy as np
import pytest
import warp as wp

from wavewarp import kernels
from wavewarp.device import reduction_threads, set_deterministic
from wavewarp.kernels.dynamics import eval_rigid_correction
from wavewarp.kernels.staged import staged_shell_forces_kernel
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.parameters import load_scene, resolve
from wavewarp.shell import Shell

F64 = dict(dtype="float64")


@pytest.fixture
def deterministic():
    set_deterministic(True)
    yield
    set_deterministic(False)


def bumpy_sphere(level=2):
    mesh = icosphere(1.0, level)
    v = mesh.vertices
    return mesh, v * (1.0 + 0.15 * v[:, [0]] ** 2 - 0.1 * v[:, [2]])


def test_laplace_gathers_equal_the_atomic_scatters(device, rng):
    """Lumped mass, K c and the consistent mass by per-point factors and a per-vertex gather equal
    the per-point atomic scatter's, and keep K·1 = 0 and K symmetric."""
    mesh, x = bumpy_sphere()
    c, d = rng.standard_normal((2, mesh.n_vertices))
    scatter = LaplaceBeltrami(mesh, x, assembled=False, device=device, deterministic=False, **F64)
    gather = LaplaceBeltrami(mesh, x, assembled=False, device=device, deterministic=True, **F64)
    np.testing.assert_allclose(gather.mass(), scatter.mass(), rtol=1e-13)
    np.testing.assert_allclose(gather.apply(c), scatter.apply(c), rtol=0, atol=1e-12 * np.abs(scatter.apply(c)).max())
    assert np.abs(gather.apply(np.ones(mesh.n_vertices))).max() < 1e-13
    assert gather.apply(c) @ d == pytest.approx(gather.apply(d) @ c, rel=1e-12)
    products = []
    for operator in (scatter, gather):
        out = wp.zeros(mesh.n_vertices, dtype=wp.float64, device=device)
        operator.consistent_mass_device(wp.array(c, dtype=wp.float64, device=device), out)
        products.append(out.numpy())
    np.testing.assert_allclose(products[1], products[0], rtol=0, atol=1e-13 * np.abs(products[0]).max())
    assert products[1].sum() == pytest.approx(gather.mass() @ c, rel=1e-12)  # Σ_I ∫ N_I N_J c_J = ∫ c


def test_one_block_rigid_sums_equal_the_many_block_ones_and_numpy(device, rng):
    """The rigid-body correction from one block (deterministic) and from whole blocks of one vertex a
    thread: the same, and its net acceleration is Σ F / Σ M computed by NumPy."""
    mesh, x = bumpy_sphere(3)
    n = mesh.n_vertices
    assert n > 2 * int(reduction_threads(1, deterministic=True))  # several blocks in the default launch
    forces, velocities = rng.standard_normal((2, n, 3))
    mass = rng.uniform(0.5, 1.5, n)
    rigid = []
    for threads in (reduction_threads(n, deterministic=False), reduction_threads(n, deterministic=True)):
        arrays = [wp.array(a, dtype=wp.vec3d, device=device) for a in (forces, x, velocities)]
        sums, second, out = (wp.zeros(k, dtype=t, device=device) for k, t in ((5, wp.vec3d), (1, wp.mat33d), (5, wp.vec3d)))
        inverse_total = wp.array([1.0 / mass.sum()], dtype=wp.float64, device=device)
        eval_rigid_correction(arrays[0], wp.array(mass, dtype=wp.float64, device=device), arrays[1], arrays[2], True, 1,
                              threads, inverse_total, sums, second, out)  # fmt: skip
        rigid.append(out.numpy())
    np.testing.assert_allclose(rigid[1], rigid[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(rigid[1][0], forces.sum(axis=0) / mass.sum(), rtol=1e-12)
    np.testing.assert_allclose(rigid[1][2], mass @ x / mass.sum(), rtol=1e-12)


def test_set_deterministic_reaches_what_is_built_after_it(deterministic):
    mesh, _ = bumpy_sphere(1)
    assert Shell(mesh, 0.1, 1.0, device="cpu").deterministic
    assert LaplaceBeltrami(mesh, device="cpu").deterministic
    assert reduction_threads(100_000) == reduction_threads(1, deterministic=True)
    set_deterministic(False)
    assert not Shell(mesh, 0.1, 1.0, device="cpu").deterministic
    assert not LaplaceBeltrami(mesh, device="cpu").deterministic
    assert reduction_threads(100_000) >= 100_000


def walker_trace(device, dtype="float32", frames=1):
    module = load_scene("sphere-walker")
    p = resolve(module.Parameters, module.QUICK, ["periods=0.05", f"frames={frames}", "noise=1e-3", "level=1",
                                                  "settle=10", f"dtype={dtype}"])  # fmt: skip
    run = module.build(p, device=device, report=lambda message: None)
    run.record(run.time, run.frame())
    for _ in range(frames):
        run.advance_frame()
        run.record(run.time, run.frame())
    return np.array(run.trace), run.frame()["positions"]


def test_a_deterministic_walker_repeats_bit_for_bit_on_a_gpu(deterministic):
    """A float32 sphere walker (chaotic: atomics' order shows in its path) run twice in deterministic
    mode on a GPU: the same trace and positions, bit for bit (a CPU run is deterministic in any mode)."""
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    first, second = walker_trace("cuda:0"), walker_trace("cuda:0")
    assert np.array_equal(first[0], second[0])
    assert np.array_equal(first[1], second[1])


def test_the_deterministic_walker_follows_the_default_one():
    """Deterministic mode changes only the order of sums: in float64 its walker follows the default
    mode's to round-off over a short horizon."""
    default = walker_trace("cpu", "float64")
    set_deterministic(True)
    try:
        fixed = walker_trace("cpu", "float64")
    finally:
        set_deterministic(False)
    radius = np.abs(default[1]).max()
    assert np.abs(fixed[1] - default[1]).max() < 1e-9 * radius
    assert np.abs(fixed[0] - default[0]).max() < 1e-9 * radius


@pytest.mark.slow
def test_every_kernel_module_compiles_in_deterministic_mode(deterministic):
    """Warp's deterministic mode refuses some atomic patterns at code generation (an array that receives
    both adds and maxima, for one): every kernel module of wavewarp, every overload, compiles under it (a
    module built on demand: one of its kernels)."""
    for info in pkgutil.iter_modules(kernels.__path__):
        if info.name not in kernels.BUILT_ON_DEMAND:
            wp.load_module(importlib.import_module(f"{kernels.__name__}.{info.name}"), device="cpu")
    wp.load_module(staged_shell_forces_kernel(32).module, device="cpu")
