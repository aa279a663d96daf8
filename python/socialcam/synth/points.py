"""Seeded 3D point sets and smooth point trajectories."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, as_float_array, check_seed


def random_points(
    n: int, *, seed: int = 0, center: npt.ArrayLike = (0.0, 0.0, 1.0), extent: float = 1.0
) -> FloatArray:
    """``n`` static points ``(n, 3)`` uniform in a cube of side ``2 * extent`` metres."""
    rng = np.random.default_rng(check_seed(seed))
    c = as_float_array(center, "center", (3,))
    return c + rng.uniform(-extent, extent, (n, 3))


def smooth_trajectories(
    n: int,
    times: npt.ArrayLike,
    *,
    seed: int = 0,
    center: npt.ArrayLike = (0.0, 0.0, 1.0),
    extent: float = 1.0,
    frequency: float = 0.5,
    static_fraction: float = 0.0,
) -> FloatArray:
    """``n`` smooth random trajectories ``(n, F, 3)`` sampled at ``times (F,)`` seconds.

    Each coordinate is a sum of sinusoids with random phases whose frequencies fall off from
    ``frequency`` Hz (so the motion is band-limited, like human motion), scaled to move
    about ``extent`` metres around a random start inside the cube ``center ± extent``.
    A ``static_fraction`` of the points does not move at all.
    """
    rng = np.random.default_rng(check_seed(seed))
    t = as_float_array(times, "times", (None,))
    if not 0.0 <= static_fraction <= 1.0:
        raise ValueError(f"static_fraction: must be in [0, 1], got {static_fraction}")
    c = as_float_array(center, "center", (3,))
    start = c + rng.uniform(-extent, extent, (n, 3))
    n_harm = 4
    freqs = frequency * rng.uniform(0.3, 1.0, (n, 3, n_harm)) * np.arange(1, n_harm + 1) ** 0.5
    amps = extent * 0.5 * rng.uniform(0.2, 1.0, (n, 3, n_harm)) / np.arange(1, n_harm + 1)
    phases = rng.uniform(0, 2 * np.pi, (n, 3, n_harm))
    arg = 2 * np.pi * freqs[..., None] * (t - t.min())[None, None, None] + phases[..., None]
    motion = (amps[..., None] * (np.sin(arg) - np.sin(phases)[..., None])).sum(axis=2)  # (n,3,F)
    X = start[:, None, :] + motion.transpose(0, 2, 1)
    still = rng.random(n) < static_fraction
    X[still] = start[still, None, :]
    return X
