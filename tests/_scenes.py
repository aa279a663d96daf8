"""Small seeded scenes shared by the robustness and API tests."""

from __future__ import annotations

import numpy as np

from socialcam.camera import Cameras


def ring(f: int, *, radius: float = 5.0, seed: int = 0) -> Cameras:
    """``f`` cameras on a wobbling ring looking at the origin, times 0.1 s apart."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, f, endpoint=False) + rng.normal(scale=0.01, size=f)
    C = np.c_[radius * np.cos(a), radius * np.sin(a), 1.5 + 0.3 * np.sin(5 * a)]
    Rs = []
    for c in C:
        z = -c / np.linalg.norm(c)
        x = np.cross([0.0, 0.0, 1.0], z)
        x /= np.linalg.norm(x)
        Rs.append([x, np.cross(z, x), z])
    K = np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 1]])
    return Cameras(K, np.array(Rs), C, times=np.arange(f) * 0.1)
