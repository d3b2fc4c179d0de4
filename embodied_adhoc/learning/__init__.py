"""learning layer (see docs/architecture in README)."""
