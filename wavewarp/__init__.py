"""wavewarp: chemical waves on active elastic shells (Loop-subdivision Koiter shells in Warp)."""

from .version import __version__  # noqa: F401
from .chemistry import FitzHughNagumoSolver, TelegraphSolver
from .coupled import QuasiStatic, Walking
from .driver import simulate
from .dynamics import Ground, InertialSolver, OverdampedDynamics, OverdampedSolver, ShellDynamics
from .implicit_dynamics import ImplicitOverdampedDynamics, ImplicitOverdampedSolver, ImplicitStepError
from .geometry import LimitSurface, limit_positions, limit_surface, sample_points
from .initial import gaussian_pulse, steady_front
from .laplace import LaplaceBeltrami
from .mesh import Mesh, cube, icosphere, load, prism, save
from .model import Model, ModelBuilder
from .modes import azimuthal_order, softest_modes
from .relax import RelaxationError
from .resting_ground import RestingGround
from .self_contact import SelfContact
from .shell import BilayerReference, KoiterReference, Shell
from .state import State
from .waves import BlowUpError, FitzHughNagumo, OscillationError, Telegraph, TimeStepError

__all__ = [
    "BilayerReference", "BlowUpError", "FitzHughNagumo", "FitzHughNagumoSolver", "Ground", "ImplicitOverdampedDynamics",
    "ImplicitOverdampedSolver", "ImplicitStepError", "InertialSolver",
    "KoiterReference", "LaplaceBeltrami", "LimitSurface", "Mesh", "Model", "ModelBuilder", "OscillationError",
    "OverdampedDynamics", "OverdampedSolver", "QuasiStatic", "RelaxationError", "RestingGround", "SelfContact", "Shell",
    "ShellDynamics", "State", "Telegraph", "TelegraphSolver", "TimeStepError", "Walking",
    "azimuthal_order", "cube", "gaussian_pulse", "icosphere", "limit_positions", "limit_surface", "load", "prism",
    "sample_points", "save", "simulate", "softest_modes", "steady_front", "__version__",
]  # fmt: skip
