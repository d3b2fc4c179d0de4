"""`embodied-adhoc envs` lists every id of the one registry, as text and JSON."""

import json
import subprocess
import sys

from embodied_adhoc.envs.registry import ENV_SPECS


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_envs_json_lists_every_registered_id():
    result = run_cli("envs", "--json")
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)["envs"]
    assert [row["id"] for row in rows] == [spec.id for spec in ENV_SPECS]
    for row in rows:
        assert row["backend"] in ("abstract", "mujoco") and row["description"]


def test_envs_text_table_has_ids_and_descriptions():
    result = run_cli("envs")
    assert result.returncode == 0, result.stderr
    for spec in ENV_SPECS:
        assert spec.id in result.stdout and spec.description in result.stdout


def test_every_registered_id_is_known_to_gymnasium():
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers)

    for spec in ENV_SPECS:
        assert spec.id in gymnasium.registry


def test_both_toxic_waste_backends_are_listed():
    rows = json.loads(run_cli("envs", "--json").stdout)["envs"]
    backends = {row["id"]: row["backend"] for row in rows}
    assert backends["EmbodiedAdhoc/ToxicWaste-v0"] == "mujoco"
    assert backends["EmbodiedAdhoc/ToxicWasteAbstract-v0"] == "abstract"
