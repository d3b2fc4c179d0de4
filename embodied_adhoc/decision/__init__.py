"""numpy/scipy only: sparse (PO)MDP types, Cassandra ``.pomdp`` I/O, solvers (value iteration, QMDP, Perseus),
belief updates and the decision agents (HOTSPOT/TEBOPA, ATPO, BOPA, baselines); no mujoco, no gymnasium
(docs/pomdp.md, docs/hotspot.md).

Where this layer sits and what it may import: docs/layout.md."""
