"""experiments layer (see docs/architecture in README)."""
