"""sim layer (see docs/architecture in README)."""
