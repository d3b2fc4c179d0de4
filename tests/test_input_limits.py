"""Inputs whose size drives memory are refused against a documented limit before anything of that size exists.

Each case runs the real command (or ``gymnasium.make``) in a subprocess whose address space is capped at 2 GiB
(``RLIMIT_AS``): a check that came after the allocation would die with a MemoryError traceback or be killed,
not exit 2 with one line naming the file and the field. That nothing started is read from the output: no
stdout, no progress bar, no result folder.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap

import pytest

ADDRESS_SPACE = 2 << 30


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def run_limited(*args: str, code: str | None = None, cwd=None) -> subprocess.CompletedProcess:
    """The CLI with ``args`` (or ``python -c code``) under the 2 GiB address-space cap."""
    command = (
        [sys.executable, "-c", code]
        if code is not None
        else [sys.executable, "-m", "embodied_adhoc.cli", *args]
    )
    environment = {**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    return subprocess.run(
        command, capture_output=True, text=True, timeout=300, preexec_fn=_limited, env=environment, cwd=cwd
    )


def assert_refused(result: subprocess.CompletedProcess, *names: str) -> str:
    """Exit 2, nothing on stdout, one line on stderr that names each of ``names``; returns that line."""
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr[-2000:]
    assert "Traceback" not in result.stderr and "MemoryError" not in result.stderr
    for name in names:
        assert name in lines[0], (name, lines[0])
    return lines[0]


def test_the_cap_is_tight_enough_to_catch_a_late_check():
    """The 2 GiB cap stops an allocation the size of the refused inputs' (here 4 GiB of float64)."""
    result = run_limited(code="import numpy as np; np.ones(1 << 29)")
    assert result.returncode != 0 and "MemoryError" in result.stderr


def test_a_long_map_is_refused_before_the_library_is_built(tmp_path):
    path = tmp_path / "long.txt"
    rows = ["S" + "." * 9998 + "G", "S" + "." * 9998 + "G", "." * 10_000]  # 3 x 10,000 cells, 30 kB
    path.write_text("\n".join(rows) + "\n")
    out = tmp_path / "runs"
    result = run_limited("trials", "map", "--map", str(path), "--out", str(out))
    line = assert_refused(result, str(path), "30,000 cells", "10,000")
    assert "smaller map" in line
    assert not out.exists()


def test_a_map_with_too_many_open_cells_is_refused_with_its_state_count(tmp_path):
    """Within the grid limit but 400 open cells: 159,601 pair states, over the domain's 150-cell limit."""
    path = tmp_path / "wide.txt"
    path.write_text("\n".join(["S" + "." * 98 + "G"] * 2 + ["." * 100] * 2) + "\n")
    result = run_limited("pomdp", "export", "map", "--map", str(path), "--out", str(tmp_path / "x"))
    assert_refused(result, str(path), "400 open cells", "159,601 states", "150")


def test_a_huge_map_file_is_read_up_to_the_cap_only(tmp_path):
    path = tmp_path / "huge.txt"
    with path.open("w") as stream:  # 16 MiB without a newline: read whole, it would be one 16 M-cell row
        stream.truncate(16 << 20)
    out = tmp_path / "runs"
    result = run_limited("trials", "map", "--map", str(path), "--out", str(out))
    assert_refused(result, str(path), "1,048,576")
    assert not out.exists()


def test_toxic_waste_tasks_are_refused_by_length_before_any_element_is_read():
    code = textwrap.dedent(
        """
        import gymnasium
        import embodied_adhoc.envs
        from embodied_adhoc.errors import ConfigError
        for tasks in ([[0] * 10**6], [[0, 1, 2]] * 10**5):
            try:
                gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", tasks=tasks)
            except ConfigError as error:
                print(error)
        """
    )
    result = run_limited(code=code)
    assert result.returncode == 0, result.stderr[-2000:]
    balls, placements = result.stdout.strip().splitlines()
    assert balls.startswith("tasks[0]: 1000000 balls") and "200,000" in balls
    assert placements.startswith("tasks: 100000 ball placements") and "at most 64" in placements


def test_the_largest_accepted_tasks_still_build():
    """The limit leaves room: 7 balls on the 5-node lab (109,350 candidate states) build the library."""
    from embodied_adhoc.domains.lab import LabConfig, library_from_config

    library = library_from_config(LabConfig(tasks=((0, 1, 2, 3, 4, 0, 1),)))
    assert library.n_tasks == 1 and len(library.tasks[0]) == 7


HEADER = "discount: 0.95\nvalues: reward\nstates: {states}\nactions: {actions}\nobservations: 2\n"


@pytest.mark.parametrize(
    ("states", "actions", "line"),
    [(10**9, 2, 3), (2, 10**9, 4)],
    ids=["1e9-states", "1e9-actions"],
)
def test_pomdp_header_counts_are_refused_at_their_line(tmp_path, states, actions, line):
    """A valid file (identity transitions, uniform observations) whose header alone needs more entries than
    the reader holds: refused at the header line, before the start belief or any index array exists."""
    path = tmp_path / "big.pomdp"
    path.write_text(
        HEADER.format(states=states, actions=actions) + "start: uniform\nT: * identity\nO: * uniform\n"
    )
    result = run_limited("pomdp", "info", str(path))
    assert_refused(result, f"{path}:{line}:", "10,000,000")


def test_a_belief_set_too_large_to_hold_is_refused_before_solving():
    result = run_limited("pomdp", "solve", "tiger.95.POMDP", "--beliefs", str(10**9))
    assert_refused(result, "--beliefs 1000000000", "100,000,000", "50000000 or fewer")


def test_a_pomdp_header_within_the_limit_still_reads(tmp_path):
    from embodied_adhoc.decision.pomdp_io import read_pomdp

    path = tmp_path / "ok.pomdp"
    path.write_text(
        HEADER.format(states=1000, actions=3)
        + "start: uniform\nT: * identity\nO: * uniform\nR: * : * : * : * 1\n"
    )
    pomdp = read_pomdp(path)
    assert (pomdp.n_states, pomdp.n_actions, pomdp.n_observations) == (1000, 3, 2)


@pytest.mark.parametrize("flag", ["--confusion", "--localisation-model"])
def test_run_reads_a_matrix_device_up_to_the_cap_only(flag):
    result = run_limited("run", "toxic-waste", flag, "/dev/zero", "--no-progress")
    assert_refused(result, "/dev/zero", "confusion matrix file", "1,048,576")


def _with_nan(source: str, target, row: int, column: int) -> None:
    document = json.loads(open(source, encoding="utf-8").read())
    document["matrix"][row][column] = float("nan")  # json writes NaN, which json.loads reads back
    target.write_text(json.dumps(document))


@pytest.mark.parametrize(
    ("flag", "asset"),
    [
        ("--confusion", "data/speech_confusion_measured.json"),
        ("--localisation-model", "data/localisation_confusion_measured.json"),
    ],
)
def test_a_nan_in_a_matrix_file_is_refused_at_load_naming_the_entry(tmp_path, flag, asset):
    from embodied_adhoc import paths

    path = tmp_path / "nan.json"
    _with_nan(str(paths.asset(asset)), path, 2, 1)
    out = tmp_path / "episode"
    result = run_limited("run", "toxic-waste", flag, str(path), "--no-progress", "--record", str(out))
    assert_refused(result, str(path), "field 'matrix'", "entry [2][1]", "nan")
    assert not out.exists()


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (lambda m: m[1].__setitem__(0, -0.1), "entry [1][0] is negative"),
        (lambda m: m[3].__setitem__(0, m[3][0] + 0.2), "row 3 sums to"),
        (lambda m: m[0].__setitem__(2, None), "entry [0][2] is nan"),
        (lambda m: m.__setitem__(4, m[4][:-1]), "must be 5 rows of 6 numbers"),
    ],
    ids=["negative", "unnormalised", "null", "ragged"],
)
def test_bad_confusion_matrices_are_refused_naming_file_and_field(tmp_path, change, expected):
    from embodied_adhoc import paths
    from embodied_adhoc.domains.confusion import load_confusion
    from embodied_adhoc.errors import ConfigError

    document = json.loads(paths.asset("data/speech_confusion_measured.json").read_text(encoding="utf-8"))
    change(document["matrix"])
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(document))
    with pytest.raises(ConfigError) as caught:
        load_confusion(path)
    assert str(caught.value).startswith(f"{path}: field 'matrix': ") and expected in str(caught.value)


def test_a_small_file_under_a_large_limit_reserves_its_own_size_only(tmp_path):
    import tracemalloc

    from embodied_adhoc.checks import read_text

    path = tmp_path / "model.pomdp"
    path.write_text("discount: 0.95\n" * 100)
    tracemalloc.start()
    try:
        assert read_text(path, 256 * 2**20, "POMDP file") == "discount: 0.95\n" * 100
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20  # a 1.5 kB file, not the 256 MiB a read up to the limit reserves
    fifo = tmp_path / "stream"
    os.mkfifo(fifo)  # no size to go by: still read up to the limit, and refused past it
    writer = subprocess.Popen([sys.executable, "-c", f"open({str(fifo)!r}, 'w').write('x' * 101)"])
    with pytest.raises(Exception, match="100-character limit"):
        read_text(fifo, 100, "POMDP file")
    writer.wait(timeout=30)
