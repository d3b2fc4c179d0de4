"""The chapter-5 domains' benchmark teammates: ``--teammate`` plug-ins (``domains.chapter5.teammates``).

A member is ``factory(library, m)`` returning the teammate's policy ``pi(b | x)`` (S x B) in model ``m``'s task,
built from its :class:`~embodied_adhoc.teammates.populations.TeammateSpec` parameters (``family``):

* ``named``: a teammate of the thesis: the library's own (``greedy``; pursuit's ``aware``; overcooked's cooks) or
  ``optimal`` (the MMDP's optimal marginal, ``domains.chapter5.library.optimal_teammate_policy``: the maps' and the
  power plant's own teammate);
* ``softmax``: softmax-rational over the task's Q-values, ``pi(b | x) ∝ exp(Q(x, b) / temperature)`` with
  ``Q(x, b) = max_a Q*(x, (a, b))`` of the task's MMDP (the teammate expects the agent to play its part);
* ``epsilon``: the ``base`` teammate, with probability ``epsilon`` a uniformly drawn action instead;
* ``lazy``: the ``base`` teammate, with probability ``p`` the stay action instead (``stay``; overcooked's ``noop``;
  the power plant's human staying in its room);
* ``goal-mix``: each step, with probability ``other`` the ``base`` teammate of the next task's goal (the first model
  after ``m``, cyclically, with other rewards on the same states), else its own: a teammate the library does not
  hold (``other = 1``: it pursues another goal); refused where no other task shares the states (the power plant's
  tasks have their own, pursuit-teammate's and overcooked's models differ in the teammate only);
* ``mix``: each step one of the library's ``teammates`` drawn with the given ``weights`` (a mixed team).

``base`` defaults to the library's ``greedy`` teammate where it has one, else ``optimal``.

Every policy is a function of the state, so the world's model (Fig. 5.2's reduction) is exact and its best
response is value iteration (:mod:`embodied_adhoc.bench.bounds`). A plug-in spec
``embodied_adhoc.teammates.chapter5_members:<domain>/<member name>`` names a member.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.errors import ConfigError

__all__ = ["FAMILIES", "Chapter5MemberFactory"]

FAMILIES = ("named", "softmax", "epsilon", "lazy", "goal-mix", "mix")
STAY_NAMES = ("stay", "noop")


def _n_teammate(library, m: int) -> int:
    return library.mmdps[m].n_actions // library.n_actions


def _named(library, m: int, name: str) -> np.ndarray:
    from embodied_adhoc.domains.chapter5.library import optimal_teammate_policy

    if name in library.teammates:
        return np.asarray(library.teammates[name](m), dtype=np.float64)
    if name == "optimal":
        return optimal_teammate_policy(library.mmdps[m], library.n_actions)
    raise ConfigError(
        f"benchmark teammate base {name!r}: {library.domain} has {', '.join(library.teammates) or 'none'} "
        "and 'optimal'"
    )


def _softmax(library, m: int, temperature: float) -> np.ndarray:
    from embodied_adhoc.decision.value_iteration import value_iteration

    mmdp = library.mmdps[m]
    q = value_iteration(mmdp, tolerance=1e-8).q_values
    per_teammate = q.reshape(mmdp.n_states, library.n_actions, _n_teammate(library, m)).max(axis=1)
    logits = (per_teammate - per_teammate.max(axis=1, keepdims=True)) / temperature
    weights = np.exp(logits)
    return weights / weights.sum(axis=1, keepdims=True)


def default_base(library) -> str:
    """The teammate the parametric families perturb: the library's ``greedy`` where it has one, else ``optimal``
    (the teammate the maps' and the power plant's models hold)."""
    return "greedy" if "greedy" in library.teammates else "optimal"


def _stay(library, m: int) -> int:
    """The teammate's stay action: by name where the joint actions are named ``agent-teammate``, the power plant's
    human's after its moves."""
    if library.domain == "power-plant":
        from embodied_adhoc.domains.chapter5.power_plant import N_MOVES

        return N_MOVES  # the human's actions are its moves, then staying in its room
    mmdp = library.mmdps[m]
    names = getattr(mmdp, "action_names", None) or ()
    first = library.pomdps[m].action_names[0] + "-"
    own = [name[len(first) :] for name in names[: _n_teammate(library, m)] if name.startswith(first)]
    for stay in STAY_NAMES:
        if stay in own:
            return own.index(stay)
    raise ConfigError(
        f"benchmark family 'lazy' needs a teammate stay action ({'/'.join(STAY_NAMES)}) in {library.domain}"
    )


def other_task(library, m: int) -> int | None:
    """The first model after ``m`` (cyclically) with other rewards on the same states: the next task's goal; None
    where there is none."""
    models = library.native_pomdps or library.pomdps
    for step in range(1, library.n_models):
        k = (m + step) % library.n_models
        if models[k].n_states == models[m].n_states and not np.array_equal(
            library.mmdps[k].rewards, library.mmdps[m].rewards
        ):
            return k
    return None


class Chapter5MemberFactory:
    """``factory(library, m) -> pi (S x B)`` of one member (the chapter-5 teammate plug-in interface)."""

    def __init__(self, name: str, params: dict) -> None:
        self.name = name
        self.params = dict(params)
        family = self.params.get("family")
        if family not in FAMILIES:
            raise ConfigError(
                f"benchmark teammate {name}: family {family!r}; choose from {', '.join(FAMILIES)}"
            )

    def __call__(self, library, m: int) -> np.ndarray:
        params = self.params
        family = params["family"]
        if family == "named":
            return _named(library, m, params["teammate"])
        if family == "softmax":
            return _softmax(library, m, float(params["temperature"]))
        if family == "mix":
            weights = np.asarray(params["weights"], dtype=np.float64)
            policies = [_named(library, m, name) for name in params["teammates"]]
            return sum(w * policy for w, policy in zip(weights / weights.sum(), policies, strict=True))
        base_name = params.get("base") or default_base(library)
        base = _named(library, m, base_name)
        if family == "epsilon":
            epsilon = float(params["epsilon"])
            return (1.0 - epsilon) * base + epsilon / base.shape[1]
        if family == "lazy":
            stay = np.zeros_like(base)
            stay[:, _stay(library, m)] = 1.0
            return (1.0 - float(params["p"])) * base + float(params["p"]) * stay
        k = other_task(library, m)
        if k is None:
            raise ConfigError(
                f"benchmark teammate {self.name}: family 'goal-mix' needs another task on the same states; "
                f"{library.domain}'s models have none"
            )
        other = float(params["other"])
        return (1.0 - other) * base + other * _named(library, k, base_name)

    def __repr__(self) -> str:
        return f"Chapter5MemberFactory({self.name!r})"


def __getattr__(name: str) -> Chapter5MemberFactory:
    """``embodied_adhoc.teammates.chapter5_members:<domain>/<member>``: the factory of that member (any split)."""
    from embodied_adhoc.teammates.populations import find_member

    domain, _, member = name.partition("/")  # the member, or SUITE/NAME of a population file
    spec = find_member(domain, member) if member else None
    if spec is None:
        raise AttributeError(name)
    return Chapter5MemberFactory(spec.name, spec.params)
