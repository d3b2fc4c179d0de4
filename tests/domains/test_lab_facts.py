"""The lab's map facts have one home (domains/lab_facts.py) that the model, the arena and the vocabulary read."""

from pathlib import Path

import pytest

from embodied_adhoc.comms.vocabulary import NODE_NAMES as SPOKEN_NAMES
from embodied_adhoc.comms.vocabulary import PLACE_SYNONYMS
from embodied_adhoc.domains import lab_facts
from embodied_adhoc.domains.lab_graph import DEFAULT_GRAPH, LabGraph
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT

PACKAGE = Path(__file__).resolve().parents[2] / "embodied_adhoc"


def test_model_arena_and_words_read_the_same_facts():
    assert DEFAULT_GRAPH.names == lab_facts.NODE_NAMES and DEFAULT_GRAPH.edges == lab_facts.EDGES
    assert DEFAULT_GRAPH.n_nodes == lab_facts.N_AREAS == len(LAB_LAYOUT.nodes)
    assert LAB_LAYOUT.node_names is lab_facts.NODE_NAMES and LAB_LAYOUT.edges is lab_facts.EDGES
    assert SPOKEN_NAMES is lab_facts.NODE_NAMES
    assert tuple(places[0] for places in PLACE_SYNONYMS) == lab_facts.NODE_NAMES


def test_no_other_module_spells_the_node_names_or_the_edges():
    spelled = (
        '("door", "open space", "robot station"'  # a tuple literal (a JSON example in a docstring is not)
    )
    edges = "((0, 1), (1, 2), (1, 3), (3, 4))"
    homes = [
        path.relative_to(PACKAGE).as_posix()
        for path in sorted(PACKAGE.rglob("*.py"))
        if spelled in path.read_text() or edges in path.read_text()
    ]
    assert homes == ["domains/lab_facts.py"], homes


def test_the_physics_lab_refuses_a_graph_that_is_not_its_map():
    from embodied_adhoc.envs.toxic_waste import ToxicWasteEnv

    other = LabGraph(n_nodes=3, edges=((0, 1), (1, 2)), names=("a", "b", "c"))
    with pytest.raises(ConfigError, match="graph= must be the MuJoCo lab's map"):
        ToxicWasteEnv(graph=other, tasks=((0, 1),))
