"""Register the test-only 'guess' trial domain (tests/experiments/fake_trial_domain.py)."""

import pytest

from embodied_adhoc.experiments.registry import register_trial_domain


@pytest.fixture(autouse=True, scope="session")
def guess_domain():
    register_trial_domain("guess", "fake_trial_domain:DOMAIN")
    return "guess"
