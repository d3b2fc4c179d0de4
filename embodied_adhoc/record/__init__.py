"""record layer (see docs/architecture in README)."""
