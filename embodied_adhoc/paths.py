"""The one place that resolves shipped data: MJCF ``scenes/``, ``assets/`` (robots, props, data files).

A source checkout keeps them at the repository root; an installed wheel carries them in
``embodied_adhoc/_data/`` (see ``setup.py``). Every other module asks here instead of building paths.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def _root(name: str) -> Path:
    installed = _PACKAGE / "_data" / name
    if installed.is_dir():
        return installed
    checkout = _PACKAGE.parent / name
    if checkout.is_dir():
        return checkout
    raise FileNotFoundError(
        f"embodied_adhoc data folder '{name}' not found (looked in {installed} and {checkout}); "
        "reinstall the package (pip install .) or run from a full source checkout"
    )


def scenes_dir() -> Path:
    """Folder of MJCF scene files."""
    return _root("scenes")


def assets_dir() -> Path:
    """Folder of robot/prop MJCF models and data files (e.g. confusion matrices)."""
    return _root("assets")


def scene(name: str) -> Path:
    """Path of one scene file, e.g. ``scene('lab.xml')``; a clear error if it does not exist."""
    path = scenes_dir() / name
    if not path.is_file():
        available = sorted(p.name for p in scenes_dir().glob("*.xml"))
        raise FileNotFoundError(f"no scene '{name}' in {scenes_dir()}; available: {available}")
    return path


def asset(relative: str) -> Path:
    """Path of one file under ``assets/``, e.g. ``asset('data/speech_confusion.json')``."""
    path = assets_dir() / relative
    if not path.exists():
        raise FileNotFoundError(f"no asset '{relative}' in {assets_dir()}")
    return path


def live_static(name: str | None = None) -> Path:
    """Folder of the live mode's web page (``embodied_adhoc/live/static``, shipped as package data), or one
    file in it by plain name (no folders: the server maps URLs to these names only)."""
    folder = _PACKAGE / "live" / "static"
    if name is None:
        return folder
    path = folder / name
    if "/" in name or "\\" in name or name.startswith(".") or not path.is_file():
        raise FileNotFoundError(f"no live page file '{name}' in {folder}")
    return path
