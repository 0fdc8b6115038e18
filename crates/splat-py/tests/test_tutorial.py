"""The tutorial of docs/python.md, run as written: its Python blocks in order, in a fresh
folder, on the pinned bonsai capture that `cargo xtask assets` fetches."""

from __future__ import annotations

import re

from conftest import REPO, missing

CAPTURE = REPO / "target" / "assets" / "bonsai-7k-mini.splat"


def python_blocks(markdown: str) -> list[str]:
    """The Python blocks of the tutorial section (the other sections' blocks are sketches)."""
    tutorial = markdown[markdown.index("## Tutorial") :]
    return re.findall(r"```python\n(.*?)```", tutorial, flags=re.S)


def test_the_tutorial_runs_as_written(tmp_path, monkeypatch):
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        missing("matplotlib is not installed: pip install -r crates/splat-py/requirements-test.txt")
    if not CAPTURE.exists():
        missing(f"no capture at {CAPTURE}: run `cargo xtask assets`")
    blocks = python_blocks((REPO / "docs" / "python.md").read_text())
    assert blocks, "docs/python.md has a tutorial"
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SPLAT_CAPTURE", str(CAPTURE))
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "docs/python.md", "exec"), namespace)
    assert (tmp_path / "rmse.png").stat().st_size > 10_000
