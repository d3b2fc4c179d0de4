"""envs layer (see docs/architecture in README)."""
