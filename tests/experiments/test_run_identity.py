"""A run's identity by content: input files, plug-in sources and the BLAS kernel class; ``--new-run``."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments import identity
from embodied_adhoc.experiments.registry import register_trial_domain
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from fake_trial_domain import GuessDomain  # noqa: E402


class FileGuessDomain(GuessDomain):
    """The guess domain reading a data file (``options["data"]``) and declaring BLAS-dependent results."""

    name = "guess-file"
    blas_dependent = True

    def input_files(self, options):
        return {"--data": options["data"]}


register_trial_domain("guess-file", FileGuessDomain())


def config(data: Path, **changes) -> SweepConfig:
    fields = {"domain": "guess-file", "backend": "abstract", "options": {"task": None, "data": str(data)},
              "agents": ("bayes", "random"), "episodes": 3, "seed": 2}  # fmt: skip
    fields.update(changes)
    return SweepConfig(**fields)


def test_an_input_file_edited_in_place_is_refused_and_new_run_writes_a_sibling(tmp_path):
    data = tmp_path / "data.txt"
    data.write_text("goal 1\n")
    out = tmp_path / "run"
    first = run_sweep(config(data), out=out)
    assert first.out == out and first.new_trials == 6
    data.write_text("goal 2\n")  # same path, other content
    with pytest.raises(ConfigError, match=r"input --data: sha256 stored .* --new-run") as refused:
        run_sweep(config(data, episodes=6), out=out)
    assert "\n" not in str(refused.value)
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 6  # nothing was added
    sibling = run_sweep(config(data, episodes=6), out=out, new_run=True)
    assert sibling.out == tmp_path / "run-2" and sibling.new_trials == 12
    again = run_sweep(config(data, episodes=6), out=out, new_run=True)  # the sibling holding this run resumes
    assert again.out == tmp_path / "run-2" and again.new_trials == 0
    data.write_text("goal 1\n")  # back to the first content: the first folder resumes
    assert run_sweep(config(data, episodes=6), out=out).new_trials == 6


def test_another_blas_kernel_is_refused(tmp_path, monkeypatch):
    data = tmp_path / "data.txt"
    data.write_text("x\n")
    run_sweep(config(data), out=tmp_path / "run")
    stored = identity.blas_kernel()
    monkeypatch.setattr(identity, "blas_kernel", lambda: stored + "-other")
    with pytest.raises(ConfigError, match=r"blas_kernel: stored '.*', now '.*-other'"):
        run_sweep(config(data), out=tmp_path / "run")


def test_the_kernel_class_follows_openblas_coretype():
    code = "from embodied_adhoc.experiments.identity import blas_kernel; print(blas_kernel())"
    kernels = {}
    for coretype in ("Sandybridge", "Haswell"):
        environment = {**os.environ, "OPENBLAS_CORETYPE": coretype}
        kernels[coretype] = subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            env=environment,
            timeout=120,
            check=True,
        ).stdout.strip()
    assert kernels["Sandybridge"] == "openblas:Sandybridge"
    assert kernels["Haswell"] == "openblas:Haswell"


def test_folder_digests_and_plugin_sources(tmp_path, monkeypatch):
    library = tmp_path / "library"
    (library / "sub").mkdir(parents=True)
    (library / "a.json").write_text("{}")
    (library / "sub" / "b.npz").write_bytes(b"\x00\x01")
    before = identity.input_digest(library)
    (library / "sub" / "b.npz").write_bytes(b"\x00\x02")
    assert identity.input_digest(library) != before
    (library / "sub" / "b.npz").write_bytes(b"\x00\x01")
    assert identity.input_digest(library) == before
    module = tmp_path / "my_teammates.py"
    module.write_text("def cautious(library, m):\n    return None\n")
    assert identity.plugin_source("teammate", f"{module}:cautious") == module
    monkeypatch.chdir(tmp_path)  # module:callable imports from the current directory first
    assert identity.plugin_source("teammate", "my_teammates:cautious") == module
    assert identity.plugin_source("teammate", "optimal") is None
    assert identity.plugin_source("teammate", None) is None
    from embodied_adhoc.experiments.registry import get_trial_domain

    declared = get_trial_domain("pursuit-task").input_files(
        {"library": {}, "teammate": "my_teammates:cautious"}
    )
    assert declared == {"--teammate": module}
    assert identity.run_inputs(get_trial_domain("pursuit-task"), {"library": {}, "teammate": "greedy"}) == {
        "blas_kernel": identity.blas_kernel()
    }
    monkeypatch.setattr(identity, "MAX_INPUT_BYTES", 4096)
    with pytest.raises(ConfigError, match="larger than the 4,096-byte limit"):
        identity.input_digest("/dev/zero", "--confusion")
    with pytest.raises(ConfigError, match="--map .*: no such file"):
        identity.input_digest(tmp_path / "missing.txt", "--map")


def test_a_plugin_agent_whose_source_changes_is_refused(tmp_path):
    agent_file = tmp_path / "my_agent.py"
    source = (
        "from embodied_adhoc.decision.agents.base import AgentBase\n"
        "class Always(AgentBase):\n"
        "    observes_state = False\n"
        "    name = 'always'\n"
        "    task_posterior = None\n"
        "    def reset(self, rng, state=None):\n"
        "        pass\n"
        "    def act(self):\n"
        "        return {action}\n"
        "    def observe(self, action, observation, state=None):\n"
        "        pass\n"
        "def make(library, rng_seed=0):\n"
        "    return Always()\n"
    )
    agent_file.write_text(source.format(action=0))
    spec = f"{agent_file}:make"
    guess = SweepConfig("guess", "abstract", {"task": None}, ("bayes", spec), episodes=2, seed=1)
    assert run_sweep(guess, out=tmp_path / "run").new_trials == 4
    agent_file.write_text(source.format(action=1))
    with pytest.raises(ConfigError, match=r"agent .*my_agent.py:make: source sha256 stored"):
        run_sweep(guess, out=tmp_path / "run")
    # other agents may still join the run
    more = SweepConfig("guess", "abstract", {"task": None}, ("bayes", "random"), episodes=2, seed=1)
    assert run_sweep(more, out=tmp_path / "run").new_trials == 2


def trials_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "trials", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_cli_map_edited_in_place_is_one_line_exit_2_and_new_run_starts_a_sibling(tmp_path):
    from embodied_adhoc.paths import asset

    grid = tmp_path / "map.txt"
    grid.write_text(asset("maps/ntu.txt").read_text())
    out = tmp_path / "run"
    common = ("map", "--map", str(grid), "--agents", "random", "--out", str(out))
    first = trials_cli(*common, "--episodes", "2", "--json")
    assert first.returncode == 0, first.stderr
    rows = grid.read_text().splitlines()
    rows[1] = rows[1].replace("#G..G#", "#.G.G#")  # one goal moved a cell
    grid.write_text("\n".join(rows) + "\n")
    refused = trials_cli(*common, "--episodes", "4", "--json")
    assert refused.returncode == 2
    assert refused.stderr.count("\n") == 1 and "input --map: sha256 stored" in refused.stderr
    assert "Traceback" not in refused.stderr
    sibling = trials_cli(*common, "--episodes", "4", "--json", "--new-run")
    assert sibling.returncode == 0, sibling.stderr
    assert f"writing this one to {tmp_path / 'run-2'}" in sibling.stderr
    assert len((tmp_path / "run-2" / "trials.csv").read_text().splitlines()) == 1 + 4
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 2


def test_toxic_waste_confusion_file_edited_in_place_is_refused(tmp_path):
    import json

    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.paths import asset

    matrix = tmp_path / "confusion.json"
    matrix.write_text(asset("data/speech_confusion_measured.json").read_text())
    options = DOMAIN.options(confusion=str(matrix))
    sweep = SweepConfig("toxic-waste", "abstract", options, ("random",), episodes=2, seed=3)
    run_sweep(sweep, out=tmp_path / "run")
    document = json.loads(matrix.read_text())
    document["provenance"] = {"edited": True}  # any change of the bytes is a change of the input
    matrix.write_text(json.dumps(document))
    with pytest.raises(ConfigError, match="input --confusion: sha256 stored"):
        run_sweep(sweep, out=tmp_path / "run")
