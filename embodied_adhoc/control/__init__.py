"""control layer (see docs/architecture in README)."""
