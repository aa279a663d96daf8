"""The README's Python snippets run as written and print no NaN (a snippet printed ``nan``
once: ``info.rms.mean()`` over points that could not be triangulated)."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
SKIP = "<!-- readme-test: skip -->"


def python_snippets() -> list[tuple[int, str]]:
    """``(line, code)`` of every fenced ``python`` block not preceded by the skip marker."""
    text = README.read_text(encoding="utf-8")
    out = []
    for m in re.finditer(r"```python\n(.*?)```", text, flags=re.S):
        before = text[: m.start()].rstrip().splitlines()
        if before and before[-1].strip() == SKIP:
            continue
        out.append((text.count("\n", 0, m.start()) + 1, m.group(1)))
    return out


def test_readme_has_snippets_to_run():
    assert len(python_snippets()) >= 2


@pytest.mark.parametrize("line, code", python_snippets(), ids=lambda v: str(v)[:12])
def test_readme_snippet_runs_and_prints_no_nan(line, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, f"README.md:{line}", "exec"), {"__name__": "__readme__"})
    assert "nan" not in out.getvalue().lower(), out.getvalue()
