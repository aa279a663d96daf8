"""The hand-written stubs of the Rust extension match what it exports."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def test_core_stubs_match_the_extension():
    allow = Path(__file__).parent / "stubtest_allowlist.txt"
    out = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "socialcam._core", "--allowlist", str(allow)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 0, out.stdout + out.stderr
