"""The HOTSPOT lab's map facts, in one place (thesis section 7.1, Fig. 7.4): its areas and their names, and the
passages between them.

The abstract model's graph (:class:`~embodied_adhoc.domains.lab_graph.LabGraph`), the MuJoCo arena's metadata
(:class:`~embodied_adhoc.sim.lab_layout.LabLayout`) and the speech vocabulary
(:mod:`embodied_adhoc.comms.vocabulary`) all read them from here, so the worlds and the words cannot disagree.
"""

from __future__ import annotations

__all__ = ["EDGES", "N_AREAS", "NODE_NAMES"]

NODE_NAMES: tuple[str, ...] = ("door", "open space", "robot station", "single workbench", "double workbench")
"""Each area's canonical name, indexed by node id (also the rows of a confusion matrix)."""
N_AREAS = len(NODE_NAMES)
"""The lab's areas (the nodes of its graph): ids ``0..N_AREAS - 1``."""
EDGES: tuple[tuple[int, int], ...] = ((0, 1), (1, 2), (1, 3), (3, 4))
"""The passages: door-open space, open space-robot station, open space-single workbench, single-double
workbench."""
