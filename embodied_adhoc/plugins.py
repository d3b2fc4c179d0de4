"""Plug-ins by name: one resolver turns what a user names on the command line into a factory.

A *spec* is one of

* a registered name (``hotspot``): the caller's built-in names, looked up first;
* ``module:callable`` (``my_agents:make``): the module is imported with the current directory searched first, as
  ``python -m`` does, so a file ``my_agents.py`` beside the user works without ``PYTHONPATH``;
* ``path/to/file.py:callable`` (``./my_agent.py:make``): the file is loaded as a module of its own;
* the name of an installed entry point in the kind's group (``embodied_adhoc.agents``, ``embodied_adhoc.teammates``,
  ``embodied_adhoc.humans``), so ``pip install my-agent`` makes ``--agents my-agent`` work.

``callable`` may be dotted (``module:Class.create``). :func:`resolve` returns a :class:`Plugin`: its factory and
the source file the factory's code lives in (``None`` for built-in names, whose code is the package's own), which a
run's identity hashes so that editing a user's module makes a new run. Every failure is one
:class:`~embodied_adhoc.errors.ConfigError` line naming the spec and the fix (the CLI exits 2 before any work).

What the factory is called with, and what it must return, is the kind's interface; ``docs/plugins.md`` documents
each (agents: :mod:`embodied_adhoc.decision.agents.base`).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import importlib.util
import os
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.errors import ConfigError

__all__ = ["GROUPS", "Plugin", "installed", "is_plugin_spec", "names_plugin", "resolve"]

GROUPS = {
    "agent": "embodied_adhoc.agents",
    "teammate": "embodied_adhoc.teammates",
    "human": "embodied_adhoc.humans",
}
"""Entry-point group of each kind of plug-in (``[project.entry-points."embodied_adhoc.agents"]``)."""


@dataclass(frozen=True)
class Plugin:
    """A resolved spec: ``name`` as the user gave it, the ``factory`` and the file it came from."""

    name: str
    kind: str
    factory: Callable | None  # None: a built-in name the caller builds itself
    source: Path | None = None  # the file defining the factory; None for built-in names

    @property
    def builtin(self) -> bool:
        return self.source is None and self.factory is None


_CACHE: dict[tuple[str, str, str], Plugin] = {}


def is_plugin_spec(spec: str) -> bool:
    """Whether ``spec`` names code (``module:callable`` or ``file.py:callable``) rather than a name."""
    return ":" in spec


def names_plugin(kind: str, spec: str) -> bool:
    """Whether ``spec`` names a plug-in of ``kind`` rather than a built-in: code, or an installed entry point."""
    return is_plugin_spec(spec) or spec in installed(kind)


def installed(kind: str) -> dict[str, importlib.metadata.EntryPoint]:
    """The entry points installed in the kind's group, by name."""
    return {ep.name: ep for ep in importlib.metadata.entry_points(group=_group(kind))}


def resolve(kind: str, spec: str, builtin: Iterable[str] = (), flag: str | None = None) -> Plugin:
    """The plug-in ``spec`` names (see the module docstring); ``builtin`` are the caller's own names, which win.

    ``flag`` (e.g. ``--agents``) starts every error message; resolved specs are cached per process and working
    directory, so workers and repeated calls import a user's module once.
    """
    _group(kind)
    spec = str(spec).strip()
    label = f"{flag or kind} {spec!r}"
    builtin = tuple(builtin)
    if spec in builtin:
        return Plugin(spec, kind, None, None)
    key = (kind, spec, os.getcwd())
    if key in _CACHE:
        return _CACHE[key]
    if is_plugin_spec(spec):
        where, _, attribute = spec.rpartition(":")
        if not where or not attribute:
            raise ConfigError(
                f"{label}: give MODULE:CALLABLE or path/to/file.py:CALLABLE (e.g. my_agent.py:make)"
            )
        if where.endswith(".py") or "/" in where or os.sep in where:
            module = _load_file(label, where)
        else:
            module = _import_module(label, where)
        factory = _attribute(label, module, attribute)
    else:
        entry = installed(kind).get(spec)
        if entry is None:
            raise ConfigError(_unknown(spec, flag, kind, builtin))
        try:
            factory = entry.load()
        except Exception as error:  # an installed plug-in that fails to import: name its package
            raise ConfigError(
                f"{label}: the installed entry point {entry.value!r} (group {_group(kind)}) fails to load: "
                f"{type(error).__name__}: {error}; reinstall or fix that package"
            ) from None
    if not callable(factory):
        raise ConfigError(f"{label}: {type(factory).__name__} is not callable; name a function or class")
    plugin = Plugin(spec, kind, factory, _source(factory))
    _CACHE[key] = plugin
    return plugin


def _group(kind: str) -> str:
    if kind not in GROUPS:
        raise ValueError(f"plug-in kind {kind!r}: one of {', '.join(GROUPS)}")
    return GROUPS[kind]


def _unknown(spec: str, flag: str | None, kind: str, builtin: tuple[str, ...]) -> str:
    entries = sorted(installed(kind))
    choices = ", ".join(builtin) or "none built in"
    extra = f"; installed ({GROUPS[kind]}): {', '.join(entries)}" if entries else ""
    return (
        f"unknown {kind} {spec!r}{f' ({flag})' if flag else ''}; choose from {choices}{extra}; or give "
        "MODULE:CALLABLE or path/to/file.py:CALLABLE"
    )


def _import_module(label: str, name: str):
    here = os.getcwd()
    if here not in sys.path and "" not in sys.path:
        sys.path.insert(0, here)  # as python -m: a module beside the user is found first
    _forget_shadowed(name.partition(".")[0], Path(here))
    importlib.invalidate_caches()  # a module written since the last import is found too
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as error:
        if error.name is not None and (name == error.name or name.startswith(error.name + ".")):
            raise ConfigError(
                f"{label}: no module '{name}' in the current directory ({here}) or installed; run from the "
                f"folder that holds {name.replace('.', '/')}.py, give its path (path/to/file.py:CALLABLE), or "
                "pip install its package"
            ) from None
        raise ConfigError(
            f"{label}: importing '{name}' needs the module '{error.name}', which is not installed "
            f"(pip install it)"
        ) from None
    except Exception as error:
        raise ConfigError(f"{label}: importing '{name}' failed: {_describe(error)}") from None


def _forget_shadowed(top: str, here: Path) -> None:
    """Drop ``top`` (and its submodules) from the imported modules when it was loaded from another folder while the
    current directory holds its own ``top.py`` or ``top/``: the current directory's wins, as in a fresh process."""
    loaded = sys.modules.get(top)
    local = [path for path in (here / f"{top}.py", here / top / "__init__.py") if path.is_file()]
    origin = getattr(loaded, "__file__", None)
    if loaded is None or not local or origin is None or Path(origin).resolve() == local[0].resolve():
        return
    for key in [key for key in sys.modules if key == top or key.startswith(top + ".")]:
        del sys.modules[key]


def _load_file(label: str, where: str):
    path = Path(where).expanduser()
    if not path.is_absolute():
        path = Path.cwd() / path
    path = path.resolve()
    if not path.is_file():
        raise ConfigError(f"{label}: no file {path} (relative paths are read from the current directory)")
    if path.suffix != ".py":
        raise ConfigError(f"{label}: {path} is not a .py file; give path/to/file.py:CALLABLE")
    # A module name of its own per file, so that two files named alike do not replace each other and pickled
    # objects of the module find it again in this process.
    name = f"_embodied_adhoc_plugin_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}"
    if name in sys.modules:
        return sys.modules[name]
    module_spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[name] = module
    try:
        module_spec.loader.exec_module(module)
    except ModuleNotFoundError as error:
        del sys.modules[name]
        raise ConfigError(
            f"{label}: {path.name} needs the module '{error.name}', which is not installed (pip install it)"
        ) from None
    except Exception as error:
        del sys.modules[name]
        raise ConfigError(f"{label}: loading {path} failed: {_describe(error)}") from None
    return module


def _attribute(label: str, module, attribute: str):
    target = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            defined = sorted(n for n in vars(module) if not n.startswith("_") and callable(vars(module)[n]))
            where = getattr(module, "__file__", module.__name__)
            raise ConfigError(
                f"{label}: {where} has no '{attribute}'; it defines {', '.join(defined) or 'no callables'}"
            )
        target = getattr(target, part)
    return target


def _source(factory) -> Path | None:
    module = sys.modules.get(getattr(factory, "__module__", None) or "")
    filename = getattr(module, "__file__", None)
    return None if filename is None else Path(filename).resolve()


def _describe(error: Exception) -> str:
    if isinstance(error, SyntaxError):
        return f"SyntaxError at {error.filename}:{error.lineno}: {error.msg}"
    return f"{type(error).__name__}: {error}"
