"""Teammate populations of the benchmark, per domain, split into train, validation and held-out (fixed, versioned).

A member is a :class:`TeammateSpec`: its name, domain, split, a type label (what kind of teammate it is), the
parameters of its policy and the suite version it belongs to. ``spec.factory()`` builds the policy's factory
(the domain's teammate plug-in interface: a lab human ``factory(library, task)``, a chapter-5 teammate
``factory(library, m) -> pi``, a grid arena's team ``factory(rules)``); a member's behaviour is a function of its
parameters and of the generator the world hands it, so the same seed gives the same episode. ``spec.plugin`` is
the plug-in spec string that names it on ``--human`` / ``--teammate`` / ``--team``, and
:meth:`TeammateSpec.trial_options` the trial runner's options for it. A grid arena's learned members (recurrent
agents in a teammate seat) are torch code, above this layer: they are listed with their weights in the package's
data and named there by plug-in spec (:func:`_learned`).

* *train*: what libraries and learners may see (the thesis's teammates are here);
* *validation*: for tuning;
* *held-out*: reported results only.

The three are disjoint by name and by parameters (``tests/bench`` checks it). :data:`SUITE_VERSION` changes
whenever a member is added, removed or re-parameterised; results carry it. A user's own population, a JSON
file (:func:`load_population`), is a suite of its own.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from embodied_adhoc.domains.chapter5 import CHAPTER5_DOMAINS
from embodied_adhoc.errors import ConfigError

__all__ = [
    "BENCH_DOMAINS",
    "SPLITS",
    "SUITE_VERSION",
    "TeammateSpec",
    "find_member",
    "load_population",
    "members",
    "population",
]

SUITE_VERSION = "4"
SPLITS = ("train", "validation", "held-out")
LAB = "toxic-waste"
CHAPTER5 = tuple(d for d in CHAPTER5_DOMAINS if d not in ("panic-buttons", "map"))
GRID = ("foraging", "pursuit")
BENCH_DOMAINS = (LAB, *CHAPTER5, *GRID)
"""The domains with a population: the toxic-waste lab, the chapter-5 domains of Table 5.5 (not panic buttons,
whose library picks the teammate, nor a user's map file) and the grid arenas of level-based foraging and
predator-prey."""
_THESIS_TEAMMATES = {
    # the teammates the domain's own library holds (its train split); the maps' and the power plant's is the MMDP's
    # optimal teammate
    "pursuit-task": ("greedy",),
    "gridworld": ("greedy",),
    "pursuit-teammate": ("greedy", "aware"),
    "pursuit-both": ("greedy", "aware"),
    "overcooked": ("optimal", "upper", "lower", "random"),
}
_NO_OTHER_TASK = ("pursuit-teammate", "power-plant", "overcooked")
"""Domains without another task on the same states: no goal-switching member
(``chapter5_members.other_task``)."""
_MIXED_TEAMS = {
    "pursuit-teammate": ("greedy", "aware"),
    "pursuit-both": ("greedy", "aware"),
    "overcooked": ("upper", "lower"),
}
"""Domains whose library holds several teammates: a held-out member mixes two of them per step."""

_SUITE_SPLIT = {"train": "train", "validation": "validation", "heldout": "held-out", "held-out": "held-out"}


@dataclass(frozen=True)
class TeammateSpec:
    """One member of a population (see the module docstring); ``plugin_spec`` is set for a user's own member."""

    name: str
    domain: str
    split: str
    type_label: str
    params: dict = field(default_factory=dict)
    version: str = SUITE_VERSION
    plugin_spec: str | None = None

    @property
    def plugin(self) -> str:
        """The plug-in spec naming this member on ``--human`` (lab) or ``--teammate`` (chapter 5)."""
        if self.plugin_spec is not None:
            return self.plugin_spec
        where = self.name if self.split in SPLITS else f"{self.split}/{self.name}"  # a user's suite: its name
        if self.domain == LAB:
            return f"embodied_adhoc.teammates.lab_members:{where}"
        if self.domain in GRID:
            return f"embodied_adhoc.teammates.grid_members:{self.domain}/{where}"
        return f"embodied_adhoc.teammates.chapter5_members:{self.domain}/{where}"

    def factory(self):
        """The member's factory (the domain's teammate interface)."""
        if self.plugin_spec is not None:
            from embodied_adhoc.plugins import resolve

            kind = "human" if self.domain == LAB else "teammate"
            return resolve(kind, self.plugin_spec, flag=f"member {self.name}").factory
        if self.domain == LAB:
            from embodied_adhoc.teammates.lab_members import LabMemberFactory

            return LabMemberFactory(self.name, self.params)
        if self.domain in GRID:
            from embodied_adhoc.teammates.grid_members import GridMemberFactory

            return GridMemberFactory(self.name, self.params)
        from embodied_adhoc.teammates.chapter5_members import Chapter5MemberFactory

        return Chapter5MemberFactory(self.name, self.params)

    def trial_options(self, options: dict) -> dict:
        """The trial runner's ``options`` of the domain with this member as the world's teammate."""
        if self.domain in GRID:  # the arena's team, drawn for every episode
            return {**options, "teams": [self.plugin]}
        key = "human" if self.domain == LAB else "teammate"
        return {**options, key: self.plugin}

    def describe(self) -> dict:
        return {
            "name": self.name,
            "domain": self.domain,
            "split": self.split,
            "type": self.type_label,
            "params": dict(self.params),
            "version": self.version,
            **({"plugin": self.plugin_spec} if self.plugin_spec else {}),
        }


def _lab() -> tuple[TeammateSpec, ...]:
    def human(name, split, label, **params):
        return TeammateSpec(name, LAB, split, label, params)

    return (
        human("thesis", "train", "thesis cleaner (nearest ball first)", slow=0.05),
        human("order-021", "train", "task order not in the library", rule="order", order=[0, 2, 1]),
        human("wander-p10", "train", "epsilon-wanderer", wander=0.10),
        human("slow-p20", "train", "slow", slow=0.20),
        human("mislead-p20", "train", "answers 'where are you?' wrongly", mislead=0.20),
        human("drop-p10", "train", "drops a ball outside the container", drop=0.10),
        human("order-102", "validation", "task order not in the library", rule="order", order=[1, 0, 2]),
        human(
            "switch-1-order",
            "validation",
            "changes plan mid-episode",
            switch_after=1,
            then="order",
            order=[2, 1, 0],
        ),
        human("wander-p25", "validation", "epsilon-wanderer", wander=0.25),
        human("slow-p35", "validation", "slow", slow=0.35),
        human("quiet-p50", "validation", "does not answer 'where are you?'", quiet=0.50),
        human("drop-p20", "validation", "drops a ball outside the container", drop=0.20),
        human("order-210", "held-out", "task order not in the library", rule="order", order=[2, 1, 0]),
        human("order-120", "held-out", "task order not in the library", rule="order", order=[1, 2, 0]),
        human(
            "order-201-switch-1",
            "held-out",
            "changes plan mid-episode",
            rule="order",
            order=[2, 0, 1],
            switch_after=1,
            then="nearest",
        ),
        human("wander-p40", "held-out", "epsilon-wanderer", wander=0.40),
        human("slow-p50", "held-out", "slow", slow=0.50),
        human("quiet-p100", "held-out", "does not answer 'where are you?'", quiet=1.0),
        human("mislead-p50", "held-out", "answers 'where are you?' wrongly", mislead=0.50),
        human("drop-p30", "held-out", "drops a ball outside the container", drop=0.30),
    )


def _chapter5(domain: str) -> tuple[TeammateSpec, ...]:
    def mate(name, split, label, **params):
        return TeammateSpec(name, domain, split, label, params)

    thesis = _THESIS_TEAMMATES.get(domain, ("optimal",))
    specs = [
        mate(name, "train", "thesis teammate (the library's)", family="named", teammate=name)
        for name in thesis
    ]
    if "optimal" not in thesis:
        specs.append(
            mate(
                "optimal", "train", "thesis: the MMDP's optimal teammate", family="named", teammate="optimal"
            )
        )
    goals = domain not in _NO_OTHER_TASK
    specs += [
        mate("softmax-t03", "train", "softmax-rational", family="softmax", temperature=0.3),
        mate("eps-p10", "train", "epsilon-greedy", family="epsilon", epsilon=0.10),
        mate("lazy-p20", "train", "lazy (stays)", family="lazy", p=0.20),
        mate("softmax-t1", "validation", "softmax-rational", family="softmax", temperature=1.0),
        mate("eps-p30", "validation", "epsilon-greedy", family="epsilon", epsilon=0.30),
        mate("lazy-p40", "validation", "lazy (stays)", family="lazy", p=0.40),
        *(
            [mate("goal-mix-p50", "validation", "goal-switching (per step)", family="goal-mix", other=0.5)]
            if goals
            else []
        ),
        mate("softmax-t3", "held-out", "softmax-rational", family="softmax", temperature=3.0),
        mate("softmax-t10", "held-out", "softmax-rational", family="softmax", temperature=10.0),
        mate("eps-p50", "held-out", "epsilon-greedy", family="epsilon", epsilon=0.50),
        mate("lazy-p60", "held-out", "lazy (stays)", family="lazy", p=0.60),
        *(
            [mate("other-goal", "held-out", "pursues another task's goal", family="goal-mix", other=1.0)]
            if goals
            else []
        ),
    ]
    if domain == "pursuit-task":  # the thesis's teammate-aware predator, which this library does not hold
        specs.append(
            mate("aware", "held-out", "thesis: teammate-aware predator", family="named", teammate="aware")
        )
    if domain in _MIXED_TEAMS:
        first, second = _MIXED_TEAMS[domain]
        specs.append(
            mate(
                f"mix-{first}-{second}",
                "held-out",
                "mixed team: the library's teammates drawn per step",
                family="mix",
                teammates=[first, second],
                weights=[0.5, 0.5],
            )
        )
    return tuple(specs)


_ATLPO_NOISE = 0.2
_ATLPO_MIXED = (("tau1", "tau0", "tau1", "tau2"), ("tau2", "tau2", "tau0", "tau0"))
"""The held-out teams of the ATLPO split (``learning.atlpo_heldout``: NOISE, MIXED; seat 0's type first)."""


def _grid(domain: str) -> tuple[TeammateSpec, ...]:
    """The arena's scripted members (``teammates.grid_members``) and its learned ones (:func:`_learned`).

    Both arenas hold the thesis teams (train) and the ATLPO split's noisy and mixed teams (held-out), with a noisy,
    a mixed and a sticky team of other parameters as validation. The scripted ``spec`` members differ:
    predator-prey has one prey and tasks whose capture positions are not interchangeable, so its target and slot
    rules pick the same prey and cells whatever they are, and a team differs only by its goal (the slot or the
    closing ring) and its navigation (greedy or path). The thesis teams take three of those four ways; the fourth,
    the ring approached greedily, is its one scripted held-out member (see :func:`_pursuit_spec`)."""

    def team(name, split, label, **params):
        return TeammateSpec(name, domain, split, label, params)

    def seats(types, noise=0.0):
        name = "mixed-" + "-".join(types[1:]) if len(types) > 1 else types[0]
        # no '.' in a name: a plug-in spec's attribute path splits there
        return name + (f"-noise-p{round(100 * noise):02d}" if noise else "")

    specs = [team(tau, "train", "thesis team", family="named", team=tau) for tau in ("tau0", "tau1", "tau2")]
    specs += [
        team(
            seats(("tau1",), 0.1),
            "validation",
            "thesis team, actions noisy",
            family="seats",
            teams=["tau1"],
            noise=0.1,
        ),
        team(
            seats(("tau2", "tau0", "tau2", "tau1")),
            "validation",
            "mixed team of thesis types",
            family="seats",
            teams=["tau2", "tau0", "tau2", "tau1"],
        ),
        team(
            "sticky-tau1-p30",
            "validation",
            "sticky: repeats its last action",
            family="sticky",
            team="tau1",
            p=0.3,
        ),
    ]
    if domain == "foraging":
        specs.append(
            team(
                "closest-path",
                "validation",
                "scripted: closest target, shortest paths",
                family="spec",
                target="closest",
                slot="assigned",
                goal="slot",
                navigation="path",
            )
        )
    specs += [
        team(
            seats((tau,), _ATLPO_NOISE),
            "held-out",
            "ATLPO split: thesis team, actions noisy",
            family="seats",
            teams=[tau],
            noise=_ATLPO_NOISE,
        )
        for tau in ("tau0", "tau1", "tau2")
    ]
    specs += [
        team(
            seats(types),
            "held-out",
            "ATLPO split: mixed team of thesis types",
            family="seats",
            teams=list(types),
        )
        for types in _ATLPO_MIXED
    ]
    specs += [
        team(
            "sticky-tau2-p50",
            "held-out",
            "sticky: repeats its last action",
            family="sticky",
            team="tau2",
            p=0.5,
        ),
    ]
    specs.append(
        team(
            "highest-greedy",
            "held-out",
            "scripted: highest-level target, greedy moves",
            family="spec",
            target="highest_level",
            slot="closest",
            goal="slot",
            navigation="greedy",
        )
        if domain == "foraging"
        else _pursuit_spec(team)
    )
    return tuple(sorted((*specs, *_learned(domain)), key=lambda spec: SPLITS.index(spec.split)))


def _pursuit_spec(team) -> TeammateSpec:
    """Predator-prey's scripted held-out member: tau0's greedy moves towards tau2's closing ring (the one way of
    moving the thesis teams do not take; see :func:`_grid`)."""
    return team(
        "ring-greedy",
        "held-out",
        "scripted: encircling ring, greedy moves",
        family="spec",
        target="closest",
        slot="closest",
        goal="ring",
        navigation="greedy",
    )


def _learned(domain: str) -> tuple[TeammateSpec, ...]:
    """The arena's learned members, listed with their weights in the package's data (``bench/<domain>/members.json``:
    name, split, type, params with ``family: learned``, and the plug-in spec of the torch code that plays them, which
    lives above this layer)."""
    from embodied_adhoc.paths import assets_dir

    path = assets_dir() / "bench" / domain / "members.json"
    if not path.is_file():
        return ()
    entries = json.loads(path.read_text())["members"]
    return tuple(
        TeammateSpec(e["name"], domain, e["split"], e["type"], dict(e["params"]), plugin_spec=e["plugin"])
        for e in entries
    )


_POPULATIONS = {
    LAB: _lab,
    **{name: (lambda name=name: _chapter5(name)) for name in CHAPTER5},
    **{name: (lambda name=name: _grid(name)) for name in GRID},
}


def population(domain: str) -> tuple[TeammateSpec, ...]:
    """Every member of ``domain``'s population, in the order train, validation, held-out."""
    if domain not in _POPULATIONS:
        raise ConfigError(
            f"--domain {domain!r}: no benchmark population; choose from {', '.join(BENCH_DOMAINS)}"
        )
    return _POPULATIONS[domain]()


def members(domain: str, split: str) -> tuple[TeammateSpec, ...]:
    """The members of one split (``train``, ``validation``, ``held-out``; ``heldout`` is accepted)."""
    if split not in _SUITE_SPLIT:
        raise ConfigError(f"--suite {split!r}: choose from heldout, validation, train, or a population file")
    return tuple(spec for spec in population(domain) if spec.split == _SUITE_SPLIT[split])


_USER_MEMBERS: dict[tuple[str, str, str], TeammateSpec] = {}
"""Members of the population files read in this process, by (domain, suite, name): their plug-in specs name them
(worker processes forked from this one know them too)."""


def find_member(domain: str, name: str) -> TeammateSpec | None:
    """The member ``name`` of ``domain``'s population (any split), or ``SUITE/NAME`` of a population file read in
    this process; None if there is none."""
    if "/" in name:
        return _USER_MEMBERS.get((domain, *name.split("/", 1)))
    if domain not in _POPULATIONS:
        return None
    return next((spec for spec in population(domain) if spec.name == name), None)


_FILE_FIELDS = ("name", "version", "members")
_MEMBER_FIELDS = ("name", "domain", "type", "plugin", "params", "split")


def load_population(path: str | Path) -> tuple[str, str, tuple[TeammateSpec, ...]]:
    """A user's population file as ``(suite name, version, members)``.

    JSON: ``{"name": "my-suite", "version": "1", "members": [{"name": "cautious", "domain": "gridworld",
    "type": "my type", "plugin": "my_teammates:cautious"}, ...]}``. A member names its code by ``plugin`` (a
    ``module:callable`` or ``path/file.py:callable`` of the domain's teammate interface) or gives ``params`` of
    the domain's built-in families (:mod:`~embodied_adhoc.teammates.lab_members`,
    :mod:`~embodied_adhoc.teammates.chapter5_members`). Every member is scored (its split is the file's name).
    """
    from embodied_adhoc.checks import read_text, refuse_unknown

    path = Path(path)
    text = read_text(path, 1_000_000, "benchmark population file")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise ConfigError(f"{path}:{error.lineno}: not JSON ({error.msg})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a JSON object with {', '.join(_FILE_FIELDS)}")
    refuse_unknown(str(path), data, _FILE_FIELDS, what="field")
    suite = str(data.get("name") or path.stem)
    if not suite or any(c in suite for c in "/.:") or suite in SPLITS:
        raise ConfigError(
            f"{path}: name {suite!r}: a suite name without '/', '.' or ':', other than {SPLITS}"
        )
    version = str(data.get("version", "1"))
    entries = data.get("members")
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path}: field 'members' must be a non-empty list of members")
    specs, seen = [], set()
    for i, entry in enumerate(entries):
        where = f"{path}: members[{i}]"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: an object with name, domain, type and plugin or params")
        refuse_unknown(where, entry, _MEMBER_FIELDS, what="field")
        name, domain = entry.get("name"), entry.get("domain")
        if not isinstance(name, str) or not name or "/" in name or ":" in name:
            raise ConfigError(f"{where}.name: a non-empty string without '/' or ':'")
        if domain not in _POPULATIONS:
            raise ConfigError(f"{where}.domain {domain!r}: choose from {', '.join(BENCH_DOMAINS)}")
        if (domain, name) in seen:
            raise ConfigError(f"{where}.name {name!r}: listed twice for {domain}")
        seen.add((domain, name))
        plugin, params = entry.get("plugin"), entry.get("params")
        if (plugin is None) == (params is None):
            raise ConfigError(f"{where}: give exactly one of 'plugin' (module:callable) and 'params'")
        if plugin is not None and (not isinstance(plugin, str) or ":" not in plugin):
            raise ConfigError(f"{where}.plugin {plugin!r}: give module:callable or path/to/file.py:callable")
        if params is not None and not isinstance(params, dict):
            raise ConfigError(f"{where}.params: an object of the family's parameters")
        spec = TeammateSpec(
            name, domain, suite, str(entry.get("type", "user")), dict(params or {}), version, plugin
        )
        try:
            spec.factory()
        except ConfigError as error:
            raise ConfigError(f"{where}: {error}") from None
        specs.append(spec)
    for spec in specs:
        _USER_MEMBERS[(spec.domain, suite, spec.name)] = spec
    return suite, version, tuple(specs)
