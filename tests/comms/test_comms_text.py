"""Vocabulary, phrase generator, grammar, accent lexicon and parser: text only, no audio."""

from __future__ import annotations

import re

import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.comms import grammar, lexicon, parsing, phrases
from embodied_adhoc.comms.vocabulary import NODE_NAMES, PLACE_SYNONYMS, PLACE_TO_NODE, normalise
from embodied_adhoc.errors import ConfigError, SpeechError


def test_vocabulary_matches_the_lab_nodes_and_synonyms():
    assert NODE_NAMES == ("door", "open space", "robot station", "single workbench", "double workbench")
    assert PLACE_SYNONYMS[0] == ("door", "entrance", "exit")
    assert PLACE_TO_NODE["middle of the room"] == 1 and PLACE_TO_NODE["docking station"] == 2
    assert PLACE_TO_NODE["single bench"] == 3 and PLACE_TO_NODE["big workbench"] == 4


def test_generator_has_over_300_distinct_phrasings_of_every_kind():
    all_phrases = list(phrases.iter_phrases())
    texts = {p.reference for p in all_phrases}
    assert len(texts) == len(all_phrases) >= 300
    assert "i'm at the door" in texts and "i'm waiting at the centre" in texts
    assert "um i'm at the entrance please" in texts
    uninformative = [p for p in all_phrases if p.node is None]
    assert uninformative and all(p.place is None for p in uninformative)
    assert {"just a second", "i don't know"} <= {p.reference for p in uninformative}


def test_sampled_phrases_are_seeded_and_labelled():
    a = phrases.sample_phrases(50, np.random.default_rng(3))
    b = phrases.sample_phrases(50, np.random.default_rng(3))
    assert a == b
    assert a != phrases.sample_phrases(50, np.random.default_rng(4))
    assert sorted(node for node, _ in a) == sorted(list(range(5)) * 10)  # balanced true nodes
    for node, phrase in a:
        assert phrase.node in (node, None)
        if phrase.place is not None:
            assert PLACE_TO_NODE[phrase.place] == node and phrase.place in phrase.reference


def test_phrase_config_and_node_are_checked():
    with pytest.raises(ConfigError, match="uninformative_probability"):
        phrases.PhraseConfig(uninformative_probability=1.5)
    with pytest.raises(ConfigError, match="not a lab node"):
        phrases.sample_phrase(7, np.random.default_rng(0))


def _grammar_regex() -> re.Pattern:
    """An independent reading of the generated JSGF: expand its rules into one regular expression."""
    text = grammar.grammar_text()
    rules = dict(re.findall(r"(?:public )?<(\w+)> = (.*?);", text, flags=re.S))

    def expand(name: str) -> str:
        body = " ".join(rules[name].split())
        body = re.sub(r"<(\w+)>", lambda m: "(?:" + expand(m.group(1)) + ")", body)
        body = body.replace("[", "(?:").replace("]", ")?").replace("(", "(?:").replace("(?:?:", "(?:")
        return body.replace(" | ", "|")

    pattern = expand("reply").replace(")? ", ")? ?").replace(" (?:", " ?(?:")
    return re.compile("^" + pattern + "$")


def test_every_generated_phrase_is_in_the_grammar_language():
    language = _grammar_regex()
    all_phrases = list(phrases.iter_phrases())
    for phrase in all_phrases[:: max(1, len(all_phrases) // 2000)]:
        assert language.match(phrase.reference), phrase.reference
    assert not language.match("i'm at the kitchen")


def test_committed_grammar_and_dictionary_are_up_to_date():
    for relative, text in grammar.generated_files().items():
        assert (paths.assets_dir() / relative).read_text(encoding="utf-8") == text, (
            f"assets/{relative} is stale: run `embodied-adhoc speech grammar`"
        )
    words = {
        line.split()[0].split("(")[0]
        for line in grammar.generated_files()[grammar.DICTIONARY_FILE].splitlines()
    }
    assert words == set(grammar.grammar_words())


@pytest.mark.parametrize(
    ("transcript", "place", "node"),
    [
        ("i'm at the door", "door", 0),
        ("Um, I'm waiting at the Entrance, please.", "entrance", 0),
        ("over here by the middle of the room", "middle of the room", 1),
        ("i'm at the center", "centre", 1),
        ("come to the docking station", "docking station", 2),
        ("the single bench", "single bench", 3),
        ("i'm holding the waste at the big workbench", "big workbench", 4),
        ("double workbench", "double workbench", 4),
        ("i don't know", None, None),
        ("just a second", None, None),
        ("", None, None),
        (None, None, None),
        ("i'm near the doorway", None, None),  # word-aligned: "doorway" is not "door"
    ],
)
def test_parser_maps_transcript_to_place_and_node(transcript, place, node):
    assert parsing.parse(transcript) == parsing.ParseResult(place, node)


def test_normalise_ignores_case_and_punctuation():
    assert normalise("Um, I'm at the DOOR!") == "um i'm at the door"


def test_grammar_language_matches_the_jsgf_reading():
    jsgf = _grammar_regex()
    for phrase in list(phrases.iter_phrases())[::97]:
        assert grammar.is_complete(phrase.reference) and jsgf.match(phrase.reference)
    for partial in ("come to the middle", "i'm at the", "i'm at the docking station right", "the open"):
        assert not grammar.is_complete(partial) and not jsgf.match(partial)


@pytest.mark.parametrize(
    ("ipa", "phones"),
    [
        ("dˈoə", "D AO"),  # Caribbean "door"
        ("stˈandɪn", "S T AE N D IH N"),  # Caribbean "standing": no velar nasal
        ("wˈɜːkbɛntʃ", "W ER K B EH N CH"),  # length mark dropped, affricate as one phone
        ("rˈʉːm", "R UW M"),  # Scottish "room"
        ("ðə", "DH AH"),
        ("t̪ˈaŋk", "T AE NG K"),  # dental diacritic ignored
    ],
)
def test_espeak_ipa_maps_onto_cmu_phones(ipa, phones):
    assert lexicon.ipa_to_arpabet(ipa) == phones.split()


def test_unknown_ipa_symbol_names_the_table_to_extend():
    with pytest.raises(SpeechError, match=r"'ʀ'.*'rouge'.*IPA_TO_ARPABET in embodied_adhoc/comms/lexicon.py"):
        lexicon.ipa_to_arpabet("ʀuʒ", "rouge")


def test_dictionary_adds_each_accent_pronunciation():
    assert lexicon.ACCENTS == ("en-us", "en-gb", "en-gb-scotland", "en-gb-x-rp", "en-029")
    assert ["D", "AH"] in lexicon.accent_pronunciations("the", ["en-029"])  # TH-stopping
    full = grammar.dictionary_text(grammar.cmudict_path()).splitlines()
    cmu_only = grammar.dictionary_text(grammar.cmudict_path(), accents=()).splitlines()
    assert set(cmu_only) < set(full)
    pronunciations = {line.split(" ", 1)[1] for line in full if line.split()[0].split("(")[0] == "standing"}
    assert {"S T AE N D IH NG", "S T AE N D IH N"} <= pronunciations
    # Variants are numbered after the CMU entries, none repeated.
    heads = [line.split()[0] for line in full]
    assert len(heads) == len(set(heads)) and len(full) == len(set(full))
