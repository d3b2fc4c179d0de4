"""Cassandra .pomdp reader/writer: the whole corpus, every statement form, errors with file:line, round trips."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from embodied_adhoc.decision import pomdp_io
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.pomdp_io import parse_pomdp, read_pomdp, read_pomdp_sizes, write_pomdp
from embodied_adhoc.errors import PomdpFormatError

CORPUS = (Path(__file__).resolve().parents[2] / ".." / "shared" / "pomdp").resolve()

# (|S|, |A|, |Z|) from each file's header. The corpus README's table lists 8, 9 and 8 observations for
# learning.c*, parr95 and web-ad; their headers declare 3, 6 and 5 names (counted by hand), which we follow.
HEADER_SIZES = {
    "1d.noisy.POMDP": (4, 2, 2), "1d.pomdp": (4, 2, 2), "4x3.95.POMDP": (11, 4, 6), "4x4.95.POMDP": (16, 4, 2),
    "4x5x2.95.POMDP": (39, 4, 4), "aloha.10.POMDP": (30, 9, 3), "aloha.30.POMDP": (90, 29, 3),
    "bridge-repair.POMDP": (5, 12, 5), "bulkhead.A.POMDP": (10, 6, 6), "cheese.95.POMDP": (11, 4, 7),
    "cheng.D3-1.POMDP": (3, 3, 3), "cheng.D3-2.POMDP": (3, 3, 3), "cheng.D3-3.POMDP": (3, 3, 3),
    "cheng.D3-4.POMDP": (3, 3, 3), "cheng.D3-5.POMDP": (3, 3, 3), "cheng.D4-1.POMDP": (4, 4, 4),
    "cheng.D4-2.POMDP": (4, 4, 4), "cheng.D4-3.POMDP": (4, 4, 4), "cheng.D4-4.POMDP": (4, 4, 4),
    "cheng.D4-5.POMDP": (4, 4, 4), "cheng.D5-1.POMDP": (5, 3, 3), "cit.POMDP": (284, 4, 28),
    "concert.POMDP": (2, 3, 2), "ejs-ft-counter.POMDP": (2, 2, 2), "ejs1.POMDP": (3, 4, 2), "ejs2.POMDP": (2, 2, 2),
    "ejs3.POMDP": (2, 2, 2), "ejs4.POMDP": (3, 2, 2), "ejs5.POMDP": (2, 2, 2), "ejs6.POMDP": (2, 2, 2),
    "ejs7.POMDP": (2, 2, 2), "fourth.POMDP": (1052, 4, 28), "hallway.POMDP": (60, 5, 21),
    "hallway2.POMDP": (92, 5, 17), "iff.POMDP": (104, 4, 22), "learning.c2.POMDP": (12, 8, 3),
    "learning.c3.POMDP": (24, 12, 3), "learning.c4.POMDP": (48, 16, 3), "line4-2goals.POMDP": (4, 2, 1),
    "machine.POMDP": (256, 4, 16), "marking.POMDP": (9, 4, 3), "marking2.POMDP": (9, 4, 3),
    "mcc-example1.POMDP": (4, 3, 3), "mcc-example2.POMDP": (4, 3, 3), "milos-aaai97.POMDP": (20, 6, 8),
    "mini-hall2.pomdp": (13, 3, 9), "mit.POMDP": (204, 4, 28), "network.POMDP": (7, 4, 2),
    "paint.95.POMDP": (4, 4, 2), "parr95.95.pomdp": (7, 3, 6), "pentagon.POMDP": (212, 4, 28),
    "pomdp-ex.pomdp": (6, 4, 2), "query.s2.POMDP": (9, 2, 3), "query.s3.POMDP": (27, 3, 3),
    "query.s4.POMDP": (81, 4, 3), "saci-s100-a10-z31.POMDP": (100, 10, 31), "saci-s12-a6-z5.95.POMDP": (12, 6, 5),
    "sarsop-Hallway.pomdp": (60, 5, 21), "sarsop-Hallway2.pomdp": (92, 5, 17),
    "sarsop-TagAvoid.pomdp": (870, 5, 30), "sarsop-Tiger.pomdp": (2, 3, 2), "shuttle.95.POMDP": (8, 3, 5),
    "stand-tiger.95.POMDP": (4, 4, 4), "sunysb.POMDP": (300, 4, 28), "tiger-grid.POMDP": (36, 5, 17),
    "tiger.95.POMDP": (2, 3, 2), "web-ad.POMDP": (4, 3, 5), "web-mall.POMDP": (2, 3, 2),
}  # fmt: skip
# Files that parse but are not valid models as written: the error must say why and where.
INVALID_MODELS = {
    "pomdp-ex.pomdp": "O row for action 0 ('north')",  # a syntax showcase: only one O entry is given
    "mini-hall2.pomdp": "never written",  # state 12 (the goal) has no transitions ('#T: * : 12' commented out)
}
LARGE = {"fourth.POMDP", "aloha.30.POMDP"}  # parsed in the sizes test only, to keep the suite fast


def corpus_files() -> list[str]:
    if not CORPUS.is_dir():
        pytest.skip(f"corpus folder {CORPUS} not present")
    return sorted(p.name for p in CORPUS.iterdir() if p.name != "README.md")


def test_corpus_is_the_expected_set():
    assert set(corpus_files()) == set(HEADER_SIZES)


@pytest.mark.parametrize("name", sorted(HEADER_SIZES))
def test_every_corpus_file_parses_with_header_sizes(name):
    if not CORPUS.is_dir():
        pytest.skip("no corpus")
    assert read_pomdp_sizes(CORPUS / name) == HEADER_SIZES[name]
    if name in LARGE:
        return
    if name in INVALID_MODELS:
        with pytest.raises(PomdpFormatError, match=re.escape(INVALID_MODELS[name])) as error:
            read_pomdp(CORPUS / name)
        assert f"{name}:" in str(error.value)
        return
    pomdp = read_pomdp(CORPUS / name)
    assert (pomdp.n_states, pomdp.n_actions, pomdp.n_observations) == HEADER_SIZES[name]


def test_mini_hall2_reads_with_missing_rows_option():
    if not CORPUS.is_dir():
        pytest.skip("no corpus")
    pomdp = read_pomdp(CORPUS / "mini-hall2.pomdp", missing_rows="absorbing")
    assert pomdp.transitions[0][12, 12] == 1.0
    reset = read_pomdp(CORPUS / "mini-hall2.pomdp", missing_rows="reset")
    np.testing.assert_allclose(reset.transitions[1][12].toarray().ravel(), reset.initial_belief)


TIGER = """
# comment line
discount: 0.95
values: reward
states: tiger-left tiger-right
actions: listen open-left open-right
observations: tiger-left tiger-right
start: uniform
T: listen
identity
T: open-left
uniform
T: open-right : * uniform
O: listen
0.85 0.15
0.15
  0.85   # a matrix spanning lines, with a comment
O: open-left uniform
O: open-right : tiger-left uniform
O: open-right : 1 : * 0.5
R: listen : * : * : * -1
R: open-left : tiger-left : * : * -100
R: open-left : tiger-right : * : * 10
R: open-right : tiger-left : * : * 10
R: open-right : tiger-right : * : * -100
"""


def test_statement_forms_give_the_tiger_model():
    pomdp = parse_pomdp(TIGER)
    assert pomdp.state_names == ("tiger-left", "tiger-right")
    np.testing.assert_allclose(pomdp.transitions[0].toarray(), np.eye(2))
    np.testing.assert_allclose(pomdp.transitions[2].toarray(), np.full((2, 2), 0.5))
    np.testing.assert_allclose(pomdp.observations[0].toarray(), [[0.85, 0.15], [0.15, 0.85]])
    np.testing.assert_allclose(pomdp.observations[2].toarray(), np.full((2, 2), 0.5))
    np.testing.assert_allclose(pomdp.rewards, [[-1, -100, 10], [-1, 10, -100]])
    np.testing.assert_allclose(pomdp.initial_belief, [0.5, 0.5])


def _header(start: str = "start: uniform", values: str = "reward") -> str:
    return f"discount: 0.9\nvalues: {values}\nstates: 3\nactions: a b\nobservations: 2\n{start}\n"


BODY = "T: * identity\nO: * uniform\n"


@pytest.mark.parametrize(
    ("start", "expected"),
    [
        ("start: 0.2 0.3 0.5", [0.2, 0.3, 0.5]),
        ("start:\n0.2\n0.3 0.5", [0.2, 0.3, 0.5]),
        ("start: uniform", [1 / 3] * 3),
        ("start: 2", [0, 0, 1]),
        ("start include: 0 2", [0.5, 0, 0.5]),
        ("start exclude: 1", [0.5, 0, 0.5]),
    ],
)
def test_start_forms(start, expected):
    pomdp = parse_pomdp(_header(start) + BODY)
    np.testing.assert_allclose(pomdp.initial_belief, expected)


def test_start_by_state_name():
    text = "discount: 0.9\nstates: x y\nactions: 1\nobservations: 1\nstart: y\nT: * identity\nO: * uniform\n"
    np.testing.assert_allclose(parse_pomdp(text).initial_belief, [0, 1])


def test_cost_is_negated_and_later_lines_override():
    text = _header(values="cost") + BODY + "R: * : * : * : * 5\nR: b : 1 : * : * 2\n"
    pomdp = parse_pomdp(text)
    np.testing.assert_allclose(pomdp.rewards, [[-5, -5], [-5, -2], [-5, -5]])


def test_reset_row_is_the_start_belief():
    text = _header("start: 0.2 0.3 0.5") + "T: * identity\nT: b : 1 reset\nO: * uniform\n"
    np.testing.assert_allclose(parse_pomdp(text).transitions[1][1].toarray().ravel(), [0.2, 0.3, 0.5])


def test_reward_on_end_state_and_observation_is_collapsed():
    # R(s,a) = sum_{s',z} T(s,a,s') O(a,s',z) R(a,s,s',z)
    text = (
        _header()
        + "T: * : * uniform\nO: * : * : 0 0.25\nO: * : * : 1 0.75\n"
        + "R: a : * : 2 : 1 8\nR: b : 0 : * 1 2\nR: b : 1\n1 1\n1 1\n1 1\n"
    )
    pomdp = parse_pomdp(text)
    np.testing.assert_allclose(pomdp.rewards[:, 0], [(1 / 3) * 0.75 * 8] * 3)
    np.testing.assert_allclose(pomdp.rewards[:, 1], [0.25 * 1 + 0.75 * 2, 1.0, 0.0])


@pytest.mark.parametrize(
    ("text", "line", "found"),
    [
        (_header() + "T: * identity\nO: * uniform\nT: a : 0\n0.5 0.4 0.0\n", 9, "sums to 0.9"),
        (_header() + "T: * identity\nO: c uniform\n", 8, "found 'c'"),
        (_header() + "T: * identity\nO: * uniform\nR: a : 7 : * : * 1\n", 9, "found '7'"),
        (_header() + "T: * identity\nO: * uniform\nT: a : 0 : 1 oops\n", 9, "found 'oops'"),
        (_header() + "T: * identity\nO: a\n0.5 0.5\n0.5 0.5\n0.5 0.5 0.1\n", 11, "too many numbers"),
        (_header(values="profit") + BODY, 2, "found 'profit'"),
        (_header("start: 0.5 0.5 0.5") + BODY, 6, "sums to 1.5"),
        ("discount: 0.9\nstates: 2\nactions: 1\n", 3, "observations"),
        (_header() + "T: * identity\nO: * uniform\nbogus\n", 9, "found 'bogus'"),
        (_header() + "T: * identity\n", 7, "O row"),
    ],
)
def test_malformed_files_name_file_line_and_expectation(text, line, found, tmp_path):
    path = tmp_path / "bad.pomdp"
    path.write_text(text)
    with pytest.raises(PomdpFormatError) as error:
        read_pomdp(path)
    message = str(error.value)
    assert f"{path}:{line}:" in message, message
    assert found in message, message


def test_unreadable_file_is_a_format_error(tmp_path):
    with pytest.raises(PomdpFormatError, match="no such file"):
        read_pomdp(tmp_path / "missing.pomdp")


@st.composite
def random_pomdps(draw):
    n_states = draw(st.integers(1, 5))
    n_actions = draw(st.integers(1, 3))
    n_obs = draw(st.integers(1, 4))
    seed = draw(st.integers(0, 2**32 - 1))
    named = draw(st.booleans())
    rng = np.random.default_rng(seed)

    def stochastic(rows: int, cols: int) -> np.ndarray:
        matrix = rng.random((rows, cols)) * (rng.random((rows, cols)) < 0.6)
        matrix[np.arange(rows), rng.integers(cols, size=rows)] += 0.1
        return matrix / matrix.sum(axis=1, keepdims=True)

    return POMDP(
        transitions=[stochastic(n_states, n_states) for _ in range(n_actions)],
        rewards=rng.normal(size=(n_states, n_actions)) * (rng.random((n_states, n_actions)) < 0.7),
        discount=float(rng.uniform(0, 1)),
        state_names=[f"s{i}-x" for i in range(n_states)] if named else None,
        action_names=[f"act_{i}" for i in range(n_actions)] if named else None,
        observations=[stochastic(n_states, n_obs) for _ in range(n_actions)],
        initial_belief=stochastic(1, n_states)[0],
        observation_names=[f"z{i}" for i in range(n_obs)] if named else None,
    )


@settings(max_examples=40, deadline=None)
@given(pomdp=random_pomdps())
def test_write_read_round_trip_preserves_the_model(pomdp, tmp_path_factory):
    path = tmp_path_factory.mktemp("rt") / "model.pomdp"
    write_pomdp(pomdp, path)
    again = read_pomdp(path)
    assert again.discount == pomdp.discount
    assert (again.state_names, again.action_names, again.observation_names) == (
        pomdp.state_names,
        pomdp.action_names,
        pomdp.observation_names,
    )
    np.testing.assert_array_equal(again.rewards, pomdp.rewards)
    np.testing.assert_array_equal(again.initial_belief, pomdp.initial_belief)
    for a in range(pomdp.n_actions):
        assert (again.transitions[a] != pomdp.transitions[a]).nnz == 0
        assert (again.observations[a] != pomdp.observations[a]).nnz == 0


def test_round_trip_of_a_corpus_file(tmp_path):
    if not CORPUS.is_dir():
        pytest.skip("no corpus")
    pomdp = read_pomdp(CORPUS / "hallway.POMDP")
    again = read_pomdp(write_pomdp(pomdp, tmp_path / "hallway.pomdp"))
    np.testing.assert_array_equal(again.rewards, pomdp.rewards)
    assert all(sp.linalg.norm(x - y) == 0 for x, y in zip(again.transitions, pomdp.transitions, strict=True))


# ------------------------------------------------------------------------ the sparse vectorised reader
FIXTURE = Path(__file__).resolve().parent / "data" / "old_reader_models.npz"


def test_reader_matches_the_previous_reader_on_a_few_files():
    """The models the dense one-statement-at-a-time reader (commit af92ccb) gave for a few corpus files
    (scripts/compare_pomdp_parsers.py compares the whole corpus and wrote this fixture)."""
    if not CORPUS.is_dir():
        pytest.skip("no corpus")
    with np.load(FIXTURE, allow_pickle=False) as data:
        names = sorted({key.split("/")[0] for key in data.files})
        assert len(names) == 7
        for name in names:
            model = read_pomdp(
                CORPUS / name, missing_rows="absorbing" if name == "mini-hall2.pomdp" else "error"
            )
            assert model.discount == float(data[f"{name}/discount"])
            np.testing.assert_array_equal(model.initial_belief, data[f"{name}/start"])
            np.testing.assert_allclose(model.rewards, data[f"{name}/rewards"], rtol=1e-12, atol=1e-12)
            for letter, matrices in (("T", model.transitions), ("O", model.observations)):
                for action, matrix in enumerate(matrices):
                    rows, columns = data[f"{name}/{letter}/{action}"]
                    expected = sp.csr_matrix(
                        (data[f"{name}/{letter}/{action}/values"], (rows, columns)), shape=matrix.shape
                    )
                    assert (matrix != expected).nnz == 0, (name, letter, action)


def _dense(writes) -> np.ndarray:
    actions, rows, columns, values, _ = writes.resolve()
    array = np.zeros(writes.shape)
    array[actions, rows, columns] = values
    return array


@st.composite
def statement_sequences(draw):
    """Random T/O/R statements of every form over a tiny model, and the arrays a naive dense painter gives."""
    n_states, n_actions, n_obs = draw(st.integers(1, 4)), draw(st.integers(1, 3)), draw(st.integers(1, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    start = rng.dirichlet(np.ones(n_states)) * (rng.random(n_states) < 0.7)
    start = start / start.sum() if start.sum() > 0 else np.full(n_states, 1 / n_states)
    arrays = {
        "T": np.zeros((n_actions, n_states, n_states)),
        "O": np.zeros((n_actions, n_states, n_obs)),
        "R": np.zeros((n_actions, n_states, n_states, n_obs)),
    }
    sizes = {"a": n_actions, "s": n_states, "z": n_obs}
    lines = []

    def pick(kind):  # (text, index or slice)
        if draw(st.booleans()) and draw(st.booleans()):
            return "*", slice(None)
        index = draw(st.integers(0, sizes[kind] - 1))
        return str(index), index

    def number():
        return float(rng.choice([0.0, 0.125, 0.25, 0.5, 1.0, -2.5, 3.0]))

    def numbers(count):
        values = np.array([number() for _ in range(count)])
        return values, " ".join(repr(v) for v in values.tolist())

    for _ in range(draw(st.integers(1, 30))):
        letter = draw(st.sampled_from("TTOOR"))
        last = "s" if letter == "T" else "z"
        form = draw(st.sampled_from(["entry", "entry", "entry", "row", "matrix"]))
        array = arrays[letter]
        a_text, a = pick("a")
        if letter == "R":
            s_text, s = pick("s")
            if form == "entry":
                (e_text, e), (z_text, z), value = pick("s"), pick("z"), number()
                array[a, s, e, z] = value
                lines.append(f"R: {a_text} : {s_text} : {e_text} : {z_text} {value!r}")
            elif form == "row":
                (e_text, e), (values, text) = pick("s"), numbers(n_obs)
                array[a, s, e, :] = values
                lines.append(f"R: {a_text} : {s_text} : {e_text}\n{text}")
            else:
                values, text = numbers(n_states * n_obs)
                array[a, s] = values.reshape(n_states, n_obs)
                lines.append(f"R: {a_text} : {s_text}\n{text}")
            continue
        width = n_states if letter == "T" else n_obs
        words = ["uniform", "reset", "identity"] if letter == "T" else ["uniform"]
        if form == "entry":
            (s_text, s), (x_text, x), value = pick("s"), pick(last), number()
            array[a, s, x] = value
            lines.append(f"{letter}: {a_text} : {s_text} : {x_text} {value!r}")
        elif form == "row":
            s_text, s = pick("s")
            word = draw(st.sampled_from([None, *words[:2]]))
            if word == "uniform":
                array[a, s, :] = 1.0 / width
            elif word == "reset":
                array[a, s, :] = start
            else:
                values, word = numbers(width)
                array[a, s, :] = values
            lines.append(f"{letter}: {a_text} : {s_text} {word}")
        else:
            word = draw(st.sampled_from([None, *words]))
            if word == "uniform":
                array[a] = 1.0 / width
            elif word == "reset":
                array[a] = start
            elif word == "identity":
                array[a] = np.eye(n_states)
            else:
                values, word = numbers(n_states * width)
                array[a] = values.reshape(n_states, width)
            lines.append(f"{letter}: {a_text}\n{word}")
    header = (
        f"discount: 0.9\nstates: {n_states}\nactions: {n_actions}\nobservations: {n_obs}\n"
        f"start: {' '.join(repr(p) for p in start.tolist())}\n"
    )
    return header + "\n".join(lines) + "\n", arrays


@settings(max_examples=150, deadline=None)
@given(case=statement_sequences())
def test_any_statement_sequence_gives_what_a_dense_painter_gives(case):
    """Overrides, wildcards, rows, matrices, identity/uniform/reset and R on (s, s', z), in any order: the sparse
    reader (one-entry statements decoded together, the rest one by one) equals painting dense arrays in order."""
    text, expected = case
    parser = pomdp_io._Parser(text, "<generated>")
    parser.parse_statements()
    transitions, observations = _dense(parser.transitions), _dense(parser.observations)
    np.testing.assert_array_equal(transitions, expected["T"])
    np.testing.assert_array_equal(observations, expected["O"])
    # R is collapsed with stochastic T and O (the reader copies R(s, a) exactly when no statement of an action
    # names an end state or observation, which equals the sum only for rows summing to 1)
    rng = np.random.default_rng(len(text))
    stochastic = []
    for shape in (transitions.shape, observations.shape):
        weights = rng.random(shape) * (rng.random(shape) < 0.6)
        np.put_along_axis(weights, rng.integers(shape[2], size=(*shape[:2], 1)), 1.0, axis=2)  # no empty row
        stochastic.append(weights / weights.sum(axis=2, keepdims=True))
    rewards = parser._collapse_rewards(*([sp.csr_matrix(m) for m in array] for array in stochastic))
    collapsed = np.einsum("ase,aez,asez->sa", *stochastic, expected["R"])
    np.testing.assert_allclose(rewards, collapsed, rtol=1e-12, atol=1e-12)


VALID = (
    "discount: 0.9\nstates: 3\nactions: a b\nobservations: 2\nstart: uniform\nT: * identity\nO: * uniform\n"
)


@pytest.mark.parametrize(
    ("extra", "line", "fragments"),
    [
        (
            "T: b : 1 : 0 -0.5\nT: b : 1 : 1 1.5\n",
            8,
            ["T entry for action 1 ('b'), start state 1, end state 0 is negative (-0.5)"],
        ),
        ("O: a : 2\n1.5 -0.5\n", 8, ["O entry for action 0 ('a'), end state 2, observation 1 is negative"]),
        ("T: a : 0 : 0 1e999\n", 8, ["T entry for action 0 ('a')", "too large for a float"]),
        ("R: a : 0 : * : * 1\nR: b : 2 : * : * 1e400\n", 9, ["reward is too large for a float"]),
    ],
)
def test_negative_and_overflowing_numbers_name_the_line_and_the_entry(extra, line, fragments):
    with pytest.raises(PomdpFormatError) as error:
        parse_pomdp(VALID + extra, "m.pomdp")
    message = str(error.value)
    assert message.startswith(f"m.pomdp:{line}: "), message
    assert all(fragment in message for fragment in fragments), message
    assert "\n" not in message


def test_negative_start_probability_names_the_state():
    text = VALID.replace("start: uniform", "start: 0.5 -0.5 1.0")
    with pytest.raises(PomdpFormatError, match=r"m.pomdp:5: the start belief gives state 1 the negative"):
        parse_pomdp(text, "m.pomdp")


def test_a_huge_identity_model_stays_sparse_and_a_dense_one_is_refused():
    big = (
        "discount: 0.95\nstates: 200000\nactions: 2\nobservations: 1\nstart: 0\nT: * identity\nO: * uniform\n"
    )
    pomdp = parse_pomdp(big + "R: * : 7 : * : * 1\n")
    assert pomdp.n_states == 200_000 and pomdp.transitions[1].nnz == 200_000
    assert pomdp.rewards[7, 1] == 1.0 and pomdp.rewards.sum() == 2.0
    with pytest.raises(PomdpFormatError) as error:
        parse_pomdp(big + "T: 1 uniform\n", "big.pomdp")
    message = str(error.value)
    assert message.startswith("big.pomdp:8: 'T: 1' uniform writes 40,000,000,000 entries"), message
    assert "dense" in message


def test_line_numbers_with_crlf_non_ascii_and_names_like_keywords():
    text = VALID.replace("\n", "\r\n") + "# caf\u00e9\r\nT: a : 0\r\n0.5 0.4 0.0\r\n"
    for variant in (
        text,
        text.replace("# caf\u00e9", "# cafe"),
    ):  # the per-line and the vectorised token lines
        with pytest.raises(
            PomdpFormatError, match=r"^m.pomdp:9: T row for action 0 \('a'\), start state 0 sums"
        ):
            parse_pomdp(variant, "m.pomdp")
    keywords = (
        "discount: 0.9\nstates: x T O\nactions: go R\nobservations: z O\nT: R identity\nT: go : T : O 0.5\n"
    )
    keywords += "T: go : T : x 0.5\nT: go : x : x 1\nT: go : O : O 1\nO: * uniform\nR: R : T : * : * 2\n"
    pomdp = parse_pomdp(keywords)  # a state named 'T' makes the reader parse statement by statement
    np.testing.assert_array_equal(pomdp.transitions[0].toarray(), [[1, 0, 0], [0.5, 0, 0.5], [0, 0, 1]])
    np.testing.assert_array_equal(pomdp.rewards[:, 1], [0, 2, 0])


def _sparse_stochastic(rng: np.random.Generator, rows: int, columns: int, per_row: int) -> sp.csr_matrix:
    spread = columns // per_row  # one column in each of per_row bands: distinct and sorted
    picked = np.arange(per_row) * spread + rng.integers(0, spread, size=(rows, per_row))
    values = rng.random((rows, per_row)) + 0.05
    values /= values.sum(axis=1, keepdims=True)
    indptr = np.arange(0, rows * per_row + 1, per_row)
    return sp.csr_matrix((values.ravel(), picked.ravel(), indptr), shape=(rows, columns))


def test_chapter5_size_model_round_trips_exactly(tmp_path):
    """~5,000 states x 5 actions x 81 observations (the largest chapter-5 model size), sparse."""
    rng = np.random.default_rng(5)
    n_states, n_actions, n_obs = 4831, 5, 81
    pomdp = POMDP(
        transitions=[_sparse_stochastic(rng, n_states, n_states, 5) for _ in range(n_actions)],
        rewards=rng.normal(size=(n_states, n_actions)) * (rng.random((n_states, n_actions)) < 0.5),
        discount=0.95,
        observations=[_sparse_stochastic(rng, n_states, n_obs, 3) for _ in range(n_actions)],
        initial_belief=rng.dirichlet(np.ones(n_states)),
        action_names=["stay", "north", "south", "east", "west"],
    )
    again = read_pomdp(write_pomdp(pomdp, tmp_path / "big.pomdp"))
    assert again.action_names == pomdp.action_names and again.discount == pomdp.discount
    np.testing.assert_array_equal(again.rewards, pomdp.rewards)
    np.testing.assert_array_equal(again.initial_belief, pomdp.initial_belief)
    for a in range(n_actions):
        assert (again.transitions[a] != pomdp.transitions[a]).nnz == 0
        assert (again.observations[a] != pomdp.observations[a]).nnz == 0
