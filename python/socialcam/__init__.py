"""socialcam: 3D social signals from social cameras.

Geometry and the thesis' solvers run in a Rust core (``socialcam._core``) with the GIL
released; this package adds I/O, simulation, plots and the command line.

Conventions (see DESIGN.md): metres, seconds, radians; float64 arrays; pinhole
``P = K R [I | -C]`` with OpenCV pixel coordinates; NaN rows for missing observations.
"""

from socialcam import mocap, sfm, synth
from socialcam._core import __version__
from socialcam.camera import Cameras
from socialcam.charges import (
    Charge,
    ChargeTrack,
    GazeRays,
    find_charges,
    find_charges_sequence,
    plot_charge_tracks,
    plot_saliency,
    saliency_field,
    saliency_grid,
    track_charges,
)
from socialcam.errors import ConvergenceError, DegenerateError
from socialcam.gazefield import (  # issue 6: gaze field (thesis Chapter 7)
    Anomalies,
    GazeCrossValidation,
    GazeField,
    cross_validate_gaze,
    detect_anomalies,
    fuse_gaze,
    plot_gaze_field,
)
from socialcam.geometry import (
    TriangulationInfo,
    align_similarity,
    dct_basis,
    perspective_distance,
    ray_sphere,
    triangulate,
)
from socialcam.trajectory import (
    Trajectory,
    TrajectoryBatch,
    reconstruct_trajectories,
    reconstruct_trajectory,
    reconstructability,
)

__all__ = [
    "Cameras",
    # social charges (issue 5)
    "Charge",
    "ChargeTrack",
    "ConvergenceError",
    "DegenerateError",
    "GazeRays",
    "TriangulationInfo",
    "__version__",
    "align_similarity",
    "dct_basis",
    "mocap",
    "find_charges",
    "find_charges_sequence",
    "perspective_distance",
    "plot_charge_tracks",
    "plot_saliency",
    "ray_sphere",
    "sfm",
    "saliency_field",
    "saliency_grid",
    "synth",
    "track_charges",
    "triangulate",
]
# trajectory reconstruction (Chapter 5)
__all__ += [
    "Trajectory",
    "TrajectoryBatch",
    "reconstruct_trajectories",
    "reconstruct_trajectory",
    "reconstructability",
]

# issue 6: gaze field (thesis Chapter 7)
__all__ += [
    "Anomalies",
    "GazeCrossValidation",
    "GazeField",
    "cross_validate_gaze",
    "detect_anomalies",
    "fuse_gaze",
    "plot_gaze_field",
]
