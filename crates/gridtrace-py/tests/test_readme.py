"""The README's Python examples run as written: every ```python block of README.md is run as a
script of its own (a fresh interpreter, the repository root as working directory, so that the
README's mesh paths ``../shared/data/meshes/...`` resolve as they do for a reader of the README
in a checkout). A block that raises, or names something it never defines, fails here."""

from __future__ import annotations

import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
README = ROOT / "README.md"


def python_blocks(text: str) -> list:
    """(first line number, source) of each fenced ```python block."""
    blocks = []
    for m in re.finditer(r"^```python[ \t]*\n(.*?)^```[ \t]*$", text, re.S | re.M):
        blocks.append((text.count("\n", 0, m.start()) + 2, m.group(1)))
    return blocks


BLOCKS = python_blocks(README.read_text(encoding="utf-8"))


def test_the_readme_has_python_examples():
    # The extraction itself: a README whose fences changed would otherwise test nothing.
    assert len(BLOCKS) >= 2, f"found {len(BLOCKS)} ```python blocks in {README}"


@pytest.mark.parametrize("line,source", BLOCKS, ids=[f"README.md:{line}" for line, _ in BLOCKS])
def test_readme_python_block_runs(line, source):
    meshes = ROOT.parent / "shared" / "data" / "meshes"
    if "../shared/data/meshes" in source:
        # Fail, not skip: the README promises these paths beside a checkout (CI has them).
        assert meshes.is_dir(), f"README.md:{line} reads meshes from {meshes}, which is missing"
    done = subprocess.run(
        [sys.executable, "-c", source],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, f"README.md:{line} failed:\n{done.stdout}\n{done.stderr}"
