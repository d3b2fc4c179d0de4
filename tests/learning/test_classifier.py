"""The recurrent Bayesian classifier (thesis Eq. 6.2) and its calibration."""

import numpy as np
import pytest
import torch

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.classifier import (
    ClassifierConfig,
    ClassifierTraining,
    RecurrentBayesianClassifier,
    Trajectories,
    expected_calibration_error,
    per_step_scores,
    train_classifier,
)

torch.set_num_threads(1)
K, STEPS, NONE = 3, 8, 5


def marked(row: int | None) -> np.ndarray:
    """A 2 x 5 x 5 observation: channel 0 lit at (row, 2) when ``row`` is given (a sign of environment ``row``),
    channel 1 a constant background."""
    observation = np.zeros((2, 5, 5), np.float32)
    observation[1] = 0.5
    if row is not None:
        observation[0, row, 2] = 1.0
    return observation


def synthetic(episodes: int, rng: np.random.Generator) -> Trajectories:
    """Environment k shows its sign (row k) on a random half of the steps and nothing otherwise; the actions are
    uniform and carry no information."""
    labels = rng.integers(0, K, episodes)
    observations = np.stack(
        [[marked(k if rng.random() < 0.5 else None) for _ in range(STEPS)] for k in labels]
    )
    previous = rng.integers(0, 5, (episodes, STEPS))
    previous[:, 0] = NONE
    return Trajectories(observations, previous, labels, np.full(episodes, STEPS))


def test_posterior_sums_to_one_and_moves_to_the_only_environment_that_explains_the_sequence():
    rng = np.random.default_rng(0)
    model = RecurrentBayesianClassifier(
        ClassifierConfig(channels=2, environments=K, features=16, hidden=16, hidden_channels=4)
    )
    losses = train_classifier(model, synthetic(192, rng), ClassifierTraining(iterations=150, batch_size=32))
    assert np.mean(losses[-20:]) < 0.5 * np.mean(losses[:20])
    sequence = [marked(None), marked(None), marked(2), marked(None), marked(2)]
    history, posteriors, action = None, [], None
    for observation in sequence:
        posterior, history = model.posterior_step(observation, action, history)
        posteriors.append(posterior)
        action = 1
    posteriors = np.array(posteriors)
    assert np.allclose(posteriors.sum(axis=1), 1.0)
    assert posteriors[1].max() < 0.6  # no sign yet: no environment is favoured
    assert (
        posteriors[2, 2] > posteriors[1, 2] + 0.3 and posteriors[-1].argmax() == 2 and posteriors[-1, 2] > 0.9
    )
    scores = per_step_scores(model, synthetic(60, np.random.default_rng(1)))
    assert len(scores) == STEPS and scores[-1]["accuracy"] > scores[0]["accuracy"]
    assert all(0.0 <= row["ece"] <= 1.0 for row in scores)


def test_expected_calibration_error():
    labels = np.array([0, 1, 0, 1])
    assert expected_calibration_error(np.eye(2)[labels], labels) == 0.0  # certain and right
    assert expected_calibration_error(np.eye(2)[1 - labels], labels) == 1.0  # certain and wrong
    half = np.full((4, 2), 0.5)
    assert expected_calibration_error(half, labels) == pytest.approx(0.0)  # argmax 0: right half the time
    overconfident = np.array([[0.9, 0.1]] * 4)
    assert expected_calibration_error(overconfident, labels) == pytest.approx(0.4)
    with pytest.raises(ConfigError):
        expected_calibration_error(np.zeros((0, 2)), np.zeros(0))
