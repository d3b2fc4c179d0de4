"""The chapter-5 domain suite (thesis sections 5.1.3 and 5.2.5): model libraries built from rules.

``build_library(name, **options)`` is the one entry point (the CLI's ``pomdp export`` and ``trials`` use it):

========================  ================================================  ===========================
name                      builder                                           states (Table 5.2)
========================  ================================================  ===========================
panic-buttons             :func:`panic_buttons.build_panic_buttons`         size^4 + 1 (82 / 257 / 626)
gridworld                 :func:`navigation.build_gridworld`                626
pursuit-task/-teammate/   :func:`pursuit.build_pursuit`                     626
-both
ntu isr mit pentagon cit  :func:`navigation.build_map_library`              n(n-1)+1: 241 ... 4,831
map (``map=PATH``)        :func:`navigation.build_map_library`              n(n-1)+1
power-plant               :func:`power_plant.build_power_plant`             105 / 97 (one per task)
overcooked                :func:`overcooked.build_overcooked`               1,730
========================  ================================================  ===========================
"""

from __future__ import annotations

from embodied_adhoc.errors import ConfigError

__all__ = ["CHAPTER5_DOMAINS", "build_library"]

CHAPTER5_DOMAINS = (
    "panic-buttons",
    "gridworld",
    "pursuit-task",
    "pursuit-teammate",
    "pursuit-both",
    "power-plant",
    "ntu",
    "isr",
    "mit",
    "pentagon",
    "cit",
    "overcooked",
    "map",
)


def build_library(name: str, **options):
    """The :class:`~embodied_adhoc.domains.chapter5.library.ModelLibrary` of domain ``name`` (options: the
    builder's keyword arguments; ``map`` needs ``map=PATH``)."""
    from embodied_adhoc.domains.chapter5 import navigation, overcooked, panic_buttons, power_plant, pursuit

    if name == "panic-buttons":
        return panic_buttons.build_panic_buttons(**options)
    if name == "gridworld":
        return navigation.build_gridworld(**options)
    if name in pursuit.PURSUIT_VARIANTS:
        return pursuit.build_pursuit(name, **options)
    if name in navigation.MAP_SETTINGS:
        return navigation.build_map_library(name, **options)
    if name == "map":
        options = dict(options)
        path = options.pop("map", None)
        if path is None:
            raise ConfigError(
                "domain 'map' needs a map file: --map PATH ('#' blocked, '.' open, 'S' start, 'G' goal)"
            )
        return navigation.build_map_library(path, **options)
    if name == "power-plant":
        return power_plant.build_power_plant(**options)
    if name == "overcooked":
        return overcooked.build_overcooked(**options)
    raise ConfigError(f"unknown chapter-5 domain {name!r}; choose from {', '.join(CHAPTER5_DOMAINS)}")
