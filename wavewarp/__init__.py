"""wavewarp: chemical waves on active elastic shells (Loop-subdivision Koiter shells in Warp)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wavewarp")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+source"

from .dynamics import Ground, OverdampedDynamics, ShellDynamics  # noqa: E402
from .geometry import LimitSurface, limit_positions, limit_surface, sample_points  # noqa: E402
from .laplace import LaplaceBeltrami  # noqa: E402
from .mesh import Mesh, cube, icosphere, load, prism, save  # noqa: E402
from .modes import azimuthal_order, softest_modes  # noqa: E402
from .self_contact import SelfContact  # noqa: E402
from .relax import RelaxationError  # noqa: E402
from .shell import Shell  # noqa: E402
from .initial import gaussian_pulse, steady_front  # noqa: E402
from .waves import BlowUpError, FitzHughNagumo, OscillationError, Telegraph  # noqa: E402

__all__ = [
    "BlowUpError", "FitzHughNagumo", "Ground", "LaplaceBeltrami", "LimitSurface", "Mesh", "OscillationError",
    "OverdampedDynamics", "RelaxationError", "SelfContact", "Shell",
    "ShellDynamics", "Telegraph",
    "azimuthal_order", "cube", "gaussian_pulse", "icosphere", "limit_positions", "limit_surface", "load", "prism",
    "sample_points", "save", "softest_modes", "steady_front", "__version__",
]  # fmt: skip
