"""``embodied-adhoc envs [--json]``: list every registered Gymnasium env id with its backend and description.

Reads ``embodied_adhoc.envs.registry.ENV_SPECS`` (no env is constructed, so no MuJoCo import).
"""

from __future__ import annotations

import argparse
import json


def env_table() -> list[dict]:
    """One row per registered id: ``id``, ``backend``, ``description``, ``entry_point``, ``max_episode_steps``."""
    from embodied_adhoc.envs.registry import ENV_SPECS

    return [
        {
            "id": spec.id,
            "backend": spec.backend,
            "description": spec.description,
            "entry_point": spec.entry_point,
            "max_episode_steps": spec.max_episode_steps,
        }
        for spec in ENV_SPECS
    ]


def format_table(rows: list[dict]) -> str:
    if not rows:
        return "no environments registered"
    id_width = max(len(row["id"]) for row in rows)
    backend_width = max(len("backend"), *(len(row["backend"]) for row in rows))
    lines = [f"{'id':<{id_width}}  {'backend':<{backend_width}}  description"]
    lines += [
        f"{row['id']:<{id_width}}  {row['backend']:<{backend_width}}  {row['description']}" for row in rows
    ]
    return "\n".join(lines)


def handle(args: argparse.Namespace) -> int:
    rows = env_table()
    if args.json:
        print(json.dumps({"envs": rows}, indent=2))
    else:
        print(format_table(rows))
        print("\nuse: gymnasium.make(ID, **kwargs) after `import embodied_adhoc.envs`")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "envs",
        help="list the registered Gymnasium env ids",
        description="List every registered Gymnasium env id with its backend (abstract or mujoco) and description.",
    )
    parser.add_argument(
        "--json", action="store_true", help='print {"envs": [{"id", "backend", "description", ...}]}'
    )
    parser.set_defaults(func=handle)
