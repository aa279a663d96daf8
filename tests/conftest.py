from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session", autouse=True)
def ctrl_c_raises() -> Iterator[None]:
    """Ctrl-C raises ``KeyboardInterrupt``, as in an interactive session. A shell starts a
    background job (``pytest ... &``) with SIGINT ignored, and Python then leaves it
    ignored: the Ctrl-C tests would see no interrupt at all."""
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def small_scene(tmp_path_factory: pytest.TempPathFactory):
    """A small rendered scene shared by the render / video / sync tests: 2 wearers × 2 s,
    320×240, 30 fps, static room only in view of the truth checks (bodies and targets
    drawn too)."""
    from socialcam.synth.render import render_scene

    out = tmp_path_factory.mktemp("scene")
    return render_scene(out, n_wearers=2, duration=2.0, size=(320, 240), seed=3, progress=False)


@pytest.fixture(scope="session")
def room_scene(tmp_path_factory: pytest.TempPathFactory):
    """1 wearer × 1 s, 320×240, with nothing moving in view (no bodies, no targets): every
    pixel is a static surface, for exact truth checks."""
    from socialcam.synth.render import render_scene

    out = tmp_path_factory.mktemp("room")
    return render_scene(
        out,
        n_wearers=1,
        duration=1.0,
        size=(320, 240),
        seed=5,
        progress=False,
        n_targets=0,
        bodies=False,
    )
