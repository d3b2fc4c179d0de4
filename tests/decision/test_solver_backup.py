"""The vectorised point-based backup (decision/backup.py) against a naive per-belief, per-observation loop.

The continuation of each branch is chosen by float32 scores (support-restricted path) or float64 dense scores
(dense observation models); the vectors are built in float64 for the best action only. Each vector must be the
exact value of its plan, and its value at the belief must equal the exact backup's up to float32 near-ties.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.decision.backup import BackupOperator
from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp
from embodied_adhoc.decision.rocksample import rocksample

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "pomdp"


def _sparse_identity_pomdp(n_states: int = 60, n_actions: int = 3, seed: int = 4) -> POMDP:
    """Sparse O (the state is observed) with predicted beliefs dense enough that the old code took its sparse
    projection path: the support-restricted scores must cover it."""
    rng = np.random.default_rng(seed)
    noisy = 0.7 * np.eye(n_states) + 0.3 * np.roll(np.eye(n_states), 1, axis=1)
    return _random_pomdp(rng, n_states, n_actions, noisy, density=0.4, bump=0.3)


def _random_pomdp(
    rng: np.random.Generator,
    n_states: int,
    n_actions: int,
    observation: np.ndarray,
    density: float,
    bump: float,
) -> POMDP:
    """Random sparse transitions (each row: entries with probability ``density``, plus ``bump`` on one random
    successor), normal rewards, discount 0.9, the same observation matrix for every action, uniform b0."""
    transitions = []
    for _ in range(n_actions):
        matrix = rng.random((n_states, n_states)) * (rng.random((n_states, n_states)) < density)
        matrix[np.arange(n_states), rng.integers(n_states, size=n_states)] += bump
        transitions.append(matrix / matrix.sum(axis=1, keepdims=True))
    return POMDP(
        transitions,
        rng.normal(size=(n_states, n_actions)),
        0.9,
        observations=[observation] * n_actions,
        initial_belief=np.full(n_states, 1.0 / n_states),
    )


def _model(name: str) -> POMDP:
    if name == "sparse-identity":
        return _sparse_identity_pomdp()
    if name == "tiger.95.POMDP":
        return read_pomdp(paths.asset(f"data/{name}"))
    if not (CORPUS / name).is_file():
        pytest.skip(f"corpus file {CORPUS / name} not present")
    return read_pomdp(CORPUS / name)


def _naive_backup_values(pomdp: POMDP, beliefs: np.ndarray, alphas: np.ndarray) -> np.ndarray:
    """max_a [b . R_a + gamma sum_z max_k (b T_a O_z) . alpha_k], one belief, action and observation at a time."""
    values = []
    for belief in beliefs:
        best = -np.inf
        for action in range(pomdp.n_actions):
            predicted = pomdp.transitions[action].T @ belief
            observation = pomdp.observations[action].toarray()
            future = sum(
                float((alphas @ (predicted * observation[:, z])).max()) for z in range(pomdp.n_observations)
            )
            best = max(best, float(belief @ pomdp.rewards[:, action]) + pomdp.discount * future)
        values.append(best)
    return np.asarray(values)


@pytest.mark.parametrize(
    "name", ["tiger.95.POMDP", "hallway.POMDP", "sarsop-TagAvoid.pomdp", "sparse-identity"]
)
def test_backup_equals_the_naive_one_and_each_vector_is_its_plan(name):
    pomdp = _model(name)
    beliefs = collect_beliefs(pomdp, 24, np.random.default_rng(3))
    alphas = perseus(pomdp, PerseusConfig(n_beliefs=60, max_iterations=8, seed=0)).alphas
    vectors, actions, values, children = BackupOperator(pomdp).backup(beliefs, alphas, with_children=True)
    np.testing.assert_allclose(values, np.einsum("is,is->i", beliefs, vectors), rtol=0, atol=1e-9)
    exact = _naive_backup_values(pomdp, beliefs, alphas)
    scale = 1.0 + np.abs(exact)
    assert np.all(values <= exact + 1e-9 * scale)  # a plan's value never exceeds the exact backup
    assert np.all(values >= exact - 1e-5 * scale)  # float32 scores only lose on near-ties
    for vector, action, plan in zip(vectors, actions, children, strict=True):
        observation = pomdp.observations[action].toarray()
        continuation = sum(observation[:, z] * alphas[plan[z]] for z in range(pomdp.n_observations))
        rebuilt = pomdp.rewards[:, action] + pomdp.discount * (pomdp.transitions[action] @ continuation)
        np.testing.assert_allclose(vector, rebuilt, rtol=0, atol=1e-9)


def _single_state_observation_pomdp(n_states: int = 40, n_actions: int = 3, seed: int = 7) -> POMDP:
    """The first half of the states is observed exactly (an observation emitted by that state alone), the second
    half emits one shared observation with probability 0.6 and its own with 0.4 (pursuit: 64 of 81 observations
    are emitted by one state, one by every state)."""
    half = n_states // 2
    observation = np.zeros((n_states, n_states + 1))
    observation[np.arange(half), np.arange(half)] = 1.0
    observation[np.arange(half, n_states), np.arange(half, n_states)] = 0.4
    observation[half:, n_states] = 0.6
    return _random_pomdp(np.random.default_rng(seed), n_states, n_actions, observation, density=0.3, bump=0.2)


def test_single_entry_branches_choose_what_the_scores_choose():
    """Branches with one entry (observations that one state emits) take that state's first best vector without a
    product; the choices (and so the vectors, values and plans) must be bit-identical to the product's argmax,
    including exact ties, near-ties a few units in the last place apart (not 'clean': left to the product) and
    tiny weights."""
    pomdp = _single_state_observation_pomdp()
    operator = BackupOperator(pomdp)
    rng = np.random.default_rng(11)
    alphas = rng.normal(size=(30, pomdp.n_states)) * 5.0
    alphas[7] = alphas[3]  # an exact duplicate: the first of the two must win
    alphas[12, :5] = alphas[4, :5]  # ties on some states only
    top = alphas.argmax(axis=0)
    near = np.nextafter(alphas[top, np.arange(pomdp.n_states)].astype(np.float32), np.float32(-np.inf))
    alphas[20, 5:10] = near[5:10]  # one float32 step below the best at states 5-9: not clean
    beliefs = collect_beliefs(pomdp, 300, np.random.default_rng(5))
    beliefs[:4] = 0.0
    beliefs[:4, 0] = 1.0 - 1e-35  # a branch of weight ~1e-35: left to the product
    beliefs[:4, 1] = 1e-35
    prepared = operator.prepare(alphas)
    with_states = operator.backup(beliefs, prepared, with_children=True)
    top, leader, clean = operator._state_best(prepared)
    assert 0 < clean.sum() < pomdp.n_states  # both kinds of state occur
    # The same operator with no clean state: every branch goes through the product.
    operator._state_best = lambda prepared: (top, leader, np.zeros_like(clean))
    products_only = operator.backup(beliefs, prepared, with_children=True)
    for got, expected in zip(with_states, products_only, strict=True):
        np.testing.assert_array_equal(got, expected)


def test_stage_values_on_the_belief_set_are_the_products_over_the_whole_stage():
    """With a CSR belief set a Perseus stage values each batch's kept vectors at all beliefs as it goes (the pending
    ones from the acceptance products); the result must be bit-identical to one product over the whole stage."""
    import scipy.sparse as sp

    from embodied_adhoc.decision import perseus_stages as stages
    from embodied_adhoc.decision.backup import blind_policy_vectors

    pomdp = _single_state_observation_pomdp()
    operator = BackupOperator(pomdp)
    beliefs = collect_beliefs(pomdp, 400, np.random.default_rng(2))
    rows = sp.csr_matrix(beliefs)
    alphas = blind_policy_vectors(pomdp)
    actions = np.arange(pomdp.n_actions)
    values = (rows @ alphas.T).max(axis=1)  # the solver's own products (CSR), so ties compare exactly
    rng = np.random.default_rng(0)
    for _ in range(4):  # a few stages, so that old vectors are kept and batches grow
        stage = stages.perseus_stage(operator, beliefs, rows, alphas, actions, values, rng, 32)
        scores_t = np.stack(stage.score_rows)
        np.testing.assert_array_equal(scores_t, (rows @ stage.vectors.T).T)
        np.testing.assert_array_equal(stage.values, scores_t.max(axis=0))
        assert np.all(stage.values >= values)
        np.testing.assert_array_equal(
            np.argmax(scores_t[:, stage.witness], axis=0), np.arange(len(stage.witness))
        )
        alphas, actions, values = stage.vectors, stage.actions, stage.values


@pytest.mark.parametrize("name", ["sarsop-TagAvoid.pomdp", "single-state"])
def test_batch_size_does_not_change_the_solve(name):
    """Batches only group backups against the same V_n; the Perseus rule runs in the stage's random order, so
    any batch size gives the sequential algorithm's stages, bit for bit (sparse belief rows included)."""
    pomdp = _single_state_observation_pomdp()
    solves = [
        perseus(
            pomdp, PerseusConfig(n_beliefs=300, max_iterations=12, seed=1, batch_size=size, update="perseus")
        )
        for size in (5, 256)
    ]
    np.testing.assert_array_equal(solves[0].alphas, solves[1].alphas)
    np.testing.assert_array_equal(solves[0].actions, solves[1].actions)
    assert solves[0].stats.trace[-1][1] == solves[1].stats.trace[-1][1]


@pytest.mark.parametrize("update", ["gauss-seidel", "perseus"])
@pytest.mark.parametrize("name", ["sarsop-TagAvoid.pomdp", "single-state"])
def test_threads_do_not_change_the_solve(name, update, monkeypatch):
    """threads=2 splits the branch scores and the belief set's value products by rows (each row is the same sum in
    the same order): the same vectors, plans, stage values and stage count as threads=1, bit for bit. The split
    threshold is lowered so that the small test products are split too."""
    from embodied_adhoc.decision import backup as backup_module

    pomdp = _single_state_observation_pomdp()
    monkeypatch.setattr(backup_module, "_SPLIT_MIN_WORK", 1)
    traces = {1: [], 2: []}
    split = []
    original = backup_module.RowProducts.__call__

    def counting(self, matrix, dense, reduce=None):
        if self.threads > 1 and getattr(matrix, "nnz", 0) and matrix.shape[0] > 1:
            split.append(matrix.shape[0])
        return original(self, matrix, dense, reduce)

    monkeypatch.setattr(backup_module.RowProducts, "__call__", counting)
    solves = {
        threads: perseus(
            pomdp,
            PerseusConfig(n_beliefs=300, max_iterations=12, seed=1, threads=threads, update=update),
            progress=lambda report, threads=threads: traces[threads].append(
                (report.iteration, report.value_b0, report.n_vectors, report.improvement)
            ),
        )
        for threads in (1, 2)
    }
    assert split, "no product was split over the threads"
    np.testing.assert_array_equal(solves[1].alphas, solves[2].alphas)
    np.testing.assert_array_equal(solves[1].actions, solves[2].actions)
    assert solves[1].stats.iterations == solves[2].stats.iterations
    assert [value for _, value in solves[1].stats.trace] == [value for _, value in solves[2].stats.trace]
    assert traces[1] == traces[2] and max(report[0] for report in traces[1]) == solves[1].stats.iterations


@pytest.mark.parametrize("name", ["sarsop-TagAvoid.pomdp", "single-state"])
def test_gauss_seidel_stages_keep_plans_exact_and_values_monotone(name):
    """Gauss-Seidel stages (perseus_stages.perseus_stage with a Seidel): V_{n+1} >= V_n on B, the stage's values on
    B are the
    products with its vectors, later backups continue with vectors of the same stage, and every vector of the plan
    graph is at most the value of doing its action and then its continuations (equal unless a continuation was
    replaced by a dominating vector): the closed set the lower bound rests on."""
    from embodied_adhoc.decision import perseus_stages as stages
    from embodied_adhoc.decision.backup import blind_policy_vectors
    from embodied_adhoc.decision.plan_graph import PlanGraph

    pomdp = _single_state_observation_pomdp()
    operator = BackupOperator(pomdp)
    # A belief set whose first stages already improve several beliefs with different vectors (with seed 2 or 4 Tag's
    # first six stages keep only 1-3 new vectors each, one of which covers every belief, so none continues another)
    beliefs = collect_beliefs(pomdp, 300, np.random.default_rng(0))
    rows = stages.belief_rows(beliefs)
    graph = PlanGraph.of_blind_policies(blind_policy_vectors(pomdp), pomdp.n_observations)
    current = np.arange(len(graph))
    alphas, actions = graph.vectors[current], graph.actions[current]
    values = np.asarray(rows @ alphas.T).max(axis=1)
    witness, owner, old_rows = np.full(len(current), -1), None, None
    rng = np.random.default_rng(0)
    same_stage = 0
    for _ in range(6):
        seidel = stages.Seidel(graph, current, owner, old_rows)
        stage = stages.perseus_stage(operator, beliefs, rows, alphas, actions, values, rng, 32, seidel)
        new_rows = seidel.extended[len(current) :]
        same_stage += int(np.isin(graph.children[new_rows], new_rows).sum())
        assert np.all(stage.values >= values)
        np.testing.assert_array_equal(stage.values, np.asarray(rows @ stage.vectors.T).max(axis=1))
        extended_witness = np.concatenate([witness, seidel.new_witness])
        current = stages.record_stage(graph, seidel.extended, stage, rows, extended_witness)
        witness, owner, old_rows = stage.witness, stage.owner, stage.score_rows
        alphas, actions, values = graph.vectors[current], graph.actions[current], stage.values
        np.testing.assert_array_equal(alphas[owner], alphas[np.argmax(np.asarray(rows @ alphas.T), axis=1)])
    assert same_stage > 0, "no backup continued with a vector of its own stage"
    vectors, plan_actions, children = graph.vectors, graph.actions, graph.children
    for row in graph.closure(current):
        action = plan_actions[row]
        observation = pomdp.observations[action].toarray()  # (S, Z)
        continuation = (observation * vectors[children[row]].T).sum(axis=1)
        plan = pomdp.rewards[:, action] + pomdp.discount * (pomdp.transitions[action] @ continuation)
        assert np.all(vectors[row] <= plan + 1e-9)


def test_gauss_seidel_stages_converge_in_fewer_stages_to_a_higher_value():
    """On Tag's fixed belief set (1,000 beliefs, the default bound rule with tolerance 1e-3) the Gauss-Seidel
    stages stop in fewer stages than the classic ones, at a lower bound at least as high."""
    pomdp = _model("sarsop-TagAvoid.pomdp")
    classic, seidel = (
        perseus(pomdp, PerseusConfig(n_beliefs=1000, seed=0, update=update))
        for update in ("perseus", "gauss-seidel")
    )
    assert seidel.stats.converged_on_beliefs and classic.stats.converged_on_beliefs
    assert seidel.stats.iterations < classic.stats.iterations
    assert seidel.stats.lower >= classic.stats.lower


def test_row_products_equal_the_whole_product_and_refuse_zero_threads():
    import scipy.sparse as sp

    from embodied_adhoc.decision import backup as backup_module
    from embodied_adhoc.errors import SolverError

    rng = np.random.default_rng(3)
    matrix = sp.random(997, 211, density=0.1, format="csr", dtype=np.float32, random_state=rng)
    matrix.data[:] = rng.random(matrix.nnz, dtype=np.float32)
    dense = rng.random((300, 211), dtype=np.float32).T  # not contiguous, as alphas.T
    products = backup_module.RowProducts(3)
    try:
        whole = matrix @ dense
        np.testing.assert_array_equal(products(matrix, dense), whole)
        np.testing.assert_array_equal(
            products(matrix, dense, lambda s: np.argmax(s, axis=1)), np.argmax(whole, axis=1)
        )
    finally:
        products.close()
    with pytest.raises(SolverError, match="threads must be an integer >= 1, got 0"):
        PerseusConfig(threads=0)


@pytest.mark.parametrize(
    "name", ["tiger.95.POMDP", "sparse-identity", "single-state", "dense-observations", "rocksample"]
)
def test_single_belief_backup_is_the_batched_backup_bit_for_bit(name):
    """backup_one (all actions and observations of one belief in one product) gives the vector, action, value and
    plan of the batched support-restricted backup on that belief, to the bit: on sparse and dense observation
    models, with exact duplicates among the vectors (ties), point-mass beliefs (impossible branches) and beliefs
    collected by simulation."""
    if name == "single-state":
        pomdp = _single_state_observation_pomdp()
    elif name == "dense-observations":
        rng = np.random.default_rng(3)
        observation = rng.random((25, 6)) + 0.05  # every state emits every observation
        observation /= observation.sum(axis=1, keepdims=True)
        pomdp = _random_pomdp(rng, 25, 4, observation, density=0.3, bump=0.2)
    elif name == "rocksample":
        pomdp = rocksample(3, 2)
    else:
        pomdp = _model(name)
    operator = BackupOperator(pomdp)
    rng = np.random.default_rng(9)
    alphas = rng.normal(size=(40, pomdp.n_states)) * 5.0
    alphas[9] = alphas[2]  # an exact duplicate: the first of the two must win
    beliefs = collect_beliefs(pomdp, 30, np.random.default_rng(2))
    point = np.zeros((3, pomdp.n_states))
    point[np.arange(3), np.arange(3) % pomdp.n_states] = 1.0
    beliefs = np.vstack([beliefs, point])
    alphas_t = np.ascontiguousarray(alphas.T, dtype=np.float32)
    fallback_scores = operator.fallback_scores(alphas)
    for belief in beliefs:
        vectors, actions, values, children = operator.backup(
            belief[None, :], alphas, with_children=True, project=False
        )
        for scores_t in (alphas_t, None):  # None: the float32 scores cast from the reached states' columns
            vector, action, value, plan = operator.backup_one(belief, alphas, scores_t, fallback_scores)
            np.testing.assert_array_equal(vector, vectors[0])
            assert action == actions[0]
            assert value == values[0]  # the same float, not a close one
            np.testing.assert_array_equal(plan, children[0])


def test_reduced_row_products_by_blocks_are_the_whole_product(monkeypatch):
    """A reduced product formed a few rows at a time (the solver's value products over all of B) gives the same
    bits as the whole product reduced at once, with and without threads."""
    import scipy.sparse as sp

    from embodied_adhoc.decision import backup as backup_module
    from embodied_adhoc.decision.backup import RowProducts, row_argmax, row_max

    rng = np.random.default_rng(5)
    matrix = sp.random(301, 40, density=0.2, random_state=7, format="csr")
    dense = rng.normal(size=(40, 37))
    whole = np.asarray(matrix @ dense)
    monkeypatch.setattr(backup_module, "_BLOCK_ENTRIES", 37 * 16 + 5)  # blocks of 16 rows, the last shorter
    monkeypatch.setattr(backup_module, "_SPLIT_MIN_WORK", 1)
    for threads in (1, 3):
        products = RowProducts(threads)
        try:
            np.testing.assert_array_equal(products(matrix, dense, row_max), whole.max(axis=1))
            np.testing.assert_array_equal(
                products(matrix, dense.T.copy().T, row_argmax), np.argmax(whole, axis=1)
            )
        finally:
            products.close()


def _dense_observation_pomdp() -> POMDP:
    """Every state emits every observation: the backups score with the dense projection."""
    rng = np.random.default_rng(3)
    observation = rng.random((25, 6)) + 0.05
    observation /= observation.sum(axis=1, keepdims=True)
    return _random_pomdp(rng, 25, 4, observation, density=0.3, bump=0.2)


@pytest.mark.parametrize("ties", ["duplicates", "leading-duplicates"])
def test_dense_projection_by_blocks_of_vectors_chooses_what_one_block_chooses(ties, monkeypatch):
    """The dense projection and its BLAS scores formed a few vectors at a time give the same vectors, actions,
    values and plans to the bit as one block: each branch's continuation is the first maximum of its fixed-order
    scores (exact duplicates among the vectors: the first of them), whatever the blocks. The chosen continuations
    are also the naive loop's first maxima. "leading-duplicates": the duplicated vector is best on every branch,
    and a copy raised by 1e-15 (within the summation-order error) ties it in BLAS."""
    from embodied_adhoc.decision import backup as backup_module

    pomdp = _dense_observation_pomdp()
    rng = np.random.default_rng(9)
    alphas = rng.normal(size=(40, pomdp.n_states)) * 5.0
    if ties == "leading-duplicates":
        alphas[2] = alphas.max(axis=0) + 1.0
        alphas[23] = alphas[2] + 1e-15
    alphas[[9, 31]] = alphas[2]  # exact duplicates across blocks: the first of them must win
    alphas[17] = alphas[5] + 1e-15  # a near-tie within the summation-order error
    beliefs = collect_beliefs(pomdp, 30, np.random.default_rng(2))
    point = np.zeros((3, pomdp.n_states))
    point[np.arange(3), np.arange(3)] = 1.0
    beliefs = np.vstack([beliefs, point])
    operator = BackupOperator(pomdp)
    assert not any(operator.sparse_observations)
    reference = operator.backup(beliefs, alphas, with_children=True)
    for block in (pomdp.n_states * pomdp.n_observations * 3, 1):  # blocks of 3 vectors; of one vector
        monkeypatch.setattr(backup_module, "_BLOCK_ENTRIES", block)
        blocked = BackupOperator(pomdp).backup(beliefs, alphas, with_children=True)
        for got, want in zip(blocked, reference, strict=True):
            np.testing.assert_array_equal(got, want)
    _, actions, _, children = reference
    for belief, action, plan in zip(beliefs, actions, children, strict=True):
        predicted = operator.transitions_t[action] @ belief
        observation = pomdp.observations[action].toarray()
        for z in range(pomdp.n_observations):
            # the fixed-order scores: summed over s in increasing order, as the backup's rescoring sums them
            scores = np.add.reduce(predicted[:, None] * (observation[:, z][:, None] * alphas.T), axis=0)
            assert plan[z] == int(np.argmax(scores))


@pytest.mark.parametrize("update", ["gauss-seidel", "perseus"])
def test_stage_products_by_chunks_change_nothing(update, monkeypatch):
    """The stage's values on B computed a vector at a time, its rows not kept between stages (as beyond
    _STAGE_ROWS_MAX_ENTRIES), and the value products over B by blocks of a few beliefs give the same solve to the
    bit as the defaults."""
    from embodied_adhoc.decision import backup as backup_module
    from embodied_adhoc.decision import perseus_stages

    pomdp = _single_state_observation_pomdp()
    config = PerseusConfig(n_beliefs=30, expand=True, max_iterations=12, seed=3, update=update)
    reference = perseus(pomdp, config)
    monkeypatch.setattr(perseus_stages, "_EVERYWHERE_BLOCK_ENTRIES", 1)
    monkeypatch.setattr(perseus_stages, "_STAGE_ROWS_MAX_ENTRIES", 0)
    monkeypatch.setattr(backup_module, "_BLOCK_ENTRIES", 7)
    chunked = perseus(pomdp, config)
    np.testing.assert_array_equal(chunked.alphas, reference.alphas)
    np.testing.assert_array_equal(chunked.actions, reference.actions)
    assert [value for _, value in chunked.stats.trace] == [value for _, value in reference.stats.trace]
    assert chunked.stats.upper == reference.stats.upper
