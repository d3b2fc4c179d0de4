"""Damaged stored trials: every bad line is moved to ``*.rejected`` with a warning naming it, never mixed in; its
trial runs again, so the resumed run equals a fresh one."""

import numpy as np
import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

AGENTS = ("bayes", "random")


def config(**changes) -> SweepConfig:
    fields = {"domain": "guess", "backend": "abstract", "options": {"task": None}, "agents": AGENTS, "episodes": 6,
              "seed": 11}  # fmt: skip
    fields.update(changes)
    return SweepConfig(**fields)


@pytest.fixture()
def fresh(tmp_path):
    result = run_sweep(config(), out=tmp_path / "fresh")
    return result, tmp_path / "fresh"


def sorted_lines(path):
    header, *rows = path.read_text().splitlines()
    return header, sorted(rows)


def stored_copy(tmp_path, fresh_folder):
    out = tmp_path / "run"
    run_sweep(config(), out=out)
    assert sorted_lines(out / "trials.csv") == sorted_lines(fresh_folder / "trials.csv")
    return out


def edit_cell(path, row: int, column: str, change) -> list[str]:
    """Replace one cell of data row ``row`` (0 = the first after the header) by ``change(old)``; the row's values."""
    header, *rows = path.read_text().splitlines()
    values = rows[row].split(",")
    index = header.split(",").index(column)
    values[index] = change(values[index])
    rows[row] = ",".join(values)
    path.write_text("\n".join([header, *rows]) + "\n")
    return values


def resume_equals_fresh(out, fresh_result, fresh_folder, rerun: int):
    resumed = run_sweep(config(), out=out)
    assert resumed.new_trials == rerun
    for name in ("trials.csv", "steps.csv"):
        assert sorted_lines(out / name) == sorted_lines(fresh_folder / name)
    assert resumed.summary() == fresh_result.summary()


def test_random_bytes_appended_are_quarantined_not_a_traceback(tmp_path, fresh, capsys):
    result, folder = fresh
    out = stored_copy(tmp_path, folder)
    trials = out / "trials.csv"
    lines_before = len(trials.read_bytes().split(b"\n")) - 1
    garbage = np.random.default_rng(64).integers(0, 256, size=64, dtype=np.uint8).tobytes()
    trials.write_bytes(trials.read_bytes() + garbage)
    capsys.readouterr()
    resume_equals_fresh(out, result, folder, rerun=0)
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warnings and all("trials.csv.rejected" in line for line in warnings)
    assert f"trials.csv:{lines_before + 1}:" in warnings[0]
    assert (out / "trials.csv.rejected").read_bytes().rstrip(b"\n") == garbage.rstrip(b"\n")


def test_an_edited_value_is_detected_by_the_row_check(tmp_path, fresh, capsys):
    result, folder = fresh
    out = stored_copy(tmp_path, folder)
    values = edit_cell(out / "trials.csv", 2, "steps", lambda old: str(int(old) + 66))  # e.g. 11 -> 77
    capsys.readouterr()
    resume_equals_fresh(out, result, folder, rerun=1)
    err = capsys.readouterr().err
    assert "trials.csv:4:" in err and "changed (check)" in err and "Traceback" not in err
    assert (out / "trials.csv.rejected").read_text().splitlines() == [",".join(values)]
    moved = (out / "steps.csv.rejected").read_text().splitlines()  # its steps rows went with it
    agent, episode = values[0], values[1]
    assert moved and all(line.startswith(f"{agent},{episode},") for line in moved)


def test_an_edited_steps_row_rejects_its_trial(tmp_path, fresh, capsys):
    result, folder = fresh
    out = stored_copy(tmp_path, folder)
    edit_cell(out / "steps.csv", 5, "reward", lambda old: "-7.0" if old != "-7.0" else "-8.0")
    capsys.readouterr()
    resume_equals_fresh(out, result, folder, rerun=1)
    assert "changed (check)" in capsys.readouterr().err


@pytest.mark.parametrize(
    "damage, reason",
    [
        (lambda values, column: values.__setitem__(column, "eleven"), "field 'steps'"),
        (lambda values, column: values.append("extra"), "fields, expected"),
    ],
)
def test_a_row_that_fails_validation_is_quarantined(tmp_path, fresh, capsys, damage, reason):
    result, folder = fresh
    out = stored_copy(tmp_path, folder)
    trials = out / "trials.csv"
    header, *rows = trials.read_text().splitlines()
    values = rows[0].split(",")
    damage(values, header.split(",").index("steps"))
    rows[0] = ",".join(values)
    trials.write_text("\n".join([header, *rows]) + "\n")
    capsys.readouterr()
    resume_equals_fresh(out, result, folder, rerun=1)
    err = capsys.readouterr().err
    assert "trials.csv:2:" in err and reason in err


def test_undecodable_bytes_inside_the_file_reject_that_line_only(tmp_path, fresh, capsys):
    result, folder = fresh
    out = stored_copy(tmp_path, folder)
    steps = out / "steps.csv"
    lines = steps.read_bytes().split(b"\n")
    lines[3] = lines[3][:4] + b"\xff\xfe" + lines[3][4:]
    steps.write_bytes(b"\n".join(lines))
    capsys.readouterr()
    resume_equals_fresh(out, result, folder, rerun=1)
    err = capsys.readouterr().err
    assert "steps.csv:4: undecodable" in err


def test_a_trial_listed_twice_is_rerun_once(tmp_path, fresh, capsys):
    result, folder = fresh
    out = stored_copy(tmp_path, folder)
    trials = out / "trials.csv"
    text = trials.read_text()
    trials.write_text(text + text.splitlines()[1] + "\n")
    steps = out / "steps.csv"
    steps.write_text(steps.read_text())
    resume_equals_fresh(out, result, folder, rerun=1)
    assert "listed twice" in capsys.readouterr().err


def test_a_foreign_header_is_refused(tmp_path):
    out = tmp_path / "run"
    run_sweep(config(episodes=1), out=out)
    trials = out / "trials.csv"
    trials.write_text(trials.read_text().replace("check", "checksum", 1))
    with pytest.raises(ConfigError, match=r"trials.csv:1: columns .* --new-run"):
        run_sweep(config(episodes=1), out=out)
