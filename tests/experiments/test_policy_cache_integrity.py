"""Policy cache entries that do not load are solved again with one note, never a traceback; the key holds the
BLAS kernel class."""

import numpy as np
import pytest

from embodied_adhoc.decision.pomdp_io import read_pomdp
from embodied_adhoc.experiments import identity, policy_cache
from embodied_adhoc.paths import asset

SETTINGS = {"n_beliefs": 40, "max_iterations": 4, "seed": 0, "update": "perseus"}


@pytest.fixture()
def tiger(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return read_pomdp(asset("data/tiger.95.POMDP"))


def entry(pomdp):
    return policy_cache.cache_dir() / f"{policy_cache.cache_key(pomdp, SETTINGS)}.npz"


def foreign_policy(path, pomdp):
    """A valid policy file of another model: vectors over one state more."""
    from embodied_adhoc.decision.policy import AlphaVectorPolicy

    AlphaVectorPolicy(np.zeros((2, pomdp.n_states + 1)), np.array([0, 1])).save(path)


@pytest.mark.parametrize(
    "damage, what",
    [
        (
            lambda path, pomdp: path.write_bytes(path.read_bytes()[: path.stat().st_size // 2]),
            "does not load",
        ),
        (lambda path, pomdp: path.write_bytes(b""), "is empty"),
        (lambda path, pomdp: path.write_bytes(np.random.default_rng(3).bytes(300)), "does not load"),
        (lambda path, pomdp: np.savez(path.with_suffix(""), weights=np.ones(3)), "does not load"),
        (foreign_policy, "holds vectors over 3 states, the model has 2"),
    ],
    ids=["truncated", "empty", "random-bytes", "foreign-npz", "wrong-shape"],
)
def test_a_damaged_entry_is_solved_again_with_one_note(tiger, capsys, damage, what):
    solved, hit = policy_cache.solve_cached(tiger, SETTINGS)
    assert not hit and entry(tiger).is_file()
    assert policy_cache.solve_cached(tiger, SETTINGS)[1]  # an intact entry is served
    damage(entry(tiger), tiger)
    capsys.readouterr()
    again, hit = policy_cache.solve_cached(tiger, SETTINGS)
    err = capsys.readouterr().err
    assert not hit
    assert (
        err.count("\n") == 1 and f"policy cache entry {entry(tiger)} {what}" in err and "solving again" in err
    )
    np.testing.assert_array_equal(again.alphas, solved.alphas)
    reloaded, hit = policy_cache.solve_cached(tiger, SETTINGS)  # the entry was rewritten
    assert hit and np.array_equal(reloaded.alphas, solved.alphas)


def test_actions_outside_the_model_are_refused(tiger, capsys):
    from embodied_adhoc.decision.policy import AlphaVectorPolicy

    policy_cache.solve_cached(tiger, SETTINGS)
    AlphaVectorPolicy(np.zeros((1, tiger.n_states)), np.array([tiger.n_actions])).save(entry(tiger))
    _, hit = policy_cache.solve_cached(tiger, SETTINGS)
    assert not hit and "names actions outside" in capsys.readouterr().err


def test_the_key_holds_the_blas_kernel_class(tiger, monkeypatch):
    here = policy_cache.cache_key(tiger, SETTINGS)
    policy_cache.solve_cached(tiger, SETTINGS)
    monkeypatch.setattr(identity, "blas_kernel", lambda: "openblas:SomeOtherKernel")
    assert policy_cache.cache_key(tiger, SETTINGS) != here
    _, hit = policy_cache.solve_cached(tiger, SETTINGS)
    assert not hit  # a cache filled on one kernel does not serve another
