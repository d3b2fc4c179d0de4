"""CLI subcommands: one module per command, each with ``register(subparsers)`` (see ``embodied_adhoc.cli``)."""
