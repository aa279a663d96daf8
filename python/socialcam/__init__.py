"""socialcam: 3D social signals from social cameras.

Geometry and the thesis' solvers run in a Rust core (``socialcam._core``) with the GIL
released; this package adds I/O, simulation, plots and the command line.

Conventions (see DESIGN.md): metres, seconds, radians; float64 arrays; pinhole
``P = K R [I | -C]`` with OpenCV pixel coordinates; NaN rows for missing observations.
"""

from socialcam import synth
from socialcam._core import __version__
from socialcam.articulated import (
    ArticulatedTrajectory,
    BqpResult,
    Skeleton,
    SkeletonReconstruction,
    articulated_bqp,
    articulated_reconstructability,
    reconstruct_articulated,
    reconstruct_skeleton,
    solve_bqp,
)
from socialcam.camera import Cameras
from socialcam.errors import ConvergenceError, DegenerateError
from socialcam.geometry import (
    TriangulationInfo,
    align_similarity,
    dct_basis,
    perspective_distance,
    ray_sphere,
    triangulate,
)

__all__ = [
    "Cameras",
    "ConvergenceError",
    "DegenerateError",
    "TriangulationInfo",
    "__version__",
    "align_similarity",
    "dct_basis",
    "perspective_distance",
    "ray_sphere",
    "synth",
    "triangulate",
]
__all__ += [
    "ArticulatedTrajectory",
    "BqpResult",
    "Skeleton",
    "SkeletonReconstruction",
    "articulated_bqp",
    "articulated_reconstructability",
    "reconstruct_articulated",
    "reconstruct_skeleton",
    "solve_bqp",
]
