"""Cassandra's ``.pomdp`` file format: reader and writer for the whole format (pomdp-solve's file spec).

Covered: states/actions/observations as counts or names (entries may then be named or 0-based indices);
``discount``; ``values: reward|cost`` (cost is negated); every ``start`` form (a vector, ``uniform``, one state,
``start include: ...`` and ``start exclude: ...``); ``T``/``O``/``R`` per entry, per row or as a whole matrix,
with ``uniform``, ``identity`` and ``reset`` (a row equal to the start belief); ``*`` wildcards anywhere; later
statements overriding earlier ones; numbers spanning any number of lines; ``#`` comments; and rewards
``R(a, s, s', z)`` depending on the end state and observation, collapsed to the immediate expected reward
``R(s, a) = sum_{s', z} T(s, a, s') O(a, s', z) R(a, s, s', z)``.

Errors are :class:`PomdpFormatError` with ``file:line``, what was found and what was expected. Probability rows
that do not sum to 1 (beyond :data:`~embodied_adhoc.decision.models.PROBABILITY_ATOL`) are errors naming the row
and the line that last wrote it; nothing is renormalised.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.decision.models import POMDP, PROBABILITY_ATOL
from embodied_adhoc.errors import ModelError, PomdpFormatError

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?)$")
_INTEGER = re.compile(r"^\d+$")
_KEYWORDS = {"discount", "values", "states", "actions", "observations", "start", "T", "O", "R"}
_MATRIX_WORDS = {"uniform", "identity", "reset"}
_REWARD_BLOCK_ELEMENTS = 4_000_000
MISSING_ROWS = ("error", "absorbing", "reset")
"""What to do with a transition row ``T(. | s, a)`` that the file never writes (e.g. mini-hall2's goal state):
an error (default), a self-loop, or the start belief. Rows written but not summing to 1 are always errors."""  # max floats painted at once when collapsing R(a, s, s', z)


class _Token(NamedTuple):  # a NamedTuple: ~4x cheaper to create than a frozen dataclass (files of 1M tokens)
    text: str
    line: int


class _Tokens:
    """A token stream with positions, for a recursive-descent parser with precise error messages."""

    def __init__(self, text: str, filename: str) -> None:
        self.filename = filename
        self.items: list[_Token] = [
            _Token(piece, number)
            for number, raw in enumerate(text.splitlines(), start=1)
            for piece in raw.split("#", 1)[0].replace(":", " : ").split()
        ]
        self.position = 0

    def peek(self, offset: int = 0) -> _Token | None:
        try:
            return self.items[self.position + offset]
        except IndexError:
            return None

    def next(self, expected: str) -> _Token:
        try:
            token = self.items[self.position]
        except IndexError:
            last = self.items[-1].line if self.items else 1
            raise PomdpFormatError(
                f"{self.filename}:{last}: found end of file, expected {expected}"
            ) from None
        self.position += 1
        return token

    def error(self, token: _Token | None, expected: str) -> PomdpFormatError:
        if token is None:
            return PomdpFormatError(
                f"{self.filename}:{self.items[-1].line if self.items else 1}: found end of file, expected {expected}"
            )
        return PomdpFormatError(f"{self.filename}:{token.line}: found '{token.text}', expected {expected}")

    def expect(self, text: str, context: str) -> _Token:
        token = self.next(f"'{text}' {context}")
        if token.text != text:
            raise self.error(token, f"'{text}' {context}")
        return token

    def at_number(self) -> bool:
        token = self.peek()
        return token is not None and bool(_NUMBER.match(token.text))

    def numbers(self, count: int, what: str) -> np.ndarray:
        chunk = self.items[self.position : self.position + count]
        match = _NUMBER.match
        for index, token in enumerate(chunk):
            if not match(token.text):
                raise self.error(token, f"{count} numbers for {what} (got {index})")
        if len(chunk) < count:
            raise self.error(None, f"{count} numbers for {what} (got {len(chunk)})")
        self.position += count
        if self.at_number():
            raise self.error(self.peek(), f"the end of {what} after {count} numbers (too many numbers)")
        return np.array([float(token.text) for token in chunk])


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
        self.start: np.ndarray | None = None
        self.start_line = 0
        self.transitions: np.ndarray | None = None  # (A, S, S) dense while parsing
        self.transition_lines: np.ndarray | None = None  # (A, S) line that last wrote each row
        self.observations: np.ndarray | None = None  # (A, S, Z)
        self.observation_lines: np.ndarray | None = None
        self.reward_statements: list[tuple[int, object, object, object, object, np.ndarray]] = []

    # ------------------------------------------------------------------------------------ preamble
    def parse_statements(self) -> None:
        tokens = self.tokens
        while (token := tokens.peek()) is not None and token.text not in ("T", "O", "R"):
            self._preamble_statement()
        here = token.line if token is not None else (tokens.items[-1].line if tokens.items else 1)
        found = f"'{token.text}'" if token is not None else "end of file"
        for kind in ("discount", "states", "actions", "observations"):
            if (kind == "discount" and self.discount is None) or (
                kind != "discount" and kind not in self.counts
            ):
                raise PomdpFormatError(
                    f"{self.filename}:{here}: found {found} before any '{kind}:' line, "
                    f"expected '{kind}:' in the preamble"
                )
        n_states, n_actions, n_obs = (
            self.counts["states"],
            self.counts["actions"],
            self.counts["observations"],
        )
        if self.start is None:
            self.start = np.full(n_states, 1.0 / n_states)  # the spec's default: uniform
        self.transitions = np.zeros((n_actions, n_states, n_states))
        self.transition_lines = np.zeros((n_actions, n_states), dtype=np.int64)
        self.observations = np.zeros((n_actions, n_states, n_obs))
        self.observation_lines = np.zeros((n_actions, n_states), dtype=np.int64)
        while (token := tokens.peek()) is not None:
            if token.text not in ("T", "O", "R"):
                raise tokens.error(token, "a 'T:', 'O:' or 'R:' statement (preamble lines must come first)")
            tokens.next("T, O or R")
            tokens.expect(":", f"after '{token.text}'")
            {"T": self._transition, "O": self._observation, "R": self._reward}[token.text](token.line)

    def _preamble_statement(self) -> None:
        tokens = self.tokens
        token = tokens.next("a preamble statement")
        if token.text not in _KEYWORDS:
            raise tokens.error(
                token, "one of discount:, values:, states:, actions:, observations:, start:, T:, O:, R:"
            )
        if token.text == "start":
            return self._start(token)
        tokens.expect(":", f"after '{token.text}'")
        if token.text == "discount":
            value = tokens.next("a discount in [0, 1]")
            if not _NUMBER.match(value.text) or not 0.0 <= float(value.text) <= 1.0:
                raise tokens.error(value, "a discount in [0, 1]")
            self.discount = float(value.text)
        elif token.text == "values":
            value = tokens.next("'reward' or 'cost'")
            if value.text not in ("reward", "cost", "rewards", "costs"):  # plural seen in the wild (ejs4-7)
                raise tokens.error(value, "'reward' or 'cost'")
            self.cost = value.text.startswith("cost")
        else:
            self._declaration(token.text)

    def _declaration(self, kind: str) -> None:
        tokens = self.tokens
        first = tokens.next(f"a count or a list of {kind}")
        if _INTEGER.match(first.text):
            count = int(first.text)
            if count < 1:
                raise tokens.error(first, f"a positive number of {kind}")
            self.counts[kind], self.names[kind] = count, None
            return
        if first.text in _KEYWORDS or first.text == ":" or _NUMBER.match(first.text):
            raise tokens.error(first, f"a count or a list of {kind} names")
        names = [first.text]
        while (token := tokens.peek()) is not None and not self._starts_statement():
            if token.text == "*" or _NUMBER.match(token.text):
                raise tokens.error(token, f"a name of one of the {kind} (names start with a letter)")
            names.append(tokens.next("a name").text)
        if len(set(names)) != len(names):
            duplicate = next(n for n in names if names.count(n) > 1)
            raise PomdpFormatError(
                f"{self.filename}:{first.line}: {kind} name '{duplicate}' is declared twice"
            )
        self.counts[kind], self.names[kind] = len(names), names

    def _starts_statement(self) -> bool:
        token, after = self.tokens.peek(), self.tokens.peek(1)
        if token is None:
            return True
        if token.text in ("T", "O", "R", "discount", "values", "states", "actions", "observations"):
            return after is not None and after.text == ":"
        return token.text == "start" and after is not None and after.text in (":", "include", "exclude")

    def _start(self, keyword: _Token) -> None:
        tokens = self.tokens
        if "states" not in self.counts:
            raise tokens.error(keyword, "'states:' before 'start:'")
        n_states = self.counts["states"]
        mode = tokens.next("':', 'include' or 'exclude' after 'start'")
        self.start_line = keyword.line
        if mode.text in ("include", "exclude"):
            tokens.expect(":", f"after 'start {mode.text}'")
            chosen = np.zeros(n_states, dtype=bool)
            listed = 0
            while tokens.peek() is not None and not self._starts_statement():
                chosen[self._index("states", tokens.next("a state"), wildcard=False)] = True
                listed += 1
            if listed == 0:
                raise tokens.error(tokens.peek(), f"a list of states after 'start {mode.text}:'")
            if mode.text == "exclude":
                chosen = ~chosen
            if not chosen.any():
                raise PomdpFormatError(
                    f"{self.filename}:{keyword.line}: 'start exclude:' excludes every state"
                )
            self.start = chosen / chosen.sum()
            return
        if mode.text != ":":
            raise tokens.error(mode, "':', 'include' or 'exclude' after 'start'")
        token = tokens.peek()
        if token is not None and token.text == "uniform":
            tokens.next("uniform")
            self.start = np.full(n_states, 1.0 / n_states)
        elif token is not None and not _NUMBER.match(token.text):
            # One state name; several names (as in pomdp-ex.pomdp) read like 'start include:'.
            chosen = np.zeros(n_states, dtype=bool)
            chosen[self._index("states", tokens.next("a state"), wildcard=False)] = True
            while tokens.peek() is not None and not self._starts_statement() and not self.tokens.at_number():
                chosen[self._index("states", tokens.next("a state"), wildcard=False)] = True
            self.start = chosen / chosen.sum()
        elif token is not None and _INTEGER.match(token.text) and n_states > 1 and not self._number_follows():
            self.start = np.zeros(n_states)  # 'start: 3' names state 3 (a vector would need |S| numbers)
            self.start[self._index("states", tokens.next("a state"), wildcard=False)] = 1.0
        else:
            self.start = tokens.numbers(n_states, "the start belief")
            self._check_distribution(self.start, "the start belief", keyword.line)

    def _number_follows(self) -> bool:
        after = self.tokens.peek(1)
        return after is not None and bool(_NUMBER.match(after.text))

    def _check_distribution(self, values: np.ndarray, what: str, line: int) -> None:
        if values.min() < 0 or abs(values.sum() - 1.0) > PROBABILITY_ATOL:
            raise PomdpFormatError(
                f"{self.filename}:{line}: {what} sums to {values.sum():.8g} (min {values.min():g}), "
                "expected a probability vector summing to 1"
            )

    # ------------------------------------------------------------------------------ identifiers
    def _index(self, kind: str, token: _Token, wildcard: bool = True) -> int | slice:
        if token.text == "*" and wildcard:
            return slice(None)
        names = self.names[kind]
        if names is not None and token.text in names:
            return names.index(token.text)
        if _INTEGER.match(token.text) and int(token.text) < self.counts[kind]:
            return int(token.text)
        singular = kind[:-1] if kind != "states" else "state"
        choices = f"a name of {names[:6]}{'...' if len(names) > 6 else ''}" if names else "no names"
        raise self.tokens.error(
            token,
            f"a {singular}{' or *' if wildcard else ''}: an index 0..{self.counts[kind] - 1} or {choices}",
        )

    def _selector(self, kind: str, what: str) -> int | slice:
        return self._index(kind, self.tokens.next(f"{what}"))

    def _colon_follows(self) -> bool:
        token = self.tokens.peek()
        return token is not None and token.text == ":"

    # ------------------------------------------------------------------------------- T, O, R
    def _transition(self, line: int) -> None:
        n_states = self.counts["states"]
        action = self._selector("actions", "an action or * after 'T:'")
        if not self._colon_follows():
            matrix = self._square_matrix(n_states, "the transition matrix", allow_reset=True)
            self.transitions[action] = matrix
            self.transition_lines[action] = line
            return
        self.tokens.next(":")
        start = self._selector("states", "a start state or * in 'T: a : s'")
        if not self._colon_follows():
            self.transitions[action, start] = self._row(n_states, "the transition row", allow_reset=True)
            self.transition_lines[action, start] = line
            return
        self.tokens.next(":")
        end = self._selector("states", "an end state or * in 'T: a : s : s''")
        self.transitions[action, start, end] = self.tokens.numbers(1, "T(s' | s, a)")[0]
        self.transition_lines[action, start] = line

    def _observation(self, line: int) -> None:
        n_states, n_obs = self.counts["states"], self.counts["observations"]
        action = self._selector("actions", "an action or * after 'O:'")
        if not self._colon_follows():
            token = self.tokens.peek()
            if token is not None and token.text == "uniform":
                self.tokens.next("uniform")
                self.observations[action] = 1.0 / n_obs
            else:
                self.observations[action] = self.tokens.numbers(
                    n_states * n_obs, "the observation matrix"
                ).reshape(n_states, n_obs)
            self.observation_lines[action] = line
            return
        self.tokens.next(":")
        end = self._selector("states", "an end state or * in 'O: a : s''")
        if not self._colon_follows():
            self.observations[action, end] = self._row(n_obs, "the observation row", allow_reset=False)
            self.observation_lines[action, end] = line
            return
        self.tokens.next(":")
        observation = self._selector("observations", "an observation or * in 'O: a : s' : z'")
        self.observations[action, end, observation] = self.tokens.numbers(1, "O(z | s', a)")[0]
        self.observation_lines[action, end] = line

    def _reward(self, line: int) -> None:
        n_states, n_obs = self.counts["states"], self.counts["observations"]
        action = self._selector("actions", "an action or * after 'R:'")
        self.tokens.expect(":", "and a start state after 'R: a' (R needs at least 'R: a : s')")
        start = self._selector("states", "a start state or * in 'R: a : s'")
        if not self._colon_follows():
            matrix = self.tokens.numbers(n_states * n_obs, "the reward matrix (|S'| x |Z|)").reshape(
                n_states, n_obs
            )
            self.reward_statements.append((line, action, start, slice(None), slice(None), matrix))
            return
        self.tokens.next(":")
        end = self._selector("states", "an end state or * in 'R: a : s : s''")
        if not self._colon_follows():
            row = self.tokens.numbers(n_obs, "the reward row (|Z| values)")
            self.reward_statements.append((line, action, start, end, slice(None), row))
            return
        self.tokens.next(":")
        observation = self._selector("observations", "an observation or * in 'R: a : s : s' : z'")
        value = self.tokens.numbers(1, "the reward R(a, s, s', z)")
        self.reward_statements.append((line, action, start, end, observation, value[0]))

    def _row(self, length: int, what: str, allow_reset: bool) -> np.ndarray:
        token = self.tokens.peek()
        if token is not None and token.text == "uniform":
            self.tokens.next("uniform")
            return np.full(length, 1.0 / length)
        if token is not None and token.text == "reset" and allow_reset:
            self.tokens.next("reset")
            return self.start.copy()
        return self.tokens.numbers(length, what)

    def _square_matrix(self, size: int, what: str, allow_reset: bool) -> np.ndarray:
        token = self.tokens.peek()
        if token is not None and token.text == "identity":
            self.tokens.next("identity")
            return np.eye(size)
        if token is not None and token.text == "uniform":
            self.tokens.next("uniform")
            return np.full((size, size), 1.0 / size)
        if token is not None and token.text == "reset" and allow_reset:
            self.tokens.next("reset")
            return np.tile(self.start, (size, 1))
        return self.tokens.numbers(size * size, f"{what} (|S| x |S|, or identity/uniform/reset)").reshape(
            size, size
        )

    # ---------------------------------------------------------------------------------- build
    def sizes(self) -> tuple[int, int, int]:
        return self.counts["states"], self.counts["actions"], self.counts["observations"]

    def build(self) -> POMDP:
        if self.missing_rows != "error":
            actions, rows = np.nonzero(self.transition_lines == 0)
            if self.missing_rows == "absorbing":
                self.transitions[actions, rows, rows] = 1.0
            else:
                self.transitions[actions, rows] = self.start
        self._check_rows(self.transitions, self.transition_lines, "T", "start state")
        self._check_rows(self.observations, self.observation_lines, "O", "end state")
        rewards = self._collapse_rewards()
        if self.cost:
            rewards = -rewards
        names = self.names
        try:
            return POMDP(
                transitions=list(self.transitions),
                rewards=rewards,
                discount=self.discount,
                state_names=names["states"],
                action_names=names["actions"],
                observations=list(self.observations),
                initial_belief=self.start,
                observation_names=names["observations"],
            )
        except ModelError as error:
            raise PomdpFormatError(f"{self.filename}: {error}") from error

    def _check_rows(self, arrays: np.ndarray, lines: np.ndarray, letter: str, row_kind: str) -> None:
        sums = arrays.sum(axis=2)
        bad = np.argwhere((np.abs(sums - 1.0) > PROBABILITY_ATOL) | (arrays.min(axis=2) < 0))
        if bad.size == 0:
            return
        action, row = (int(v) for v in bad[0])
        line = int(lines[action, row])
        where = f"{self.filename}:{line}" if line else f"{self.filename}:{self.tokens.items[-1].line}"
        written = (
            "last written here"
            if line
            else "never written; to read it anyway choose missing_rows='absorbing' or 'reset' (--missing-rows)"
        )
        raise PomdpFormatError(
            f"{where}: {letter} row for action {self._label('actions', action)}, {row_kind} "
            f"{self._label('states', row)} sums to {sums[action, row]:.8g} (min {arrays[action, row].min():g}); "
            f"expected probabilities summing to 1 ({written}; {len(bad)} bad row(s) in all; rows are never "
            "renormalised)"
        )

    def _label(self, kind: str, index: int) -> str:
        names = self.names[kind]
        return f"{index} ('{names[index]}')" if names else str(index)

    def _collapse_rewards(self) -> np.ndarray:
        """``R(s, a) = sum_{s', z} T(s,a,s') O(a,s',z) R(a,s,s',z)``, painting statements in file order."""
        n_actions, n_states, n_obs = (
            self.counts["actions"],
            self.counts["states"],
            self.counts["observations"],
        )
        rewards = np.zeros((n_states, n_actions))
        block = max(1, _REWARD_BLOCK_ELEMENTS // (n_states * n_obs))
        for action in range(n_actions):
            statements = [s for s in self.reward_statements if _hits(s[1], action)]
            if not statements:
                continue
            if all(s[3] == slice(None) and s[4] == slice(None) and np.ndim(s[5]) == 0 for s in statements):
                column = np.zeros(n_states)  # rewards that depend on (s, a) only: no 4-D painting needed
                for _, _, start, _, _, value in statements:
                    column[start] = value
                rewards[:, action] = column
                continue
            for first in range(0, n_states, block):
                last = min(n_states, first + block)
                weights = (
                    self.transitions[action][first:last, :, None] * self.observations[action][None, :, :]
                )
                painted = np.zeros((last - first, n_states, n_obs))
                for _, _, start, end, observation, value in statements:
                    rows = _clip(start, first, last)
                    if rows is not None:
                        painted[rows, end, observation] = value
                rewards[first:last, action] = np.einsum("ijk,ijk->i", weights, painted)
        return rewards


def _hits(selector: int | slice, index: int) -> bool:
    return isinstance(selector, slice) or selector == index


def _clip(selector: int | slice, first: int, last: int) -> int | slice | None:
    if isinstance(selector, slice):
        return slice(None)
    return selector - first if first <= selector < last else None


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
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise PomdpFormatError(f"{path}: cannot read the file ({error.strerror})") from error


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
    for action in range(pomdp.n_actions):
        for letter, matrix in (("T", pomdp.transitions[action]), ("O", pomdp.observations[action])):
            coo = matrix.tocoo()
            lines.extend(
                f"{letter}: {action} : {row} : {column} {float(value)!r}"
                for row, column, value in zip(coo.row, coo.col, coo.data, strict=True)
            )
        lines.extend(
            f"R: {action} : {state} : * : * {float(value)!r}"
            for state, value in enumerate(pomdp.rewards[:, action])
            if value != 0.0
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
