"""What a person may answer to the robot's "Where are you?": templates and a seeded phrase generator.

A reply is ``[opening] body [closing]``. The body either names a place (one of 18 templates x 15 place
expressions, from :mod:`embodied_adhoc.comms.vocabulary`) or is uninformative ("just a second", "I don't know"),
in which case the correct answer is "no location". Openings are fillers ("um", "well") and closings are
politeness ("please", "thank you"). The recognition grammar is generated from the same tables
(:mod:`embodied_adhoc.comms.grammar`), so every generated phrase is in the grammar's language.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.comms.vocabulary import NODE_NAMES, PLACE_SYNONYMS, PLACE_TO_NODE, normalise
from embodied_adhoc.errors import ConfigError

LOCATED_TEMPLATES: tuple[str, ...] = (
    "I'm at the {place}",
    "I am at the {place}",
    "the {place}",
    "at the {place}",
    "I'm near the {place}",
    "I'm by the {place}",
    "I'm next to the {place}",
    "I'm waiting at the {place}",
    "I'm standing at the {place}",
    "I'm still at the {place}",
    "I'm over at the {place}",
    "I'm here at the {place}",
    "I'm holding the waste at the {place}",
    "I picked up a ball at the {place}",
    "I'm waiting for you at the {place}",
    "come to the {place}",
    "you can find me at the {place}",
    "over here by the {place}",
)
"""Bodies that name a place; ``{place}`` is replaced by one of the place expressions."""

UNINFORMATIVE_REPLIES: tuple[str, ...] = (
    "just a second",
    "I don't know",
    "hold on",
    "wait a moment",
    "one moment",
    "give me a second",
    "hang on",
    "I'm not sure",
    "I'm busy",
    "not now",
    "sorry",
    "I'm coming",
)
"""Bodies that carry no location: the correct recognition result is "no location"."""

OPENINGS: tuple[str, ...] = ("um", "uh", "well", "okay", "so", "hey robot")
"""Fillers that may start a reply (written with a trailing comma)."""

CLOSINGS: tuple[str, ...] = ("please", "thanks", "thank you", "right now")
"""Politeness or emphasis that may end a reply (written after a comma)."""


@dataclass(frozen=True)
class PhraseConfig:
    """How :func:`sample_phrase` draws a reply.

    Attributes:
        uninformative_probability: probability that the body carries no location.
        opening_probability: probability of a filler opening ("um, ...").
        closing_probability: probability of a politeness closing ("..., please").
    """

    uninformative_probability: float = 0.1
    opening_probability: float = 0.3
    closing_probability: float = 0.25

    def __post_init__(self) -> None:
        for name in ("uninformative_probability", "opening_probability", "closing_probability"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ConfigError(
                    f"PhraseConfig.{name} = {value} is not a probability; use a value in [0, 1]"
                )


@dataclass(frozen=True)
class Phrase:
    """One reply: the text to speak, and its labels for metrics 4-6 (thesis section 7.1).

    ``place`` is the place expression it mentions (the named entity, metric 5) and ``node`` the node that
    expression names (metric 6); both are ``None`` for an uninformative reply ("no location").
    """

    text: str
    place: str | None
    node: int | None

    @property
    def reference(self) -> str:
        """The normalised text a perfect transcription equals (metric 4)."""
        return normalise(self.text)


def _compose(opening: str | None, body: str, closing: str | None) -> str:
    text = body[0].upper() + body[1:] if opening is None else f"{opening.capitalize()}, {body}"
    return text if closing is None else f"{text}, {closing}"


def make_phrase(
    body_template: str, place: str | None, opening: str | None = None, closing: str | None = None
) -> Phrase:
    """Build a :class:`Phrase` from its parts (``place`` is ``None`` for an uninformative body)."""
    if place is None:
        return Phrase(_compose(opening, body_template, closing), None, None)
    if place not in PLACE_TO_NODE:
        raise ConfigError(f"unknown place expression {place!r}; known: {sorted(PLACE_TO_NODE)}")
    return Phrase(_compose(opening, body_template.format(place=place), closing), place, PLACE_TO_NODE[place])


def iter_phrases() -> Iterator[Phrase]:
    """Every distinct phrasing the generator can produce, in a fixed order (about 10,000)."""
    bodies = [(t, p) for t in LOCATED_TEMPLATES for places in PLACE_SYNONYMS for p in places]
    bodies += [(t, None) for t in UNINFORMATIVE_REPLIES]
    for opening, (template, place), closing in itertools.product(
        (None, *OPENINGS), bodies, (None, *CLOSINGS)
    ):
        yield make_phrase(template, place, opening, closing)


def sample_phrase(node: int, rng: np.random.Generator, config: PhraseConfig = PhraseConfig()) -> Phrase:
    """A reply of a person standing at ``node``: names one of its place expressions, or is uninformative."""
    if not 0 <= node < len(NODE_NAMES):
        raise ConfigError(
            f"node {node} is not a lab node; use 0..{len(NODE_NAMES) - 1} ({', '.join(NODE_NAMES)})"
        )
    opening = OPENINGS[rng.integers(len(OPENINGS))] if rng.random() < config.opening_probability else None
    closing = CLOSINGS[rng.integers(len(CLOSINGS))] if rng.random() < config.closing_probability else None
    if rng.random() < config.uninformative_probability:
        return make_phrase(
            UNINFORMATIVE_REPLIES[rng.integers(len(UNINFORMATIVE_REPLIES))], None, opening, closing
        )
    places = PLACE_SYNONYMS[node]
    template = LOCATED_TEMPLATES[rng.integers(len(LOCATED_TEMPLATES))]
    return make_phrase(template, places[rng.integers(len(places))], opening, closing)


def sample_phrases(
    count: int, rng: np.random.Generator, config: PhraseConfig = PhraseConfig()
) -> list[tuple[int, Phrase]]:
    """``count`` (true node, reply) pairs with the true nodes balanced (cycled 0..4, then shuffled)."""
    if count < 1:
        raise ConfigError(f"phrase count {count} must be at least 1")
    nodes = rng.permutation(np.resize(np.arange(len(NODE_NAMES)), count))
    return [(int(node), sample_phrase(int(node), rng, config)) for node in nodes]
