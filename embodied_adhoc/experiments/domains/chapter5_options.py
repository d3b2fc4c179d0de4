"""Command-line options of the chapter-5 libraries, shared by ``pomdp export`` and ``trials`` (argparse only, so
``--help`` stays light). :func:`library_options` turns the parsed flags into the JSON-able keyword arguments of
:func:`embodied_adhoc.domains.chapter5.build_library` for one domain (flags a domain does not use are refused)."""

from __future__ import annotations

import argparse

from embodied_adhoc.errors import ConfigError

__all__ = ["add_library_arguments", "library_options"]

# domain -> the flags (dest names) it accepts
_ACCEPTED = {
    "panic-buttons": {"size", "teammate"},
    "gridworld": {"size", "models", "noise", "task_seed"},
    "pursuit-task": {"noise"},
    "pursuit-teammate": {"noise"},
    "pursuit-both": {"noise"},
    "power-plant": {"noise"},
    "overcooked": {"bug_compatible"},
    "map": {"map", "noise", "models"},
}
for _name in ("ntu", "isr", "mit", "pentagon", "cit"):
    _ACCEPTED[_name] = {"noise", "models", "bug_compatible"}
_FLAGS = {
    "size": "--size",
    "teammate": "--teammate",
    "models": "--models",
    "noise": "--noise",
    "task_seed": "--task-seed",
    "bug_compatible": "--bug-compatible",
    "map": "--map",
}


def add_library_arguments(parser: argparse.ArgumentParser, domain: str | None = None) -> None:
    """The model flags (of ``domain`` only, or of every domain when None)."""
    accepted = set().union(*_ACCEPTED.values()) if domain is None else _ACCEPTED[domain]
    group = parser.add_argument_group("model options")
    if "map" in accepted:
        group.add_argument(
            "--map",
            default=None,
            metavar="PATH",
            help="map file: '#' blocked, '.' open, 'S' start, 'G' goal (domain map); each pair of 'G' cells is "
            "one task, so n goals give n(n-1)/2 tasks (two give a single task: nothing to identify)",
        )
    if "size" in accepted:
        group.add_argument(
            "--size", type=int, default=None, help="grid side (panic buttons 3/4/5, default 3; gridworld 5)"
        )
    if "teammate" in accepted:
        group.add_argument(
            "--teammate",
            default=None,
            metavar="NAME",
            help="panic buttons teammate: optimal (default), suboptimal (fails to act w.p. 0.3), random",
        )
    if "models" in accepted:
        group.add_argument(
            "--models", type=int, default=None, metavar="K", help="library size |M| (default: Table 5.2's)"
        )
    if "noise" in accepted:
        group.add_argument(
            "--noise", type=float, default=None, metavar="EPS", help="noise eps (default: Table 5.2's)"
        )
    if "task_seed" in accepted:
        group.add_argument(
            "--task-seed", type=int, default=None, help="gridworld: seed of the goal-pair draw (default 0)"
        )
    if "bug_compatible" in accepted:
        group.add_argument(
            "--bug-compatible",
            action="store_true",
            help="rebuild the original's model bug (maps: goal layout, ntu/mit tasks identical; overcooked: the "
            "stubborn cook's 50 %% frozen coin instead of 90 %%)",
        )


def library_options(domain: str, args: argparse.Namespace, ignore: tuple[str, ...] = ()) -> dict:
    """The ``build_library`` keyword arguments of ``domain`` from parsed flags; ConfigError on a foreign flag.
    ``ignore``: flags (dest names) that the caller owns for this domain (trials' ``--teammate MODULE:CALLABLE``)."""
    if domain not in _ACCEPTED:
        raise ConfigError(f"unknown chapter-5 domain {domain!r}; choose from {', '.join(_ACCEPTED)}")
    options = {}
    for dest, flag in _FLAGS.items():
        value = getattr(args, dest, None)
        if value is None or value is False or (dest in ignore and dest not in _ACCEPTED[domain]):
            continue
        if dest not in _ACCEPTED[domain]:
            raise ConfigError(f"{flag} does not apply to domain {domain}; its flags: {_flag_list(domain)}")
        options[{"models": "n_models"}.get(dest, dest)] = value
    if domain == "map" and "map" not in options:
        raise ConfigError("domain map needs --map PATH ('#' blocked, '.' open, 'S' start, 'G' goal)")
    if domain == "panic-buttons":
        options.setdefault("size", 3)
        options.setdefault("teammate", "optimal")
    return options


def _flag_list(domain: str) -> str:
    return ", ".join(_FLAGS[d] for d in _FLAGS if d in _ACCEPTED[domain]) or "none"
