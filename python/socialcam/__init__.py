"""socialcam: 3D social signals from social cameras.

Geometry and the thesis' solvers run in a Rust core (``socialcam._core``) with the GIL
released; this package adds I/O, simulation, plots and the command line.

Conventions (see the README): metres, seconds, radians; float64 arrays; pinhole
``P = K R [I | -C]`` with OpenCV pixel coordinates; NaN rows for missing observations;
options keyword-only; bad input raises ``ValueError`` naming the argument.
"""

from socialcam import mocap, sfm, synth
from socialcam._core import __version__
from socialcam.articulated import (
    ArticulatedOptions,
    ArticulatedTrajectory,
    BqpOptions,
    BqpResult,
    Skeleton,
    SkeletonReconstruction,
    articulated_bqp,
    articulated_reconstructability,
    bone_angles,
    learn_angle_ranges,
    reconstruct_articulated,
    reconstruct_skeleton,
    solve_bqp,
)
from socialcam.camera import Cameras
from socialcam.charges import (
    Charge,
    ChargeOptions,
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
from socialcam.gaze import GazeCalibration, calibrate_gaze
from socialcam.gazefield import (
    Anomalies,
    GazeCrossValidation,
    GazeField,
    GazeFieldOptions,
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
from socialcam.pipeline import RunOptions, RunResult, poses, run
from socialcam.sfm import VideoReconstruction, reconstruct_videos
from socialcam.trajectory import (
    Trajectory,
    TrajectoryBatch,
    TrajectoryOptions,
    reconstruct_trajectories,
    reconstruct_trajectory,
    reconstructability,
)

__all__ = [
    "Anomalies",
    "ArticulatedOptions",
    "ArticulatedTrajectory",
    "BqpOptions",
    "BqpResult",
    "Cameras",
    "Charge",
    "ChargeOptions",
    "ChargeTrack",
    "ConvergenceError",
    "DegenerateError",
    "GazeCalibration",
    "GazeCrossValidation",
    "GazeField",
    "GazeFieldOptions",
    "GazeRays",
    "RunOptions",
    "RunResult",
    "Skeleton",
    "SkeletonReconstruction",
    "Trajectory",
    "TrajectoryBatch",
    "TrajectoryOptions",
    "TriangulationInfo",
    "VideoReconstruction",
    "__version__",
    "align_similarity",
    "articulated_bqp",
    "articulated_reconstructability",
    "bone_angles",
    "calibrate_gaze",
    "cross_validate_gaze",
    "dct_basis",
    "detect_anomalies",
    "find_charges",
    "find_charges_sequence",
    "fuse_gaze",
    "learn_angle_ranges",
    "mocap",
    "perspective_distance",
    "plot_charge_tracks",
    "plot_gaze_field",
    "plot_saliency",
    "poses",
    "ray_sphere",
    "reconstruct_articulated",
    "reconstruct_skeleton",
    "reconstruct_trajectories",
    "reconstruct_trajectory",
    "reconstruct_videos",
    "reconstructability",
    "run",
    "saliency_field",
    "saliency_grid",
    "sfm",
    "solve_bqp",
    "synth",
    "track_charges",
    "triangulate",
]
