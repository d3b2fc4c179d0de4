"""Accent pronunciations for the recognition dictionary, from espeak-ng's letter-to-sound rules.

pocketsphinx's dictionary and acoustic model are American English (CMU phone set). Speakers of other accents say
the grammar's words differently: Caribbean English stops "the" to /də/ and drops the velar in "-ing" (/stˈandɪn/),
Scottish English keeps the r and rounds "room" (/rˈʉːm/), southern British English drops it ("door" /dɔː/). A
multi-accent pronunciation dictionary lets the decoder follow those phone sequences instead of forcing them onto
the American ones. The variants are generated, not hand-written: espeak-ng phonemises each word in each accent
(``espeak-ng -q --ipa -v LANGUAGE WORD``) and :func:`ipa_to_arpabet` maps the IPA onto the 39 CMU phones the
acoustic model knows.

A caveat for reading the measured accuracies: the evaluation's speakers are espeak-ng voices too, so for them
these variants are exactly what is said. For people the variants are the accents' textbook features, not a
measured lexicon.
"""

from __future__ import annotations

import functools
import subprocess
from collections.abc import Iterable

from embodied_adhoc.comms.synthesis import DEFAULT_VOICES, require_espeak
from embodied_adhoc.errors import SpeechError

ACCENTS: tuple[str, ...] = tuple(dict.fromkeys(voice.split("+", 1)[0] for voice in DEFAULT_VOICES))
"""espeak-ng languages (accents) whose pronunciations are added: those of the default voices, without the
timbre variant (``en-029+m3`` -> ``en-029``)."""

IPA_TO_ARPABET: dict[str, str] = {
    # diphthongs and affricates first (longest match wins)
    "aɪ": "AY", "aʊ": "AW", "eɪ": "EY", "ɔɪ": "OY", "oʊ": "OW", "əʊ": "OW", "oə": "AO",
    "ɪə": "IH AH", "eə": "EH AH", "ʊə": "UH AH", "tʃ": "CH", "dʒ": "JH",
    # vowels (length marks are dropped before matching)
    "ɜ": "ER", "ɚ": "ER", "ɑ": "AA", "ɒ": "AA", "ɔ": "AO", "ʉ": "UW", "u": "UW", "i": "IY", "o": "OW",
    "e": "EY", "æ": "AE", "a": "AE", "ʌ": "AH", "ə": "AH", "ɐ": "AH", "ɛ": "EH", "ɪ": "IH", "ᵻ": "IH",
    "ʊ": "UH",
    # consonants
    "p": "P", "b": "B", "t": "T", "d": "D", "k": "K", "ɡ": "G", "g": "G", "f": "F", "v": "V", "θ": "TH",
    "ð": "DH", "s": "S", "z": "Z", "ʃ": "SH", "ʒ": "ZH", "h": "HH", "m": "M", "n": "N", "ŋ": "NG", "l": "L",
    "ɹ": "R", "r": "R", "ɾ": "T", "w": "W", "j": "Y", "x": "K", "ʔ": "T", "ɬ": "L",
}  # fmt: skip
"""espeak-ng's English IPA symbols -> CMU phones. A flap (ɾ) and a glottal stop (ʔ) stand for /t/ in English."""

IGNORED = frozenset("ˈˌː.-_ \u0303\u0329\u032a")
"""Stress and length marks, syllable breaks, and diacritics (nasal, syllabic, dental) carry no CMU phone."""

_KEYS = sorted(IPA_TO_ARPABET, key=len, reverse=True)


def ipa_to_arpabet(ipa: str, word: str = "") -> list[str]:
    """CMU phones of an espeak-ng IPA string (longest symbol first). An unknown symbol is a :class:`SpeechError`."""
    phones: list[str] = []
    index = 0
    while index < len(ipa):
        if ipa[index] in IGNORED:
            index += 1
            continue
        for key in _KEYS:
            if ipa.startswith(key, index):
                phones += IPA_TO_ARPABET[key].split()
                index += len(key)
                break
        else:
            raise SpeechError(
                f"espeak-ng IPA symbol {ipa[index]!r} (U+{ord(ipa[index]):04X}) in {ipa!r}"
                f"{f' for {word!r}' if word else ''} has no CMU phone; add it to IPA_TO_ARPABET in "
                "embodied_adhoc/comms/lexicon.py"
            )
    if not phones:
        raise SpeechError(f"espeak-ng gave no phones for {word!r} ({ipa!r})")
    return phones


@functools.cache
def espeak_ipa(word: str, language: str) -> str:
    """espeak-ng's IPA for ``word`` alone, in ``language`` (an accent such as ``en-gb-scotland``)."""
    result = subprocess.run(
        [require_espeak(), "-q", "--ipa", "-v", language, word], capture_output=True, text=True, check=False
    )
    if result.returncode != 0 or result.stderr.strip() or not result.stdout.strip():
        raise SpeechError(
            f"espeak-ng could not phonemise {word!r} in {language!r} (exit {result.returncode}): "
            f"{result.stderr.strip() or 'no output'}; list the languages with `espeak-ng --voices=en`"
        )
    return result.stdout.strip()


def accent_pronunciations(word: str, accents: Iterable[str] = ACCENTS) -> list[list[str]]:
    """The distinct CMU pronunciations of ``word`` in each accent, in accent order."""
    found: list[list[str]] = []
    for language in accents:
        phones = ipa_to_arpabet(espeak_ipa(word, language), word)
        if phones not in found:
            found.append(phones)
    return found
