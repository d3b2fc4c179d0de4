"""decision layer (see docs/architecture in README)."""
