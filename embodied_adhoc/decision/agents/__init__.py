"""Decision agents (generic over model libraries): HOTSPOT/TEBOPA, ATPO, BOPA and baselines."""

from embodied_adhoc.decision.agents.base import Agent

__all__ = ["Agent"]
