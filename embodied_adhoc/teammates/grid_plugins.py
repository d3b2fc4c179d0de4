"""User teammates on the grid arenas (foraging, pursuit): a team named by a plug-in spec instead of ``tau0``.

A grid team plug-in (kind ``teammate`` of :mod:`embodied_adhoc.plugins`) is ``factory(rules)`` returning either

* a :class:`~embodied_adhoc.domains.grid_rules_team.TeamSpec` (the scripted planner's parameters: target, slot,
  goal, navigation), or
* a policy object with ``actions(state, task, rng, members) -> array of ints``: the actions of the listed team
  ``members`` (indices into the agents) in ``state`` (a ``GridState``: ``agents`` cells, ``targets`` cells and
  levels, ``alive``) for ``task`` (its ``offsets`` around the target), drawing any randomness from ``rng`` (the
  env's generator, so an episode is reproducible from its seed).

Actions index ``domains.grid_rules.ACTION_NAMES`` (up, down, left, right, interact). In the joint action the ad hoc
agent is index 0 and teammate ``i`` is index ``i`` (``1 .. n_agents - 1``); the env asks for members ``1..N-1``.
"""

from __future__ import annotations

from embodied_adhoc.domains.grid_rules_team import TeamSpec
from embodied_adhoc.errors import ConfigError

__all__ = ["with_plugin_teams"]


def with_plugin_teams(library: dict, chosen, rules) -> dict:
    """``library`` (team name -> TeamSpec) plus every plug-in spec in ``chosen`` (names or specs), built with
    ``rules``; names keep their library entry."""
    from embodied_adhoc.plugins import names_plugin, resolve

    if isinstance(chosen, str):
        items = [chosen]
    elif isinstance(chosen, (list, tuple)):
        items = list(chosen)
    else:  # None (the whole library) or a value the env's own check refuses
        return library
    specs = [
        item
        for item in items
        if isinstance(item, str) and item not in library and names_plugin("teammate", item)
    ]
    if not specs:
        return library
    teams = dict(library)
    for spec in specs:
        plugin = resolve("teammate", spec, builtin=tuple(library), flag="teams")
        team = plugin.factory(rules)
        if not isinstance(team, TeamSpec) and not callable(getattr(team, "actions", None)):
            raise ConfigError(
                f"team {spec!r}: factory(rules) returned {type(team).__name__}; return a TeamSpec or an object "
                "with actions(state, task, rng, members) (see embodied_adhoc.teammates.grid_plugins)"
            )
        teams[spec] = team
    return teams
