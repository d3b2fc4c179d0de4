"""``embodied-adhoc trials`` through a subprocess, as a user runs it."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
# Run the real CLI with the test-only 'guess' domain registered first.
LAUNCHER = (
    "import sys; sys.path.insert(0, sys.argv.pop(1));"
    "from embodied_adhoc.experiments.registry import register_trial_domain;"
    "register_trial_domain('guess', 'fake_trial_domain:DOMAIN');"
    "from embodied_adhoc.cli import main; sys.exit(main(sys.argv[1:]))"
)


def trials(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", LAUNCHER, str(HERE), "trials", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_json_output_is_exactly_the_summary_document(tmp_path):
    result = trials("guess", "--agents", "bayes,random", "--episodes", "6", "--seed", "2", "--json")
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert set(document) == {"agents", "comparisons", "statistics", "config"}
    assert set(document["agents"]) == {"bayes", "random"}
    for summary in document["agents"].values():
        assert {"steps_mean", "steps_ci95", "steps_iqm", "success_rate", "identify_steps_mean"} <= set(
            summary
        )
    assert document["comparisons"][0]["a"] == "bayes" and document["comparisons"][0]["b"] == "random"
    assert "p_improvement" in document["comparisons"][0]


def test_table_files_plots_and_resume(tmp_path):
    out = tmp_path / "run"
    first = trials("guess", "--agents", "bayes,random", "--episodes", "4", "--out", str(out))
    assert first.returncode == 0, first.stderr
    assert "steps mean ± sd" in first.stdout and "Welch t" in first.stdout
    assert "95% CI (bootstrap)" in first.stdout and "P(a fewer steps)" in first.stdout
    expected = {"config.json", "trials.csv", "steps.csv", "summary.json", "steps.png", "entropy.png"}
    assert expected <= {p.name for p in out.iterdir()}
    second = trials(
        "guess", "--agents", "bayes,random", "--episodes", "6", "--out", str(out), "--workers", "2"
    )
    assert second.returncode == 0, second.stderr
    assert "4 trial(s) run" in second.stdout and "8 resumed" in second.stdout
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 12


def test_bad_input_is_one_line_exit_2(tmp_path):
    result = trials("guess", "--agents", "bayes,nobody", "--episodes", "2")
    assert result.returncode == 2
    assert result.stderr.startswith("embodied-adhoc: error: unknown agent")
    assert "Traceback" not in result.stderr
    trials("guess", "--agents", "bayes", "--episodes", "1", "--out", str(tmp_path))
    clash = trials("guess", "--agents", "bayes", "--episodes", "1", "--out", str(tmp_path), "--seed", "9")
    assert clash.returncode == 2 and "different run" in clash.stderr


def test_bare_group_prints_help():
    result = trials()
    assert result.returncode == 2
    assert "toxic-waste" in result.stdout and "guess" in result.stdout


@pytest.mark.parametrize("domain", ["toxic-waste"])
def test_domain_help(domain):
    result = trials(domain, "--help")
    assert result.returncode == 0 and "--backend" in result.stdout and "--human-epsilon" in result.stdout


def test_backend_comparison_runs_the_same_episodes_on_each(tmp_path):
    result = trials(
        "guess",
        "--backend",
        "abstract,twin",
        "--agents",
        "bayes,random",
        "--episodes",
        "5",
        "--json",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert set(document) == {"backends", "backend_comparisons", "statistics"}
    assert set(document["backends"]) == {"abstract", "twin"}
    # the twin backend is the same env: same episodes and seeds give the same trials
    assert document["backends"]["abstract"]["agents"] == document["backends"]["twin"]["agents"]
    assert [(t["a"], t["b"]) for t in document["backend_comparisons"]] == [
        ("bayes (abstract)", "bayes (twin)"),
        ("random (abstract)", "random (twin)"),
    ]
    assert {"abstract", "twin", "comparison.json", "backends.png"} <= {p.name for p in tmp_path.iterdir()}
    bad = trials("guess", "--backend", "abstract,mujoco", "--episodes", "1")
    assert bad.returncode == 2 and "choose one or more" in bad.stderr
