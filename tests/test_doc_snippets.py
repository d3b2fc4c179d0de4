"""The README's and the docs' Python examples run: every ```python block of README.md and docs/*.md is executed as
a script in a fresh interpreter (working directory: an empty folder with the repository's ``assets/``), and must
exit 0.

The blocks that are not runnable as written are listed in :data:`NOT_RUN` by their first line, each with the reason
and where what it shows is tested instead; a test checks that every entry still names a block, so the list cannot
hide a new example.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)

NOT_RUN = {
    ("docs/plugins.md", "agent.reset(rng, state=s0 if agent.observes_state else None)"): (
        "the episode loop in pseudo-code (repeat:); the loop itself: tests/episodes, tests/test_obs_contract.py"
    ),
    ("docs/recording.md", "from rerun.chunk import RrdReader"): (
        "reads runs/demo/episode.rrd, the README main job's recording; reading recordings: tests/episodes"
    ),
    ("docs/teamster.md", "import time, numpy as np, torch"): (
        "a CPU-time measurement of 20-step TEAMSTER runs on three maps (minutes); the agents: tests/teamster"
    ),
}


def blocks() -> list[tuple[str, int, str]]:
    found = []
    for page in PAGES:
        text = page.read_text()
        for match in BLOCK.finditer(text):
            found.append(
                (page.relative_to(ROOT).as_posix(), text[: match.start()].count("\n") + 1, match.group(1))
            )
    return found


def first_line(code: str) -> str:
    return next(line for line in code.splitlines() if line.strip())


RUN = [block for block in blocks() if (block[0], first_line(block[2])) not in NOT_RUN]


def test_every_example_is_run_or_listed_with_its_reason():
    found = {(page, first_line(code)) for page, _, code in blocks()}
    assert set(NOT_RUN) <= found, f"NOT_RUN names blocks that no longer exist: {sorted(set(NOT_RUN) - found)}"
    assert len(RUN) == len(found) - len(NOT_RUN) and len(RUN) >= 8  # the examples are found, not lost


@pytest.mark.parametrize(("page", "line", "code"), RUN, ids=[f"{page}:{line}" for page, line, _ in RUN])
def test_the_example_runs(page, line, code, tmp_path):
    (tmp_path / "assets").symlink_to(ROOT / "assets")  # examples read assets/... as from a checkout
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    env.setdefault("MUJOCO_GL", "egl")  # the arena example renders its camera headless
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, f"{page}:{line} failed:\n{done.stderr[-3000:]}"
