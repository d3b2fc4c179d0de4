"""Transcript -> place -> node: the named-entity and node-location steps of the sensing pipeline.

Thesis section 7.1 (metrics 5 and 6): a named-entity step extracts the place expression ("the entrance"), a
node-location step maps it to a node of the topological map (0). Here both use the generated vocabulary: the
longest place expression found in the normalised transcript (word-aligned) wins; none found = "no location".
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from embodied_adhoc.comms.vocabulary import PLACE_TO_NODE, PLACES, normalise

# Longest expressions first, so "double workbench" is preferred over a shorter overlapping expression.
_PLACE_PATTERN = re.compile(
    r"\b(" + "|".join(re.escape(place) for place in sorted(PLACES, key=len, reverse=True)) + r")\b"
)


@dataclass(frozen=True)
class ParseResult:
    """The place expression found in a transcript (metric 5) and its node (metric 6); ``None`` = no location."""

    place: str | None
    node: int | None


def parse(transcript: str | None) -> ParseResult:
    """Find the place a transcript names. With several places, the last one counts ("not the door, the exit")."""
    if not transcript:
        return ParseResult(None, None)
    matches = _PLACE_PATTERN.findall(normalise(transcript))
    if not matches:
        return ParseResult(None, None)
    return ParseResult(matches[-1], PLACE_TO_NODE[matches[-1]])
