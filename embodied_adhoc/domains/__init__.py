"""domains layer (see docs/architecture in README)."""
