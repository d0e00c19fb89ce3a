"""wavewarp: chemical waves on active elastic shells (Loop-subdivision Koiter shells in Warp)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wavewarp")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+source"

from .chemistry import FitzHughNagumoSolver, TelegraphSolver  # noqa: E402
from .coupled import QuasiStatic, Walking  # noqa: E402
from .driver import simulate  # noqa: E402
from .dynamics import Ground, InertialSolver, OverdampedDynamics, OverdampedSolver, ShellDynamics  # noqa: E402
from .geometry import LimitSurface, limit_positions, limit_surface, sample_points  # noqa: E402
from .initial import gaussian_pulse, steady_front  # noqa: E402
from .laplace import LaplaceBeltrami  # noqa: E402
from .mesh import Mesh, cube, icosphere, load, prism, save  # noqa: E402
from .model import Model, ModelBuilder  # noqa: E402
from .modes import azimuthal_order, softest_modes  # noqa: E402
from .relax import RelaxationError  # noqa: E402
from .self_contact import SelfContact  # noqa: E402
from .shell import BilayerReference, KoiterReference, Shell  # noqa: E402
from .state import State  # noqa: E402
from .waves import BlowUpError, FitzHughNagumo, OscillationError, Telegraph, TimeStepError  # noqa: E402

__all__ = [
    "BilayerReference", "BlowUpError", "FitzHughNagumo", "FitzHughNagumoSolver", "Ground", "InertialSolver",
    "KoiterReference", "LaplaceBeltrami", "LimitSurface", "Mesh", "Model", "ModelBuilder", "OscillationError",
    "OverdampedDynamics", "OverdampedSolver", "QuasiStatic", "RelaxationError", "SelfContact", "Shell", "ShellDynamics",
    "State", "Telegraph", "TelegraphSolver", "TimeStepError", "Walking",
    "azimuthal_order", "cube", "gaussian_pulse", "icosphere", "limit_positions", "limit_surface", "load", "prism",
    "sample_points", "save", "simulate", "softest_modes", "steady_front", "__version__",
]  # fmt: skip
