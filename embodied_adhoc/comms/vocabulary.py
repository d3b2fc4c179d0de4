"""The lab's place vocabulary: the five areas (nodes) and the words a person may use for each.

Node ids follow the thesis (section 7.1, Fig. 7.4) and ``docs/hotspot-original.md``: 0 door, 1 open space,
2 robot station, 3 single workbench, 4 double workbench. Every other part of the communication module (phrase
generator, recognition grammar, parser) is generated from this table, so adding a synonym here is enough.
"""

from __future__ import annotations

import re

from embodied_adhoc.domains.lab_facts import NODE_NAMES

_OTHER_WORDS: tuple[tuple[str, ...], ...] = (
    ("entrance", "exit"),
    ("middle of the room", "centre"),
    ("charging station", "docking station"),
    ("small workbench", "single bench"),
    ("big workbench", "double bench"),
)
PLACE_SYNONYMS: tuple[tuple[str, ...], ...] = tuple(
    (name, *others) for name, others in zip(NODE_NAMES, _OTHER_WORDS, strict=True)
)
"""The place expressions (named entities) of each node; the first one is the canonical name
(``domains.lab_facts.NODE_NAMES``)."""

PLACE_TO_NODE: dict[str, int] = {
    place: node for node, places in enumerate(PLACE_SYNONYMS) for place in places
}
"""Place expression -> node id."""

PLACES: tuple[str, ...] = tuple(PLACE_TO_NODE)
"""Every place expression, in node order."""

_WORD = re.compile(r"[a-z]+(?:'[a-z]+)?")


def normalise(text: str) -> str:
    """Lower-case words separated by single spaces, punctuation dropped (apostrophes inside words kept).

    Metric 4 ignores capitalisation and punctuation that do not change the phrase (thesis section 7.1), so
    transcripts and reference phrases are compared after this normalisation. British and American spellings
    of the same word ("centre"/"center") are spelled the British way, the vocabulary's spelling.
    """
    words = _WORD.findall(text.lower().replace("\u2019", "'"))
    return " ".join("centre" if word == "center" else word for word in words)


def node_name(node: int | None) -> str:
    """Canonical name of ``node``, or ``"no location"`` for ``None``."""
    return "no location" if node is None else NODE_NAMES[node]
