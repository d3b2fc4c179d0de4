"""The chapter-5 worlds' teammates: by name (``optimal``, ``random`` and each library's own teammate models) or
as a plug-in (``module:callable``, ``path/to/file.py:callable``, an installed ``embodied_adhoc.teammates`` entry
point), and the library's models with the world's teammate replaced (Fig. 5.2's reduction).

A teammate is ``CALLABLE(library, m)`` returning ``pi(b | x)``, an (S x B) array for model ``m`` (S the states of
its MMDP, B the teammate's actions); in the joint action ``a * B + b`` the agent's action ``a`` comes first."""

from __future__ import annotations

import numpy as np

from embodied_adhoc.errors import ConfigError

__all__ = [
    "DOMAIN_TEAMMATES",
    "GENERIC_HELP",
    "NAMED_TEAMMATES",
    "TEAMMATE_HELP",
    "world_teammate_names",
    "world_with_teammate",
]


NAMED_TEAMMATES = ("optimal", "random")
"""World teammates by name in every domain: ``optimal`` (the MMDP's optimal marginal,
``library.optimal_teammate_policy``) and ``random`` (uniform over its actions). A domain adds its own teammate
models (``ModelLibrary.teammates``), listed per domain in ``DOMAIN_TEAMMATES`` for ``--help`` (a test checks that
both agree)."""
DOMAIN_TEAMMATES = {
    "gridworld": ("greedy",),
    "pursuit-task": ("greedy", "aware"),
    "pursuit-teammate": ("greedy", "aware"),
    "pursuit-both": ("greedy", "aware"),
    "overcooked": ("optimal", "upper", "lower", "random"),
}
GENERIC_HELP = "optimal: the MMDP's; random: uniform"
TEAMMATE_HELP = {
    "gridworld": "greedy: to its closest goal cell, the library's; " + GENERIC_HELP,
    **dict.fromkeys(
        ("pursuit-task", "pursuit-teammate", "pursuit-both"),
        "greedy: columns then rows to its closest capture cell; aware: teammate-aware, a shortest path around "
        "the agent; " + GENERIC_HELP,
    ),
    "overcooked": "the library's four cooks: optimal; upper / lower: insists on the top / bottom counter w.p. "
    "0.9; random: uniform",
    "power-plant": "optimal: the library's human, the MMDP's; random: uniform over its moves and stay; a "
    "CALLABLE's S is the task's own states, 105 explore / 97 clean",
}


def world_teammate_names(domain_name: str) -> tuple[str, ...]:
    """The ``--teammate`` names of a domain: its own teammate models, then the generic ones."""
    own = DOMAIN_TEAMMATES.get(domain_name, ())
    return own + tuple(name for name in NAMED_TEAMMATES if name not in own)


def _named_teammate(name: str):
    from embodied_adhoc.domains.chapter5.library import optimal_teammate_policy

    def policy(library, model: int) -> np.ndarray:
        mmdp = library.mmdps[model]
        n_teammate = mmdp.n_actions // library.n_actions
        if name == "random":
            return np.full((mmdp.n_states, n_teammate), 1.0 / n_teammate)
        return optimal_teammate_policy(mmdp, library.n_actions)

    return policy


def world_with_teammate(library, reference: str) -> tuple:
    """The library's models with the teammate replaced by ``reference``: a name of ``NAMED_TEAMMATES`` or
    ``module:callable``, where ``CALLABLE(library, m)`` gives ``pi(b | x)`` (S x B, S the states of model ``m``'s
    MMDP) for model ``m``. Fig. 5.2's reduction turns it into the world's transitions (same rewards, observations
    and start). The power plant's tasks have their own state spaces (105 and 97 states): the reduction runs on the
    task's own model, which is then padded as the library's is."""
    from embodied_adhoc.decision.models import POMDP
    from embodied_adhoc.domains.chapter5.library import reduce_joint
    from embodied_adhoc.domains.chapter5.power_plant import pad_pomdp

    if reference in library.teammates:
        own = library.teammates[reference]

        def factory(_, m: int) -> np.ndarray:
            return own(m)
    elif reference in NAMED_TEAMMATES:
        factory = _named_teammate(reference)
    else:  # a plug-in: module:callable, path/to/file.py:callable or an embodied_adhoc.teammates entry point
        from embodied_adhoc.plugins import installed, is_plugin_spec, resolve

        names = (*library.teammates, *(n for n in NAMED_TEAMMATES if n not in library.teammates))
        if not is_plugin_spec(reference) and reference not in installed("teammate"):
            raise ConfigError(
                f"--teammate {reference!r}: unknown teammate of {library.domain}; give one of {', '.join(names)}, "
                "or MODULE:CALLABLE (e.g. my_teammates:cautious)"
            )
        factory = resolve("teammate", reference, builtin=names, flag="--teammate").factory
    world = []
    for m, pomdp in enumerate(library.native_pomdps or library.pomdps):
        mmdp = library.mmdps[m]
        n_teammate = mmdp.n_actions // pomdp.n_actions
        policy = np.asarray(factory(library, m), dtype=np.float64)
        if policy.shape != (pomdp.n_states, n_teammate):
            raise ConfigError(
                f"--teammate {reference}: returned shape {policy.shape} for model {m}; expected "
                f"({pomdp.n_states}, {n_teammate}) = (states, teammate actions)"
            )
        if policy.min() < 0.0 or not np.allclose(policy.sum(axis=1), 1.0, atol=1e-9):
            raise ConfigError(
                f"--teammate {reference}: model {m}: every row must be a probability distribution"
            )
        joint = [
            [mmdp.transitions[a * n_teammate + b] for b in range(n_teammate)] for a in range(pomdp.n_actions)
        ]
        model = POMDP(
            reduce_joint(joint, policy),
            pomdp.rewards,
            pomdp.discount,
            pomdp.state_names,
            pomdp.action_names,
            pomdp.observations,
            pomdp.initial_belief,
            pomdp.observation_names,
        )  # fmt: skip
        world.append(pad_pomdp(model, library.n_states))
    return tuple(world)
