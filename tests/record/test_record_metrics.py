"""metrics.json: required fields, Metric 2 via the shared statistics helper, atomic write."""

import json

import numpy as np

from embodied_adhoc.experiments.stats import identify_step
from embodied_adhoc.record.metrics import EpisodeMetrics


def test_metrics_json_fields_and_identify_step(tmp_path):
    metrics = EpisodeMetrics(config={"agent": "hotspot", "seed": 0}, true_task=1, identify=identify_step)
    metrics.start_episode(np.array([0.5, 0.5]))
    posteriors = [[0.6, 0.4], [0.4, 0.6], [0.2, 0.8], [0.1, 0.9]]
    for step, posterior in enumerate(posteriors):
        metrics.start_step()
        metrics.end_step(
            action=step % 5,
            observation=f"z{step}",
            reward=-3.0,
            sim_time_s=2.0 * (step + 1),
            task_posterior=np.array(posterior),
            entropy=0.5,
        )
    metrics.finish(success=True, truncated=False)
    path = metrics.write(tmp_path / "run" / "metrics.json")
    payload = json.loads(path.read_text())
    assert payload["success"] is True and payload["outcome"] == "success"
    assert payload["steps"] == 4
    assert payload["identify_step"] == 2  # true task leads from the 2nd posterior on
    assert payload["sim_time_s"] == 8.0
    assert payload["macro_step_time_s"]["mean"] is not None
    assert [record["observation"] for record in payload["per_step"]] == ["z0", "z1", "z2", "z3"]
    assert list(path.parent.iterdir()) == [path]


def test_never_identified_and_truncated(tmp_path):
    metrics = EpisodeMetrics(true_task=0, identify=identify_step)
    metrics.start_episode(np.array([0.5, 0.5]))
    metrics.start_step()
    metrics.end_step(0, "z", -1.0, 1.0, np.array([0.3, 0.7]), 0.9)
    metrics.finish(success=False, truncated=True)
    payload = metrics.summary()
    assert payload["identify_step"] is None and payload["outcome"] == "truncated" and not payload["success"]


def test_without_an_identify_rule_the_step_is_null():
    metrics = EpisodeMetrics(true_task=0)
    metrics.start_episode(np.array([0.5, 0.5]))
    metrics.start_step()
    metrics.end_step(0, "z", -1.0, 1.0, np.array([0.9, 0.1]), 0.5)
    assert metrics.summary()["identify_step"] is None
