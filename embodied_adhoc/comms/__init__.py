"""comms layer (see docs/architecture in README)."""
