"""teammates layer (see docs/architecture in README)."""
