"""Every torch piece lives here and only here: encoders and networks, PPO, the recurrent task/team classifier of
ATLPO, world models, replay buffers, weights stored as safetensors (``torch.load(weights_only=True)`` only).
Agents built on it implement the same ``Agent`` protocol as the tabular ones, so the trial runner does not know
the difference.

Where this layer sits and what it may import: docs/layout.md."""

LEARNED_AGENTS = ("ppo-generalist", "liam", "meliba")
"""The library-free agents that trials name directly where their weights ship (the grid arenas, the lab,
pursuit-task, ntu); kept here, free of torch, so that listing a domain's agents imports no network code."""
LEARNED_CHAPTER5_DOMAINS = ("pursuit-task", "ntu")
"""The chapter-5 domains whose trials name :data:`LEARNED_AGENTS` (their weights ship in ``assets/``)."""
