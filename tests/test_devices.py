"""Mixed devices are a one-line ValueError, never a crash (issue 57, item 2): every launcher of kernels/ (`eval_*`),
the operators' and the shell's device methods and the adjoints check that the arrays of a call lie on one device
before anything is launched (Warp itself launches across devices unchecked: a segfault, or CUDA error 700 that
poisons the context for every later launch). Where CUDA is present the other device is cuda:0; on a CPU-only machine
it is an object that says it lives on cuda:0 (its launch would raise a TypeError, not the ValueError checked)."""

import importlib
import pkgutil
from types import SimpleNamespace

import numpy as np
import pytest
import warp as wp
from wavewarp.kernels import check_one_device
from wavewarp.kernels.adjoint_wave import eval_add_scaled

from wavewarp import kernels
from wavewarp.adjoint_wave import WaveAdjoint
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.shell import Shell

CUDA = wp.is_cuda_available()


def elsewhere(values, dtype=wp.float64):
    """`values` on another device than the CPU: cuda:0 where present, else a stand-in that says it lives there."""
    if CUDA:
        return wp.array(values, dtype=dtype, device="cuda:0")
    return SimpleNamespace(device=SimpleNamespace(alias="cuda:0", is_cuda=True), shape=np.shape(values))


def one_line(error) -> str:
    message = str(error.value)
    assert "\n" not in message
    return message


def test_every_launcher_checks_its_devices():
    """Each `eval_*` function of every kernel module is wrapped by `one_device`."""
    launchers = []
    for info in pkgutil.iter_modules(kernels.__path__):
        module = importlib.import_module(f"{kernels.__name__}.{info.name}")
        launchers += [(info.name, name, value) for name, value in vars(module).items()
                      if name.startswith("eval_") and callable(value) and value.__module__ == module.__name__]
    assert len(launchers) >= 40
    unchecked = [f"{module}.{name}" for module, name, value in launchers if not hasattr(value, "__wrapped__")]
    assert unchecked == []


def test_a_launcher_refuses_arrays_on_two_devices_naming_them():
    total = wp.zeros(4, dtype=wp.float64, device="cpu")
    with pytest.raises(ValueError) as error:
        eval_add_scaled(total, elsewhere(np.ones(4)), 2.0)
    assert one_line(error).startswith("eval_add_scaled: its arrays lie on different devices (total on cpu; part on "
                                      "cuda:0)")
    eval_add_scaled(total, wp.ones(4, dtype=wp.float64, device="cpu"), 2.0)  # one device: launched
    np.testing.assert_array_equal(total.numpy(), 2.0)
    if CUDA:  # the context is not poisoned: a CUDA launch after the refusal works
        on_gpu = wp.zeros(4, dtype=wp.float64, device="cuda:0")
        eval_add_scaled(on_gpu, wp.ones(4, dtype=wp.float64, device="cuda:0"), 3.0)
        np.testing.assert_array_equal(on_gpu.numpy(), 3.0)


def test_the_operator_the_shell_and_the_wave_adjoint_refuse_another_devices_arrays():
    mesh = icosphere(1.0, 1)
    operator = LaplaceBeltrami(mesh, device="cpu", dtype="float64")
    out = wp.zeros(mesh.n_vertices, dtype=wp.float64, device="cpu")
    with pytest.raises(ValueError, match=r"apply_device: its arrays lie on different devices \(self on cpu; c on "):
        operator.apply_device(elsewhere(np.ones(mesh.n_vertices)), out)
    shell = Shell(mesh, 0.1, 1.0, device="cpu", dtype="float64")
    forces = wp.zeros(mesh.n_vertices, dtype=wp.vec3d, device="cpu")
    with pytest.raises(ValueError, match=r"forces_device: its arrays lie on different devices \(self on cpu; x on "):
        shell.forces_device(elsewhere(mesh.vertices, wp.vec3d), forces)
    wave = SimpleNamespace(solver=None, operator=operator, dt=0.1)
    with pytest.raises(ValueError, match=r"WaveAdjoint: its arrays lie on different devices \(wave on cpu; "
                                         r"shell_tables on cuda:0\)"):
        WaveAdjoint(wave, elsewhere(np.ones(3)))


def test_one_device_passes_and_the_check_names_what_differs():
    check_one_device("here", a=wp.zeros(2, device="cpu"), b=[wp.zeros(2, device="cpu")], scalar=1.0, none=None)
    with pytest.raises(ValueError, match=r"^there: its arrays lie on different devices \(a on cpu; b on cuda:0\)"):
        check_one_device("there", a=wp.zeros(2, device="cpu"), b=[elsewhere(np.ones(2))])
