"""The package's layering: which package may import which, checked on every import statement in the source.

The README's rule ("dependencies point downward only") as a table. Imports are read from the AST, so imports
inside functions (the lazy ones that hid the cycles envs -> experiments -> envs, record -> experiments and
domains -> teammates -> domains) count exactly like module-level ones, and so do ``importlib.import_module("...")``
calls and entry-point strings (``"embodied_adhoc.pkg.module:attr"``) with a literal module name.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parents[1] / "embodied_adhoc"

FOUNDATION = frozenset({"errors", "atomic", "paths", "checks", "gl", "plugins", "__init__"})
"""Top-level modules every layer may import (errors, atomic writes, data paths, validation, GL platform, the
plug-in resolver)."""

ALLOWED: dict[str, frozenset[str]] = {
    # layer: the layers (besides FOUNDATION) it may import. Lower layers first.
    "decision": frozenset(),
    "control": frozenset(),
    "domains": frozenset({"decision"}),
    # the teammates the agents meet, the benchmark's versioned populations among them (learners train on their
    # train split; the exact best responses behind their bounds live in bench/)
    "teammates": frozenset({"decision", "domains"}),
    "comms": frozenset({"domains"}),
    "sim": frozenset({"control", "domains"}),
    "envs": frozenset({"decision", "control", "domains", "teammates", "comms", "sim"}),
    "learning": frozenset(
        {"decision", "control", "domains", "teammates", "comms", "sim", "envs"}
    ),  # trains on envs
    "record": frozenset(),
    # the episode loop, the recorders' observers and the recorded-run driver: above envs/ and record/, below
    # the trial infrastructure that runs it
    "episodes": frozenset({"decision", "control", "domains", "teammates", "comms", "sim", "envs", "record"}),
    "experiments": frozenset(
        {
            "decision",
            "control",
            "domains",
            "teammates",
            "comms",
            "sim",
            "learning",
            "envs",
            "record",
            "episodes",
        }
    ),
    # the real-time lab and the browser live mode: an env subclass plus the episode loop and recorders
    "live": frozenset(
        {
            "decision",
            "control",
            "domains",
            "teammates",
            "comms",
            "sim",
            "envs",
            "record",
            "episodes",
            "experiments",
        }
    ),
    # the benchmark: teammate populations (lab humans, chapter-5 teammates), their bounds, and evaluate through
    # the trial runner
    "bench": frozenset({"decision", "domains", "teammates", "envs", "experiments"}),
    "commands": frozenset(
        {
            "bench",
            "live",
            "decision",
            "control",
            "domains",
            "teammates",
            "comms",
            "sim",
            "learning",
            "envs",
            "record",
            "episodes",
            "experiments",
        }
    ),
    "cli": frozenset({"commands"}),
}
FOUNDATION_ALLOWED: dict[str, frozenset[str]] = {
    "errors": frozenset(),
    "atomic": frozenset({"errors"}),
    "paths": frozenset({"errors"}),
    "checks": frozenset({"errors"}),
    "gl": frozenset(),
    "plugins": frozenset({"errors"}),
    "__init__": frozenset(),
}
FORBIDDEN_THIRD_PARTY: dict[str, frozenset[str]] = {
    # README: decision imports neither mujoco nor gymnasium, control no mujoco, only learning imports torch;
    # recorders take plain numpy data and know nothing of MuJoCo.
    "decision": frozenset({"mujoco", "dm_control", "gymnasium", "torch"}),
    "control": frozenset({"mujoco", "dm_control", "gymnasium", "torch"}),
    "record": frozenset({"mujoco", "dm_control", "gymnasium", "torch"}),
    # the episode layer drives envs and worlds through the objects it is given, never through the simulators
    "episodes": frozenset({"mujoco", "dm_control", "gymnasium", "torch"}),
}
TORCH_LAYERS = frozenset({"learning"})


def layer_of(path: Path) -> str:
    parts = path.relative_to(PACKAGE_ROOT).parts
    return parts[0] if len(parts) > 1 else parts[0].removesuffix(".py")


def _resolve_relative(path: Path, module: str | None, level: int) -> str:
    package = list(path.relative_to(PACKAGE_ROOT.parent).with_suffix("").parts)[:-level]
    return ".".join(package + ([module] if module else []))


def imported_modules(source: str, path: Path) -> list[tuple[str, int]]:
    """Every module name imported anywhere in ``source`` (any depth), with its line."""
    found: list[tuple[str, int]] = []
    for node in ast.walk(ast.parse(source, filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module if not node.level else _resolve_relative(path, node.module, node.level)
            found.append((module or "", node.lineno))
            if module == "embodied_adhoc":  # from embodied_adhoc import envs (a subpackage, not __version__)
                found += [
                    (f"embodied_adhoc.{alias.name}", node.lineno)
                    for alias in node.names
                    if (PACKAGE_ROOT / alias.name).is_dir() or (PACKAGE_ROOT / f"{alias.name}.py").is_file()
                ]
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.append((node.args[0].value, node.lineno))
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and node.value.startswith("embodied_adhoc.")
            and ":" in node.value
            and " " not in node.value
        ):
            found.append((node.value.partition(":")[0], node.lineno))  # entry point "pkg.module:attr"
    return found


def violations(source: str, path: Path) -> list[str]:
    layer = layer_of(path)
    allowed = FOUNDATION_ALLOWED[layer] if layer in FOUNDATION_ALLOWED else ALLOWED[layer] | FOUNDATION
    forbidden = FORBIDDEN_THIRD_PARTY.get(layer, frozenset()) | (
        {"torch"} if layer not in TORCH_LAYERS else set()
    )
    problems = []
    for module, line in imported_modules(source, path):
        parts = module.split(".")
        where = f"{path.relative_to(PACKAGE_ROOT.parent)}:{line}"
        if parts[0] == "embodied_adhoc" and len(parts) > 1:
            target = parts[1]
            if target != layer and target not in allowed:
                problems.append(f"{where}: {layer} imports {module} ({layer} -> {target} is not allowed)")
        elif parts[0] in forbidden:
            problems.append(f"{where}: {layer} imports {parts[0]}")
    return problems


def package_files() -> list[Path]:
    return sorted(PACKAGE_ROOT.rglob("*.py"))


def test_every_layer_is_in_the_table():
    layers = {layer_of(path) for path in package_files()}
    unknown = layers - set(ALLOWED) - set(FOUNDATION_ALLOWED)
    assert not unknown, (
        f"new package or module {sorted(unknown)}: add its allowed imports to tests/test_layers.py"
    )


def test_allowed_directions_have_no_cycle():
    def reaches(start: str, goal: str, seen: set[str]) -> bool:
        for target in ALLOWED.get(start, ()):
            if target == goal or (target not in seen and reaches(target, goal, seen | {target})):
                return True
        return False

    assert not [layer for layer in ALLOWED if reaches(layer, layer, set())]


def test_imports_follow_the_layer_table():
    problems = [problem for path in package_files() for problem in violations(path.read_text(), path)]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize(
    ("relative", "source", "expected"),
    [
        # a function-level import counts like a module-level one
        (
            "record/metrics.py",
            "def f():\n    from embodied_adhoc.experiments.stats import x\n",
            "record -> experiments",
        ),
        ("envs/x.py", "def f():\n    import embodied_adhoc.experiments.seeding\n", "envs -> experiments"),
        ("domains/lab.py", "from embodied_adhoc import teammates\n", "domains -> teammates"),
        ("envs/x.py", "def f():\n    from ..record import video\n", "envs -> record"),
        ("envs/x.py", "importlib.import_module('embodied_adhoc.experiments.trial')\n", "envs -> experiments"),
        ("decision/x.py", "def f():\n    import mujoco\n", "decision imports mujoco"),
        ("record/x.py", "def f():\n    import torch\n", "record imports torch"),
        ("experiments/x.py", "import torch.nn\n", "experiments imports torch"),
        # the episode layer sits above envs/ and record/, below the trial infrastructure
        ("envs/x.py", "def f():\n    from embodied_adhoc.episodes.loop import x\n", "envs -> episodes"),
        ("record/x.py", "from embodied_adhoc.episodes import recording\n", "record -> episodes"),
        (
            "episodes/x.py",
            "def f():\n    from embodied_adhoc.experiments import seeding\n",
            "episodes -> experiments",
        ),
        ("episodes/x.py", "def f():\n    import gymnasium\n", "episodes imports gymnasium"),
    ],
)
def test_the_checker_sees_hidden_imports(relative, source, expected):
    problems = violations(source, PACKAGE_ROOT / relative)
    assert len(problems) == 1 and expected in problems[0], problems


def test_the_checker_accepts_allowed_imports():
    source = "from embodied_adhoc.domains.lab import x\ndef f():\n    from embodied_adhoc.errors import ConfigError\n"
    assert violations(source, PACKAGE_ROOT / "teammates" / "x.py") == []


def envs_and_agents(source: str, path: Path) -> list[str]:
    """Classes in ``source`` that are an env (Gymnasium's ``reset`` and ``step``, or an ``*Env`` base) or an agent
    (``act``, or an ``*Agent``/``AgentBase`` base): ``experiments/`` runs them and defines neither."""
    found = []
    for node in ast.walk(ast.parse(source, filename=str(path))):
        if not isinstance(node, ast.ClassDef):
            continue
        methods = {
            item.name for item in node.body if isinstance(item, ast.FunctionDef | ast.AsyncFunctionDef)
        }
        bases = [ast.unparse(base).rpartition(".")[2] for base in node.bases]
        where = f"{path.relative_to(PACKAGE_ROOT.parent)}:{node.lineno}"
        if {"reset", "step"} <= methods or any(base.endswith("Env") for base in bases):
            found.append(f"{where}: class {node.name} is an env (its home is envs/)")
        elif "act" in methods or any(base.endswith("Agent") or base == "AgentBase" for base in bases):
            found.append(
                f"{where}: class {node.name} is an agent (its home is decision/agents/ or learning/)"
            )
    return found


def test_experiments_define_no_env_and_no_agent():
    problems = [
        problem
        for path in sorted((PACKAGE_ROOT / "experiments").rglob("*.py"))
        for problem in envs_and_agents(path.read_text(), path)
    ]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("class W:\n    def reset(self): ...\n    def step(self, a): ...\n", "is an env"),
        ("class W(gymnasium.Env):\n    pass\n", "is an env"),
        ("class A(AgentBase):\n    pass\n", "is an agent"),
        ("class A:\n    def act(self): ...\n", "is an agent"),
        ("def f():\n    class A(base.RandomAgent):\n        pass\n", "is an agent"),
    ],
)
def test_the_checker_sees_envs_and_agents(source, expected):
    problems = envs_and_agents(source, PACKAGE_ROOT / "experiments" / "x.py")
    assert len(problems) == 1 and expected in problems[0], problems


def test_the_checker_lets_sessions_and_observers_be():
    source = (
        "class Session:\n    def make_env(self): ...\n    def make_agent(self): ...\n    def reset_options(self): ...\n"
        "class Observer(EpisodeObserver):\n    def step_finished(self): ...\n"
    )
    assert envs_and_agents(source, PACKAGE_ROOT / "experiments" / "x.py") == []
