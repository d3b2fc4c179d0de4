"""Cassandra's ``.pomdp`` file format: reader and writer for the whole format (pomdp-solve's file spec).

Covered: states/actions/observations as counts or names (entries may then be named or 0-based indices);
``discount``; ``values: reward|cost`` (cost is negated); every ``start`` form (a vector, ``uniform``, one state,
``start include: ...`` and ``start exclude: ...``); ``T``/``O``/``R`` per entry, per row or as a whole matrix,
with ``uniform``, ``identity`` and ``reset`` (a row equal to the start belief); ``*`` wildcards anywhere; later
statements overriding earlier ones; numbers spanning any number of lines; ``#`` comments; and rewards
``R(a, s, s', z)`` depending on the end state and observation, collapsed to the immediate expected reward
``R(s, a) = sum_{s', z} T(s, a, s') O(a, s', z) R(a, s, s', z)``.

How it reads (fast and sparse): the text is split into tokens once (the line of every token comes from one
vectorised pass over the bytes); the statements of the common one-entry forms (``T: a : s : s' p``,
``O: a : s' : z p``, ``R: a : s : s' : z r``, which are 95 % of the corpus) are decoded together with numpy, every
other statement by a recursive-descent parser. Nothing is dense: every statement becomes (action, row, column,
value, statement number) entries plus "clear this row/column" marks (``identity``, a whole row, a ``0``
wildcard), and the model is resolved at the end, the last statement writing an entry winning. A statement that
would write more than :data:`MAX_ENTRIES` entries (a dense ``|S| x |S|`` block such as ``T: * uniform`` with
100,000 states) is refused with a size error naming its line; ``identity`` and per-entry files of any size stay
sparse. Every row of T and of O holds at least one entry, so a header whose ``2 |A| |S|`` exceeds
:data:`MAX_ENTRIES` (or whose ``|A| |Z|`` does) describes a model this reader cannot hold: it is refused at the
header line, before anything of that size is allocated. Files are read up to :data:`MAX_FILE_CHARS`.

Errors are :class:`PomdpFormatError` with ``file:line``, what was found and what was expected. Probability rows
that do not sum to 1 (beyond :data:`~embodied_adhoc.decision.models.PROBABILITY_ATOL`) are errors naming the row
and the line that last wrote it; a negative probability names its entry and line; a number that overflows to
infinity names its line; nothing is renormalised.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from embodied_adhoc import checks
from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.decision.models import POMDP, PROBABILITY_ATOL
from embodied_adhoc.errors import ModelError, PomdpFormatError

_NUMBER_TEXT = r"[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?)"
_NUMBER = re.compile(rf"^{_NUMBER_TEXT}$")
_NOT_IN_NUMBERS = re.compile(r"[^0-9eE+\-. ]")  # no nan/inf/1_0: float() then accepts exactly _NUMBER
_INTEGER = re.compile(r"^\d+$")
_COMMENT = re.compile(r"#[^\n]*")
_KEYWORDS = {"discount", "values", "states", "actions", "observations", "start", "T", "O", "R"}
_MATRIX_WORDS = {"uniform", "identity", "reset"}
_ASCII_SPACE = np.array([chr(code).isspace() for code in range(128)])  # str.split()'s whitespace
_WILD = -1  # a '*' selector in index arrays
MAX_ENTRIES = 10_000_000
"""Most (action, row, column) entries the reader holds for T and O together (40 bytes each while parsing)."""
MAX_FILE_CHARS = 1 << 28
"""Longest ``.pomdp`` file read, in characters (256 Mi: about ten million per-entry lines, what
:data:`MAX_ENTRIES` admits)."""
MISSING_ROWS = ("error", "absorbing", "reset")
"""What to do with a transition row ``T(. | s, a)`` that the file never writes (e.g. mini-hall2's goal state):
an error (default), a self-loop, or the start belief. Rows written but not summing to 1 are always errors."""


_LONG = 1 << 21  # added to the code of a token's first character when the token is longer than one character


def _tokenize(text: str) -> tuple[Sequence[str], np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """Tokens (``:`` always a token of its own, ``#`` to the end of the line a comment), a code per token (its
    character if it has one, else the code of its first character plus ``_LONG``) and a function giving the
    1-based lines (as ``str.splitlines`` counts them) of an array of token indices."""
    text = "\n".join(text.splitlines())
    if "#" in text:
        text = _COMMENT.sub("", text)
    text = text.replace(":", " : ")
    if text.isascii():  # one vectorised pass over the bytes finds where each token starts and ends
        data = np.frombuffer(text.encode("ascii"), dtype=np.uint8)
        space = _ASCII_SPACE[data]  # str.split()'s whitespace, so the tokens are text.split()'s
        after_space = np.empty(len(data), dtype=bool)
        after_space[:1] = True
        after_space[1:] = space[:-1]
        offsets = np.flatnonzero(~space & after_space)
        before_space = np.empty(len(data), dtype=bool)
        before_space[-1:] = True
        before_space[:-1] = space[1:]
        ends = np.flatnonzero(~space & before_space) + 1
        longer = ends - offsets > 1
        newlines = np.flatnonzero(data == 10)
        return (
            _TokenTexts(text, offsets, ends),
            data[offsets].astype(np.int64) + _LONG * longer,
            (lambda indices: np.searchsorted(newlines, offsets[indices]) + 1),
        )
    tokens = text.split()
    counts = [len(line.split()) for line in text.split("\n")]
    lines = np.repeat(np.arange(1, len(counts) + 1), counts)
    codes = [ord(token[0]) + (_LONG if len(token) > 1 else 0) for token in tokens]
    return tokens, np.array(codes, dtype=np.int64), lines.__getitem__


class _TokenTexts(Sequence[str]):
    """The tokens of an ASCII text as slices of it, made when read: a list of every token as a string holds about
    60 bytes a token, most of what reading a large file takes."""

    def __init__(self, text: str, starts: np.ndarray, ends: np.ndarray) -> None:
        self.text, self.starts, self.ends = text, starts, ends

    def __len__(self) -> int:
        return len(self.starts)

    def __getitem__(self, index):
        text = self.text
        if isinstance(index, slice):
            return [
                text[start:end]
                for start, end in zip(self.starts[index].tolist(), self.ends[index].tolist(), strict=True)
            ]
        return text[int(self.starts[index]) : int(self.ends[index])]


def _gather(texts: list[str], positions: np.ndarray, stride: int) -> list[str]:
    """``[texts[p] for p in positions]``, by slices over runs of positions ``stride`` apart (consecutive
    statements of the same length), which is several times faster."""
    breaks = np.flatnonzero(np.diff(positions) != stride) + 1
    gathered: list[str] = []
    for first, last in zip(
        np.append(0, breaks).tolist(), np.append(breaks, len(positions)).tolist(), strict=True
    ):
        if last > first:
            gathered.extend(texts[positions[first] : positions[last - 1] + 1 : stride])
    return gathered


def _floats(texts: list[str]) -> np.ndarray | None:
    """The numbers, or None if one of ``texts`` is not a number of the format (``_NUMBER``)."""
    if _NOT_IN_NUMBERS.search(" ".join(texts)):
        return None
    try:
        return np.array(texts, dtype=np.float64)
    except ValueError:
        return None


class _Tokens:
    """A token stream with positions, for a recursive-descent parser with precise error messages."""

    def __init__(self, text: str, filename: str) -> None:
        self.filename = filename
        self.texts, self.codes, self.lines = _tokenize(text)
        self.count = len(self.texts)
        self.position = 0

    def peek(self, offset: int = 0) -> str | None:
        index = self.position + offset
        return self.texts[index] if index < self.count else None

    def line(self, index: int) -> int:
        """The line of token ``index``; the last line for the end of the file."""
        if index < self.count:
            return int(self.lines(index))
        return int(self.lines(self.count - 1)) if self.count else 1

    def next(self, expected: str) -> str:
        if self.position >= self.count:
            raise self.error(self.position, expected)
        self.position += 1
        return self.texts[self.position - 1]

    def error(self, index: int, expected: str) -> PomdpFormatError:
        """An error at token ``index`` (at or past the end: the end of the file)."""
        if index >= self.count:
            return PomdpFormatError(
                f"{self.filename}:{self.line(index)}: found end of file, expected {expected}"
            )
        return PomdpFormatError(
            f"{self.filename}:{self.line(index)}: found '{self.texts[index]}', expected {expected}"
        )

    def expect(self, text: str, context: str) -> None:
        if self.next(f"'{text}' {context}") != text:
            raise self.error(self.position - 1, f"'{text}' {context}")

    def at_number(self) -> bool:
        token = self.peek()
        return token is not None and bool(_NUMBER.match(token))

    def numbers(self, count: int, what: str) -> np.ndarray:
        first = self.position
        chunk = self.texts[first : first + count]
        values = _floats(chunk)
        if values is None:
            match = _NUMBER.match
            bad = next(index for index, token in enumerate(chunk) if not match(token))
            raise self.error(first + bad, f"{count} numbers for {what} (got {bad})")
        if len(chunk) < count:
            raise self.error(first + len(chunk), f"{count} numbers for {what} (got {len(chunk)})")
        self.position += count
        if self.at_number():
            raise self.error(self.position, f"the end of {what} after {count} numbers (too many numbers)")
        return values


def _statement_starts(tokens: _Tokens, first: int) -> np.ndarray:
    """Indices (>= first) of the tokens 'T', 'O' or 'R' followed by ':' (statement keywords)."""
    codes = tokens.codes[first:]
    if len(codes) < 2:
        return np.zeros(0, dtype=np.int64)
    keyword = (codes[:-1] == ord("T")) | (codes[:-1] == ord("O")) | (codes[:-1] == ord("R"))
    return first + np.flatnonzero(keyword & (codes[1:] == ord(":")))


class _Writes:
    """Writes into a sparse ``(|A|, rows, columns)`` probability array, in file order, resolved at the end.

    Entries are kept as (action, row, column, value, statement) arrays; a statement that writes a whole row
    (or, with a ``0`` wildcard, a whole column) also records that it clears it. An entry survives if it is the
    last write of its cell and no later statement cleared its row or column.
    """

    def __init__(self, shape: tuple[int, int, int], budget: list[int], parser: _Parser) -> None:
        n_actions, n_rows, n_columns = shape
        self.shape = shape
        self.parts: list[tuple[np.ndarray, ...]] = []
        self.budget = budget  # shared by T and O: [entries left]
        self.parser = parser
        self.row_clear = np.full((n_actions, n_rows), -1, dtype=np.int64)
        self.column_clear = np.full((n_actions, n_columns), -1, dtype=np.int64)
        self.row_written = np.full((n_actions, n_rows), -1, dtype=np.int64)

    def _reserve(self, count: int, seq: int, what: str) -> None:
        if count > self.budget[0]:
            raise PomdpFormatError(
                f"{self.parser.filename}:{self.parser.statement_line(seq)}: {what} writes {count:,} entries, more "
                f"than this reader holds ({MAX_ENTRIES:,} for T and O together): the model would be dense; "
                "write it sparsely (per entry or per row, e.g. 'T: a : s : s' p'), or use fewer states"
            )
        self.budget[0] -= count

    def entries(self, actions, rows, columns, values, seqs) -> None:
        """Explicit entries (equal-length arrays; ``actions`` may hold ``_WILD``)."""
        wild = actions == _WILD
        if wild.any():
            repeats = np.where(wild, self.shape[0], 1)
            index = np.repeat(np.arange(len(actions)), repeats)
            within = np.arange(len(index)) - np.repeat(np.cumsum(repeats) - repeats, repeats)
            actions = np.where(wild[index], within, actions[index])
            rows, columns, values, seqs = rows[index], columns[index], values[index], seqs[index]
        if len(actions):  # past the budget: name the statement where it ran out
            self._reserve(len(actions), int(seqs[min(len(seqs) - 1, self.budget[0])]), "the file's entries")
        self.parts.append((actions, rows, columns, values, seqs))
        np.maximum.at(self.row_written, (actions, rows), seqs)

    def product(self, actions, rows, columns, values, seq: int, what: str, clear_rows: bool = False) -> None:
        """Every (action, row) pair gets the same ``columns``/``values``; ``clear_rows``: the rest of each row
        becomes 0 (the statement writes whole rows)."""
        n_pairs = len(actions) * len(rows)
        self._reserve(n_pairs * len(columns), seq, what)
        # Statements parsed one by one come in file order, so plain assignment keeps the latest statement.
        cell = np.ix_(actions, rows) if n_pairs > 1 else (actions[0], rows[0])
        self.row_written[cell] = seq
        if clear_rows:
            self.row_clear[cell] = seq
        if len(columns) == 0 or n_pairs == 0:
            return
        if n_pairs == 1:
            count = len(columns)
            self.parts.append(
                (np.full(count, actions[0]), np.full(count, rows[0]), columns, values, np.full(count, seq))
            )
            return
        self.parts.append(
            (
                np.repeat(actions, len(rows) * len(columns)),
                np.tile(np.repeat(rows, len(columns)), len(actions)),
                np.tile(columns, n_pairs),
                np.tile(values, n_pairs),
                np.full(n_pairs * len(columns), seq, dtype=np.int64),
            )
        )

    def matrix(self, actions, rows, columns, values, seq: int, what: str) -> None:
        """Whole matrices: the entries (rows, columns, values) for every action, every other entry 0."""
        self._reserve(len(actions) * len(rows), seq, what)
        self.row_written[actions] = seq
        self.row_clear[actions] = seq
        count = len(rows)
        self.parts.append(
            (
                np.repeat(actions, count),
                np.tile(rows, len(actions)),
                np.tile(columns, len(actions)),
                np.tile(values, len(actions)),
                np.full(count * len(actions), seq, dtype=np.int64),
            )
        )

    def clear_columns(self, actions, column: int, seq: int) -> None:
        """``X: a : * : c 0``: column ``c`` of every row becomes 0 (every row counts as written)."""
        self.column_clear[actions, column] = seq
        self.row_written[actions] = seq

    def resolve(self) -> tuple[np.ndarray, ...]:
        """The surviving nonzero-or-zero entries, sorted by (action, row, column): (a, row, col, value, seq)."""
        n_actions, n_rows, n_columns = self.shape
        if not self.parts:
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty, empty, np.zeros(0), empty
        actions, rows, columns, values, seqs = (
            np.concatenate(arrays) for arrays in zip(*self.parts, strict=True)
        )
        keys = (actions.astype(np.int64) * n_rows + rows) * n_columns + columns
        order = np.lexsort((seqs, keys))
        keys = keys[order]
        last = np.ones(len(keys), dtype=bool)
        last[:-1] = keys[1:] != keys[:-1]
        order = order[last]
        actions, rows, columns, values, seqs = (x[order] for x in (actions, rows, columns, values, seqs))
        alive = (seqs >= self.row_clear[actions, rows]) & (seqs >= self.column_clear[actions, columns])
        return tuple(x[alive] for x in (actions, rows, columns, values, seqs))


class _Parser:
    def __init__(self, text: str, filename: str, missing_rows: str = "error") -> None:
        if missing_rows not in MISSING_ROWS:
            raise PomdpFormatError(f"missing_rows must be one of {MISSING_ROWS}, got {missing_rows!r}")
        self.missing_rows = missing_rows
        self.tokens = _Tokens(text, filename)
        self.filename = filename
        self.discount: float | None = None
        self.cost = False
        self.names: dict[str, list[str] | None] = {}
        self.counts: dict[str, int] = {}
        self.lookups: dict[str, dict[str, int]] = {}
        self.start: np.ndarray | None = None
        self.start_line = 0
        self.statement_lines = np.zeros(0, dtype=np.int64)  # line of body statement k (its 'seq')
        self.transitions: _Writes | None = None
        self.observations: _Writes | None = None
        self.reward_parts: list[tuple[np.ndarray, ...]] = []  # (seq, action, start, end, observation, value)

    def statement_line(self, seq: int) -> int:
        return (
            int(self.statement_lines[seq])
            if seq < len(self.statement_lines)
            else self.tokens.line(self.tokens.count)
        )

    # ------------------------------------------------------------------------------------ preamble
    def parse_statements(self) -> None:
        tokens = self.tokens
        while (token := tokens.peek()) is not None and token not in ("T", "O", "R"):
            self._preamble_statement()
        found = f"'{token}'" if token is not None else "end of file"
        for kind in ("discount", "states", "actions", "observations"):
            if (kind == "discount" and self.discount is None) or (
                kind != "discount" and kind not in self.counts
            ):
                raise PomdpFormatError(
                    f"{self.filename}:{tokens.line(tokens.position)}: found {found} before any '{kind}:' line, "
                    f"expected '{kind}:' in the preamble"
                )
        n_states, n_actions, n_obs = self.sizes()
        if self.start is None:
            self.start = np.full(n_states, 1.0 / n_states)  # the spec's default: uniform
        for kind in ("states", "actions", "observations"):
            lookup = {str(index): index for index in range(self.counts[kind])}
            lookup.update((name, index) for index, name in enumerate(self.names[kind] or ()))
            lookup["*"] = _WILD
            self.lookups[kind] = lookup
        budget = [MAX_ENTRIES]
        self.transitions = _Writes((n_actions, n_states, n_states), budget, self)
        self.observations = _Writes((n_actions, n_states, n_obs), budget, self)
        self._body(tokens.position)

    def _body(self, first: int) -> None:
        tokens = self.tokens
        if first >= tokens.count:
            return
        starts = _statement_starts(tokens, first)
        if any(name in ("T", "O", "R") for names in self.names.values() for name in names or ()):
            starts = np.zeros(0, dtype=np.int64)  # a name 'T' could be a statement keyword: parse one by one
        if len(starts) == 0 or starts[0] != first:
            self.statement_lines = tokens.lines(np.array([first]))
            tokens.position = first
            self._statement(0)  # raises (not a statement), or this file needs the one-by-one parse
            return self._sequential_body()
        self.statement_lines = tokens.lines(starts)
        ends = np.append(starts[1:], tokens.count)
        lengths = ends - starts
        letters = tokens.codes[starts]
        one_entry = {  # 'T: a : s : s' p' / 'O: a : s' : z p' (8 tokens), 'R: a : s : s' : z r' (10 tokens)
            "T": (np.flatnonzero((letters == ord("T")) & (lengths == 8)), ("actions", "states", "states")),
            "O": (
                np.flatnonzero((letters == ord("O")) & (lengths == 8)),
                ("actions", "states", "observations"),
            ),
            "R": (
                np.flatnonzero((letters == ord("R")) & (lengths == 10)),
                ("actions", "states", "states", "observations"),
            ),
        }
        decoded = {letter: self._decode(starts, *found) for letter, found in one_entry.items()}
        general = np.ones(len(starts), dtype=bool)
        for seqs, _, _ in decoded.values():
            general[seqs] = False
        for seq in np.flatnonzero(general).tolist():  # every other statement, in file order (errors in order)
            tokens.position = int(starts[seq])
            self._statement(seq)
            while tokens.position < ends[seq]:
                self._statement(seq)  # leftover tokens: raises the error the one-by-one parse would
        for letter, writes in (("T", self.transitions), ("O", self.observations)):
            seqs, (actions, rows, columns), values = decoded[letter]
            if len(seqs):
                writes.entries(actions, rows, columns, values, seqs)
        seqs, selectors, values = decoded["R"]
        if len(seqs):
            self.reward_parts.append((seqs, *selectors, values))

    def _decode(self, starts: np.ndarray, seqs: np.ndarray, kinds: tuple[str, ...]):
        """Decode one-entry statements (``seqs``, all of the same letter and length) together.

        Returns the statements decoded, their selector indices (one array per selector, ``_WILD`` for '*') and
        their values. T and O entries with '*' for a row or column, unknown names and malformed numbers are left
        to the statement parser (which expands wildcards, or raises the precise error).
        """
        tokens, texts = self.tokens, self.tokens.texts
        positions = starts[seqs]
        ok = np.ones(len(seqs), dtype=bool)
        for slot in range(len(kinds)):  # ':' after the keyword and after each selector but the last
            ok &= tokens.codes[positions + 1 + 2 * slot] == ord(":")
        seqs, positions = seqs[ok], positions[ok]
        ok = np.ones(len(seqs), dtype=bool)
        selectors = []
        length = 2 * len(kinds) + 2
        for slot, kind in enumerate(kinds):
            get = self.lookups[kind].get
            found = np.array(
                [get(t, -2) for t in _gather(texts, positions + 2 + 2 * slot, length)], dtype=np.int64
            )
            ok &= (found != -2) & ((found != _WILD) | (slot == 0) | (len(kinds) == 4))
            selectors.append(found)
        value_texts = _gather(texts, positions + length - 1, length)
        values = _floats(value_texts)
        if values is None:
            good = np.array([bool(_NUMBER.match(t)) for t in value_texts], dtype=bool)
            ok &= good
            values = _floats([t if g else "0" for t, g in zip(value_texts, good.tolist(), strict=True)])
        return seqs[ok], tuple(x[ok] for x in selectors), values[ok]

    def _sequential_body(self) -> None:
        tokens = self.tokens
        lines: list[int] = [int(self.statement_lines[0])]
        seq = 1
        while tokens.peek() is not None:
            lines.append(tokens.line(tokens.position))
            self.statement_lines = np.array(lines, dtype=np.int64)
            self._statement(seq)
            seq += 1

    def _statement(self, seq: int) -> None:
        tokens = self.tokens
        token = tokens.peek()
        if token not in ("T", "O", "R"):
            raise tokens.error(
                tokens.position, "a 'T:', 'O:' or 'R:' statement (preamble lines must come first)"
            )
        tokens.next("T, O or R")
        tokens.expect(":", f"after '{token}'")
        {"T": self._transition, "O": self._observation, "R": self._reward}[token](seq)

    def _preamble_statement(self) -> None:
        tokens = self.tokens
        token = tokens.next("a preamble statement")
        if token not in _KEYWORDS:
            raise tokens.error(
                tokens.position - 1,
                "one of discount:, values:, states:, actions:, observations:, start:, T:, O:, R:",
            )
        if token == "start":
            return self._start()
        tokens.expect(":", f"after '{token}'")
        if token == "discount":
            value = tokens.next("a discount in [0, 1]")
            if not _NUMBER.match(value) or not 0.0 <= float(value) <= 1.0:
                raise tokens.error(tokens.position - 1, "a discount in [0, 1]")
            self.discount = float(value)
        elif token == "values":
            value = tokens.next("'reward' or 'cost'")
            if value not in ("reward", "cost", "rewards", "costs"):  # plural seen in the wild (ejs4-7)
                raise tokens.error(tokens.position - 1, "'reward' or 'cost'")
            self.cost = value.startswith("cost")
        else:
            self._declaration(token)

    def _declaration(self, kind: str) -> None:
        tokens = self.tokens
        first_index = tokens.position
        first = tokens.next(f"a count or a list of {kind}")
        if _INTEGER.match(first):
            count = int(first)
            if count < 1:
                raise tokens.error(first_index, f"a positive number of {kind}")
            self.counts[kind], self.names[kind] = count, None
            self._check_counts(first_index)
            return
        if first in _KEYWORDS or first == ":" or _NUMBER.match(first):
            raise tokens.error(first_index, f"a count or a list of {kind} names")
        names = [first]
        while (token := tokens.peek()) is not None and not self._starts_statement():
            if token == "*" or _NUMBER.match(token):
                raise tokens.error(
                    tokens.position, f"a name of one of the {kind} (names start with a letter)"
                )
            names.append(tokens.next("a name"))
        if len(set(names)) != len(names):
            times = Counter(names)
            duplicate = next(n for n in names if times[n] > 1)
            raise PomdpFormatError(
                f"{self.filename}:{tokens.line(first_index)}: {kind} name '{duplicate}' is declared twice"
            )
        self.counts[kind], self.names[kind] = len(names), names
        self._check_counts(first_index)

    def _check_counts(self, index: int) -> None:
        """Refuse counts whose model cannot fit (checked as each count is declared, before its arrays exist)."""
        n_states, n_actions = self.counts.get("states", 1), self.counts.get("actions", 1)
        n_obs = self.counts.get("observations", 1)
        needed = {
            "2 x actions x states: one entry per row of T and of O": 2 * n_actions * n_states,
            "actions x observations": n_actions * n_obs,
        }
        declared = ", ".join(f"{count:,} {kind}" for kind, count in self.counts.items())
        for what, count in needed.items():
            if count > MAX_ENTRIES:
                raise PomdpFormatError(
                    f"{self.filename}:{self.tokens.line(index)}: {declared} need at least {count:,} entries "
                    f"({what}), more than this reader holds ({MAX_ENTRIES:,}); use a smaller model"
                )

    def _starts_statement(self) -> bool:
        token, after = self.tokens.peek(), self.tokens.peek(1)
        if token is None:
            return True
        if token in ("T", "O", "R", "discount", "values", "states", "actions", "observations"):
            return after == ":"
        return token == "start" and after in (":", "include", "exclude")

    def _start(self) -> None:
        tokens = self.tokens
        keyword_index = tokens.position - 1
        if "states" not in self.counts:
            raise tokens.error(keyword_index, "'states:' before 'start:'")
        n_states = self.counts["states"]
        mode = tokens.next("':', 'include' or 'exclude' after 'start'")
        self.start_line = tokens.line(keyword_index)
        if mode in ("include", "exclude"):
            tokens.expect(":", f"after 'start {mode}'")
            chosen = np.zeros(n_states, dtype=bool)
            listed = 0
            while tokens.peek() is not None and not self._starts_statement():
                chosen[self._index("states", "a state", wildcard=False)] = True
                listed += 1
            if listed == 0:
                raise tokens.error(tokens.position, f"a list of states after 'start {mode}:'")
            if mode == "exclude":
                chosen = ~chosen
            if not chosen.any():
                raise PomdpFormatError(
                    f"{self.filename}:{self.start_line}: 'start exclude:' excludes every state"
                )
            self.start = chosen / chosen.sum()
            return
        if mode != ":":
            raise tokens.error(tokens.position - 1, "':', 'include' or 'exclude' after 'start'")
        token = tokens.peek()
        if token == "uniform":
            tokens.next("uniform")
            self.start = np.full(n_states, 1.0 / n_states)
        elif token is not None and not _NUMBER.match(token):
            # One state name; several names (as in pomdp-ex.pomdp) read like 'start include:'.
            chosen = np.zeros(n_states, dtype=bool)
            chosen[self._index("states", "a state", wildcard=False)] = True
            while tokens.peek() is not None and not self._starts_statement() and not tokens.at_number():
                chosen[self._index("states", "a state", wildcard=False)] = True
            self.start = chosen / chosen.sum()
        elif token is not None and _INTEGER.match(token) and n_states > 1 and not self._number_follows():
            self.start = np.zeros(n_states)  # 'start: 3' names state 3 (a vector would need |S| numbers)
            self.start[self._index("states", "a state", wildcard=False)] = 1.0
        else:
            self.start = tokens.numbers(n_states, "the start belief")
            self._check_distribution(self.start, "the start belief", self.start_line)

    def _number_follows(self) -> bool:
        after = self.tokens.peek(1)
        return after is not None and bool(_NUMBER.match(after))

    def _check_distribution(self, values: np.ndarray, what: str, line: int) -> None:
        if not np.all(np.isfinite(values)):
            raise PomdpFormatError(f"{self.filename}:{line}: {what} has a number too large for a float (inf)")
        if values.min() < 0:
            state = int(np.argmin(values))
            raise PomdpFormatError(
                f"{self.filename}:{line}: {what} gives state {self._label('states', state)} the negative "
                f"probability {values[state]:g}; expected probabilities >= 0 summing to 1"
            )
        if abs(values.sum() - 1.0) > PROBABILITY_ATOL:
            raise PomdpFormatError(
                f"{self.filename}:{line}: {what} sums to {values.sum():.8g}, expected a probability vector summing to 1"
            )

    # ------------------------------------------------------------------------------ identifiers
    def _index(self, kind: str, expected: str = "a state", wildcard: bool = True) -> int:
        """The next token as an index of ``kind`` (``_WILD`` for '*' where allowed)."""
        tokens = self.tokens
        token = tokens.next(expected)
        index = self.lookups[kind].get(token) if kind in self.lookups else None
        if index is None:
            names = self.names[kind]
            if names is not None and token in names:
                index = names.index(token)
            elif token == "*":
                index = _WILD
            elif _INTEGER.match(token) and int(token) < self.counts[kind]:
                index = int(token)
        if index is not None and (index != _WILD or wildcard):
            return index
        names = self.names[kind]
        singular = kind[:-1]
        choices = f"a name of {names[:6]}{'...' if len(names) > 6 else ''}" if names else "no names"
        raise tokens.error(
            tokens.position - 1,
            f"a {singular}{' or *' if wildcard else ''}: an index 0..{self.counts[kind] - 1} or {choices}",
        )

    def _colon_follows(self) -> bool:
        return self.tokens.peek() == ":"

    def _all(self, kind: str, index: int) -> np.ndarray:
        return np.arange(self.counts[kind]) if index == _WILD else np.array([index])

    # ------------------------------------------------------------------------------- T, O, R
    def _transition(self, seq: int) -> None:
        self._probabilities(
            seq, "T", self.transitions, "states", "T(s' | s, a)", "transition", allow_reset=True
        )

    def _observation(self, seq: int) -> None:
        self._probabilities(
            seq, "O", self.observations, "observations", "O(z | s', a)", "observation", allow_reset=False
        )

    def _probabilities(
        self,
        seq: int,
        letter: str,
        writes: _Writes,
        column_kind: str,
        entry: str,
        noun: str,
        allow_reset: bool,
    ) -> None:
        tokens = self.tokens
        n_states, n_columns = self.counts["states"], self.counts[column_kind]
        row_word, column_word, row_symbol, column_symbol = (
            ("a start state", "an end state", "s", "s'")
            if letter == "T"
            else ("an end state", "an observation", "s'", "z")
        )
        action = self._index("actions", f"an action or * after '{letter}:'")
        actions = self._all("actions", action)
        if not self._colon_follows():  # a whole matrix
            token = tokens.peek()
            what = f"'{letter}: {'*' if action == _WILD else action}' {token}"
            if token == "identity" and letter == "T":
                tokens.next("identity")
                everything = np.arange(n_states)
                writes.matrix(actions, everything, everything, np.ones(n_states), seq, what)
            elif token == "uniform":
                tokens.next("uniform")
                writes.product(
                    actions,
                    np.arange(n_states),
                    np.arange(n_columns),
                    np.full(n_columns, 1.0 / n_columns),
                    seq,
                    what,
                )
            elif token == "reset" and allow_reset:
                tokens.next("reset")
                support = np.flatnonzero(self.start)
                writes.product(
                    actions, np.arange(n_states), support, self.start[support], seq, what, clear_rows=True
                )
            else:
                shape = "|S| x |S|, or identity/uniform/reset" if letter == "T" else "|S| x |Z|, or uniform"
                matrix = tokens.numbers(n_states * n_columns, f"the {noun} matrix ({shape})")
                nonzero = np.flatnonzero(matrix)
                writes.matrix(actions, nonzero // n_columns, nonzero % n_columns, matrix[nonzero], seq, what)
            return
        tokens.next(":")
        row = self._index("states", f"{row_word} or * in '{letter}: a : {row_symbol}'")
        rows = self._all("states", row)
        if not self._colon_follows():  # one row (or every row, for '*')
            token = tokens.peek()
            what = f"this '{letter}:' row statement"
            if token == "uniform":
                tokens.next("uniform")
                writes.product(
                    actions, rows, np.arange(n_columns), np.full(n_columns, 1.0 / n_columns), seq, what
                )
            elif token == "reset" and allow_reset:
                tokens.next("reset")
                support = np.flatnonzero(self.start)
                writes.product(actions, rows, support, self.start[support], seq, what, clear_rows=True)
            else:
                values = tokens.numbers(n_columns, f"the {noun} row")
                nonzero = np.flatnonzero(values)
                writes.product(actions, rows, nonzero, values[nonzero], seq, what, clear_rows=True)
            return
        tokens.next(":")
        column = self._index(
            column_kind, f"{column_word} or * in '{letter}: a : {row_symbol} : {column_symbol}'"
        )
        value = float(tokens.numbers(1, entry)[0])
        if row != _WILD and column != _WILD:
            writes.entries(
                actions,
                np.full(len(actions), row),
                np.full(len(actions), column),
                np.full(len(actions), value),
                np.full(len(actions), seq, dtype=np.int64),
            )
        elif value == 0.0 and column == _WILD:
            writes.product(actions, rows, np.zeros(0, dtype=np.int64), np.zeros(0), seq, "", clear_rows=True)
        elif value == 0.0:
            writes.clear_columns(actions, column, seq)
        else:
            columns = self._all(column_kind, column)
            what = f"'{letter}: ...' with a '*' and the value {value:g}"
            writes.product(actions, rows, columns, np.full(len(columns), value), seq, what)

    def _reward(self, seq: int) -> None:
        n_states, n_obs = self.counts["states"], self.counts["observations"]
        tokens = self.tokens
        action = self._index("actions", "an action or * after 'R:'")
        tokens.expect(":", "and a start state after 'R: a' (R needs at least 'R: a : s')")
        start = self._index("states", "a start state or * in 'R: a : s'")
        if not self._colon_follows():
            matrix = tokens.numbers(n_states * n_obs, "the reward matrix (|S'| x |Z|)")
            ends, observations = np.divmod(np.arange(n_states * n_obs), n_obs)
            self._add_rewards(seq, action, start, ends, observations, matrix)
            return
        tokens.next(":")
        end = self._index("states", "an end state or * in 'R: a : s : s''")
        if not self._colon_follows():
            row = tokens.numbers(n_obs, "the reward row (|Z| values)")
            self._add_rewards(seq, action, start, np.full(n_obs, end), np.arange(n_obs), row)
            return
        tokens.next(":")
        observation = self._index("observations", "an observation or * in 'R: a : s : s' : z'")
        value = tokens.numbers(1, "the reward R(a, s, s', z)")
        self._add_rewards(seq, action, start, np.array([end]), np.array([observation]), value)

    def _add_rewards(self, seq, action, start, ends, observations, values) -> None:
        count = len(values)
        self.reward_parts.append(
            (np.full(count, seq), np.full(count, action), np.full(count, start), ends, observations, values)
        )

    # ---------------------------------------------------------------------------------- build
    def sizes(self) -> tuple[int, int, int]:
        return self.counts["states"], self.counts["actions"], self.counts["observations"]

    def build(self) -> POMDP:
        n_states = self.counts["states"]
        if self.missing_rows != "error":
            actions, rows = np.nonzero(self.transitions.row_written < 0)
            after = np.full(len(rows), len(self.statement_lines), dtype=np.int64)
            if self.missing_rows == "absorbing":
                self.transitions.parts.append((actions, rows, rows, np.ones(len(rows)), after))
            else:
                support = np.flatnonzero(self.start)
                self.transitions.parts.append(
                    (
                        np.repeat(actions, len(support)),
                        np.repeat(rows, len(support)),
                        np.tile(support, len(rows)),
                        np.tile(self.start[support], len(rows)),
                        np.repeat(after, len(support)),
                    )
                )
        transitions = self._matrices(self.transitions, "T", "start state", "end state", "states", n_states)
        observations = self._matrices(
            self.observations, "O", "end state", "observation", "observations", self.counts["observations"]
        )
        rewards = self._collapse_rewards(transitions, observations)
        if self.cost:
            rewards = -rewards
        names = self.names
        try:
            return POMDP(
                transitions=transitions,
                rewards=rewards,
                discount=self.discount,
                state_names=names["states"],
                action_names=names["actions"],
                observations=observations,
                initial_belief=self.start,
                observation_names=names["observations"],
            )
        except ModelError as error:
            raise PomdpFormatError(f"{self.filename}: {error}") from error

    def _matrices(
        self, writes: _Writes, letter: str, row_kind: str, column_noun: str, column_kind: str, n_columns: int
    ) -> list[sp.csr_matrix]:
        """CSR matrices per action from the resolved writes; negative entries, overflows and rows not summing
        to 1 are errors naming the line."""
        n_actions, n_rows, _ = writes.shape
        actions, rows, columns, values, seqs = writes.resolve()
        bad = np.flatnonzero(~np.isfinite(values) | (values < 0))
        if bad.size:
            k = int(bad[0])
            what = (
                "is too large for a float (inf)"
                if not np.isfinite(values[k])
                else f"is negative ({values[k]:g})"
            )
            raise PomdpFormatError(
                f"{self.filename}:{self.statement_line(int(seqs[k]))}: {letter} entry for action "
                f"{self._label('actions', int(actions[k]))}, {row_kind} {self._label('states', int(rows[k]))}, "
                f"{column_noun} {self._label(column_kind, int(columns[k]))} {what}; expected a probability in [0, 1]"
            )
        nonzero = values != 0.0
        actions, rows, columns, values = actions[nonzero], rows[nonzero], columns[nonzero], values[nonzero]
        flat_rows = actions * n_rows + rows
        sums = np.bincount(flat_rows, weights=values, minlength=n_actions * n_rows).reshape(n_actions, n_rows)
        wrong = np.argwhere(np.abs(sums - 1.0) > PROBABILITY_ATOL)
        if wrong.size:
            action, row = (int(v) for v in wrong[0])
            seq = int(writes.row_written[action, row])
            where = f"{self.filename}:{self.statement_line(seq) if seq >= 0 else self.tokens.line(self.tokens.count)}"
            written = (
                "last written here"
                if seq >= 0
                else "never written; to read it anyway choose missing_rows='absorbing' or 'reset' (--missing-rows)"
            )
            raise PomdpFormatError(
                f"{where}: {letter} row for action {self._label('actions', action)}, {row_kind} "
                f"{self._label('states', row)} sums to {sums[action, row]:.8g}; expected probabilities summing "
                f"to 1 ({written}; {len(wrong)} bad row(s) in all; rows are never renormalised)"
            )
        bounds = np.searchsorted(flat_rows, np.arange(n_actions + 1) * n_rows)
        matrices = []
        for action in range(n_actions):
            lo, hi = bounds[action], bounds[action + 1]
            indptr = np.searchsorted(flat_rows[lo:hi], action * n_rows + np.arange(n_rows + 1))
            matrices.append(sp.csr_matrix((values[lo:hi], columns[lo:hi], indptr), shape=(n_rows, n_columns)))
        return matrices

    def _label(self, kind: str, index: int) -> str:
        names = self.names[kind]
        return f"{index} ('{names[index]}')" if names else str(index)

    def _collapse_rewards(
        self, transitions: list[sp.csr_matrix], observations: list[sp.csr_matrix]
    ) -> np.ndarray:
        """``R(s, a) = sum_{s', z} T(s,a,s') O(a,s',z) R(a,s,s',z)``, the last statement covering an entry winning.

        Only the (s, s', z) with ``T O > 0`` are evaluated (sparse); rewards that depend on (s, a) only are
        copied exactly.
        """
        n_states, n_actions, n_obs = self.sizes()
        rewards = np.zeros((n_states, n_actions))
        if not self.reward_parts:
            return rewards
        seqs, actions, starts, ends, observations_, values = (
            np.concatenate([np.asarray(part[i]) for part in self.reward_parts]) for i in range(6)
        )
        order = np.argsort(seqs, kind="stable")
        seqs, actions, starts, ends, observations_, values = (
            x[order] for x in (seqs, actions, starts, ends, observations_, values)
        )
        infinite = np.flatnonzero(~np.isfinite(values))
        if infinite.size:
            raise PomdpFormatError(
                f"{self.filename}:{self.statement_line(int(seqs[infinite[0]]))}: a reward is too large for a float "
                f"({values[infinite[0]]:g}); expected a finite number"
            )
        for action in range(n_actions):
            mine = (actions == action) | (actions == _WILD)
            if not mine.any():
                continue
            statements = (seqs[mine], starts[mine], ends[mine], observations_[mine], values[mine])
            if np.all(statements[2] == _WILD) and np.all(statements[3] == _WILD):
                cells = (
                    np.arange(n_states),
                    np.zeros(n_states, dtype=np.int64),
                    np.zeros(n_states, dtype=np.int64),
                )
                rewards[:, action] = _last_writes(cells, statements, n_states, n_obs)
                continue
            transition, observation = transitions[action], observations[action]
            row_of_entry = np.repeat(np.arange(n_states), np.diff(transition.indptr))
            per_end = np.diff(observation.indptr)[transition.indices]
            cell_start = np.repeat(row_of_entry, per_end)
            cell_end = np.repeat(transition.indices, per_end)
            offsets = np.arange(len(cell_start)) - np.repeat(np.cumsum(per_end) - per_end, per_end)
            positions = observation.indptr[cell_end] + offsets
            weights = np.repeat(transition.data, per_end) * observation.data[positions]
            cells = (cell_start, cell_end, observation.indices[positions].astype(np.int64))
            painted = _last_writes(cells, statements, n_states, n_obs)
            rewards[:, action] = np.bincount(cell_start, weights=weights * painted, minlength=n_states)
        return rewards


def _last_writes(cells, statements, n_states: int, n_obs: int) -> np.ndarray:
    """The value of the last statement covering each cell (0 where none does).

    ``cells``: (start, end, observation) arrays; ``statements``: (seq, start, end, observation, value) arrays in
    file order, with ``_WILD`` for '*'. Statements are grouped by which selectors are wildcards; within a group
    the last statement per key wins, and across groups the latest statement.
    """
    seqs, starts, ends, observations, values = statements
    best_seq = np.full(len(cells[0]), -1, dtype=np.int64)
    best_value = np.zeros(len(cells[0]))
    specific = (starts != _WILD, ends != _WILD, observations != _WILD)
    pattern = specific[0] * 4 + specific[1] * 2 + specific[2]
    for group in np.unique(pattern).tolist():
        members = np.flatnonzero(pattern == group)
        use = (bool(group & 4), bool(group & 2), bool(group & 1))
        keys = _cell_keys([x[members] for x in (starts, ends, observations)], use, n_states, n_obs)
        order = np.argsort(keys, kind="stable")  # stable: file order within a key
        keys, chosen = keys[order], members[order]
        last = np.ones(len(keys), dtype=bool)
        last[:-1] = keys[1:] != keys[:-1]
        keys, chosen = keys[last], chosen[last]
        cell_keys = _cell_keys(cells, use, n_states, n_obs)
        where = np.minimum(np.searchsorted(keys, cell_keys), len(keys) - 1)
        hit = keys[where] == cell_keys
        candidate = np.where(hit, seqs[chosen[where]], -1)
        better = candidate > best_seq
        best_seq = np.where(better, candidate, best_seq)
        best_value = np.where(better, values[chosen[where]], best_value)
    return best_value


def _cell_keys(coordinates, use: tuple[bool, bool, bool], n_states: int, n_obs: int) -> np.ndarray:
    """One integer per (start, end, observation), counting only the coordinates in ``use``."""
    keys = np.zeros(len(coordinates[0]), dtype=np.int64)
    for values, used, scale in zip(coordinates, use, (n_states * n_obs, n_obs, 1), strict=True):
        if used:
            keys += np.asarray(values, dtype=np.int64) * scale
    return keys


def parse_pomdp(text: str, filename: str = "<string>", missing_rows: str = "error") -> POMDP:
    """Parse the text of a Cassandra ``.pomdp`` file; errors name ``filename:line``."""
    parser = _Parser(text, filename, missing_rows)
    parser.parse_statements()
    return parser.build()


def read_pomdp(path: str | Path, missing_rows: str = "error") -> POMDP:
    """Read a Cassandra ``.pomdp`` file (see :data:`MISSING_ROWS` for rows the file never writes)."""
    return parse_pomdp(_read_text(path), str(path), missing_rows)


def read_pomdp_sizes(path: str | Path) -> tuple[int, int, int]:
    """``(|S|, |A|, |Z|)`` after parsing every statement of the file, without validating the model's rows."""
    parser = _Parser(_read_text(path), str(path))
    parser.parse_statements()
    return parser.sizes()


def _read_text(path: str | Path) -> str:
    return checks.read_text(path, MAX_FILE_CHARS, ".pomdp file", PomdpFormatError, replace=True)


# ------------------------------------------------------------------------------------------ writer
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_\-.]*$")


def format_pomdp(pomdp: POMDP) -> str:
    """The model as ``.pomdp`` text: sparse per-entry T/O lines, ``R: a : s : * : *`` rewards, exact floats."""
    lines = [
        "# written by embodied-adhoc",
        f"discount: {pomdp.discount!r}",
        "values: reward",
        f"states: {_declaration(pomdp.state_names, pomdp.n_states, 'state')}",
        f"actions: {_declaration(pomdp.action_names, pomdp.n_actions, 'action')}",
        f"observations: {_declaration(pomdp.observation_names, pomdp.n_observations, 'observation')}",
        "start:",
        " ".join(repr(float(p)) for p in pomdp.initial_belief),
        "",
    ]
    for action in range(pomdp.n_actions):  # Python ints and floats (tolist): repr is exact and fast
        for letter, matrix in (("T", pomdp.transitions[action]), ("O", pomdp.observations[action])):
            coo = matrix.tocoo()
            lines.extend(
                map(
                    f"{letter}: {action} : {{}} : {{}} {{!r}}".format,
                    coo.row.tolist(),
                    coo.col.tolist(),
                    coo.data.tolist(),
                )
            )
        states = np.flatnonzero(pomdp.rewards[:, action])
        lines.extend(
            map(
                f"R: {action} : {{}} : * : * {{!r}}".format,
                states.tolist(),
                pomdp.rewards[states, action].tolist(),
            )
        )
    return "\n".join(lines) + "\n"


def _declaration(names: tuple[str, ...] | None, count: int, kind: str) -> str:
    if names is None:
        return str(count)
    for name in names:
        if not _NAME.match(name) or name in _KEYWORDS or name in _MATRIX_WORDS:
            raise ModelError(
                f"{kind} name '{name}' cannot be written to a .pomdp file: names must start with a letter and "
                "use letters, digits, '_', '-', '.' only, and not be a keyword; rename it"
            )
    return " ".join(names)


def write_pomdp(pomdp: POMDP, path: str | Path) -> Path:
    """Write ``pomdp`` to ``path`` atomically (temp file + rename); reading it back gives the same model."""
    return atomic_write_text(path, format_pomdp(pomdp))
