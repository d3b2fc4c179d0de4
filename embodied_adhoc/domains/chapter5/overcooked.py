"""Overcooked (section 5.2.5, Fig. 5.8; Carroll et al. 2019): the ad hoc helper passes onions and plates to a cook.

State ``(helper cell, cook cell, helper's hand, cook's hand, top counter, bottom counter, pan)``: cells top/bottom;
the helper holds nothing/onion/plate, the cook nothing/onion/plate/soup; each counter holds nothing/onion/plate;
the pan holds 0, 1 or 2 onions or a cooked soup. 2*2*3*4*3*3*4 = 1,728 states, plus "soup delivered" and the
absorbing state: 1,730. Fully observable (``z = y``, 1,730 observations). Actions up, down, noop, act.

Rules of one step (the helper's act resolves first):

* up / down move to the top / bottom cell;
* helper ``act``: empty-handed, it takes an onion (top: the onion supply) or a plate (bottom: the plate supply);
  holding something, it puts it on the counter of its cell if that counter is empty;
* cook ``act``: empty-handed, it takes what lies on the counter of its cell; with a plate at the top and a cooked
  soup in the pan it takes the soup; with an onion at the top and fewer than 3 onions in the pan it adds it (the
  third cooks the soup); with the soup at the bottom it delivers it (the "delivered" state); otherwise it puts
  what it holds on the counter of its cell if that counter was empty and the helper did not just fill it.

Reward +100 in the delivered state (then the absorbing state, 0), -1 otherwise. Initial belief: empty hands,
counters and pan, uniform over the 4 cell pairs.

Teammates (the cook), one model each, in the original's order: ``optimal`` (knows the task: the MMDP's optimal
marginal, ``library.optimal_teammate_policy``), ``upper`` / ``lower`` (empty-handed, with probability
``stubbornness`` = 0.9 it insists on receiving at the top / bottom counter: moves there, then acts; otherwise
optimal) and ``random`` (uniform). The original's bug (``bug_compatible=True``): its coin
``random.randint(0, 1) <= 0.9`` came up with probability 0.5, not 0.9, and was tossed once per state while the
model was built, so each state's choice was frozen into the model; the buggy variant reproduces that with a
seeded generator (``bug_seed``).
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.chapter5.library import (
    ModelLibrary,
    deterministic_matrix,
    joint_mdp,
    optimal_teammate_policy,
    reduce_joint,
    step_rewards,
    task_pomdp,
)

__all__ = ["TEAMMATES", "build_overcooked"]

ACTION_NAMES = ("up", "down", "noop", "act")
UP, DOWN, NOOP, ACT = range(4)
TOP, BOTTOM = range(2)
NOTHING, ONION, PLATE, SOUP = range(4)
COOKED = 3  # pan value of a cooked soup
DIMENSIONS = (2, 2, 3, 4, 3, 3, 4)
TEAMMATES = ("optimal", "upper", "lower", "random")


def _state_arrays() -> tuple[np.ndarray, ...]:
    grids = np.indices(DIMENSIONS).reshape(len(DIMENSIONS), -1)
    return tuple(grids)


def _encode(fields: tuple[np.ndarray, ...]) -> np.ndarray:
    return np.ravel_multi_index(fields, DIMENSIONS)


def _next_states(
    fields: tuple[np.ndarray, ...], helper_action: int, cook_action: int, delivered_state: int
) -> np.ndarray:
    helper, cook, helper_hand, cook_hand, top, bottom, pan = (f.copy() for f in fields)
    old_top, old_bottom = top.copy(), bottom.copy()
    helper_cell, cook_cell = fields[0], fields[1]
    if helper_action == UP:
        helper = np.zeros_like(helper)
    elif helper_action == DOWN:
        helper = np.ones_like(helper)
    if cook_action == UP:
        cook = np.zeros_like(cook)
    elif cook_action == DOWN:
        cook = np.ones_like(cook)
    helper_dropped_top = np.zeros_like(helper, dtype=bool)
    helper_dropped_bottom = np.zeros_like(helper, dtype=bool)
    if helper_action == ACT:
        empty = fields[2] == NOTHING
        helper_hand = np.where(empty, np.where(helper_cell == TOP, ONION, PLATE), helper_hand)
        helper_dropped_top = ~empty & (helper_cell == TOP) & (old_top == NOTHING)
        helper_dropped_bottom = ~empty & (helper_cell == BOTTOM) & (old_bottom == NOTHING)
        top = np.where(helper_dropped_top, fields[2], top)
        bottom = np.where(helper_dropped_bottom, fields[2], bottom)
        helper_hand = np.where(helper_dropped_top | helper_dropped_bottom, NOTHING, helper_hand)
    delivered = np.zeros_like(helper, dtype=bool)
    if cook_action == ACT:
        hand, at_top = fields[3], cook_cell == TOP
        counter = np.where(at_top, old_top, old_bottom)
        take = (hand == NOTHING) & (counter != NOTHING)
        serve = (hand == PLATE) & at_top & (fields[6] == COOKED)
        add_onion = (hand == ONION) & at_top & (fields[6] < COOKED)
        deliver = (hand == SOUP) & ~at_top
        keep_soup = (hand == SOUP) & at_top
        other = (hand != NOTHING) & ~serve & ~add_onion & ~deliver & ~keep_soup
        drop_top = other & at_top & (old_top == NOTHING) & ~helper_dropped_top
        drop_bottom = other & ~at_top & (old_bottom == NOTHING) & ~helper_dropped_bottom
        cook_hand = np.where(take, counter, cook_hand)
        top = np.where(take & at_top, NOTHING, top)
        bottom = np.where(take & ~at_top, NOTHING, bottom)
        cook_hand = np.where(serve, SOUP, cook_hand)
        pan = np.where(serve, 0, pan)
        cook_hand = np.where(add_onion, NOTHING, cook_hand)
        pan = np.where(add_onion, fields[6] + 1, pan)  # the third onion makes pan == COOKED
        top = np.where(drop_top, fields[3], top)
        bottom = np.where(drop_bottom, fields[3], bottom)
        cook_hand = np.where(drop_top | drop_bottom, NOTHING, cook_hand)
        delivered = deliver
    encoded = _encode((helper, cook, helper_hand, cook_hand, top, bottom, pan))
    return np.where(delivered, delivered_state, encoded)


def _stubborn_action(fields: tuple[np.ndarray, ...], cell: int) -> np.ndarray:
    """Empty-handed cook insisting on the ``cell`` counter: move there, then act."""
    move = UP if cell == TOP else DOWN
    return np.where(fields[1] == cell, ACT, move)


def build_overcooked(
    stubbornness: float = 0.9,
    bug_compatible: bool = False,
    bug_seed: int = 0,
    horizon: int = 50,
    n_beliefs: int = 1800,
) -> ModelLibrary:
    """The four-teammate overcooked library of Table 5.2 (eps 0, h 50, 1,800 beliefs)."""
    fields = _state_arrays()
    n_live = len(fields[0])
    delivered_state, absorbing = n_live, n_live + 1
    n_states = n_live + 2
    goal = np.zeros(n_states, dtype=bool)
    goal[delivered_state] = True
    rewards = step_rewards(goal, absorbing, len(ACTION_NAMES))
    joint = []
    for a in range(4):
        row = []
        for b in range(4):
            nxt = np.concatenate([_next_states(fields, a, b, delivered_state), [absorbing, absorbing]])
            row.append(deterministic_matrix(nxt, n_states))
        joint.append(row)
    mmdp = joint_mdp(joint, rewards, ACTION_NAMES)
    optimal = optimal_teammate_policy(mmdp, 4)
    empty_handed = np.append(fields[3] == NOTHING, [False, False])
    rng = np.random.default_rng(bug_seed)
    policies = {"optimal": optimal, "random": np.full((n_states, 4), 0.25)}
    for name, cell in (("upper", TOP), ("lower", BOTTOM)):
        stubborn = np.zeros((n_states, 4))
        stubborn[np.arange(n_live), _stubborn_action(fields, cell)] = 1.0
        stubborn[n_live:] = optimal[n_live:]
        if bug_compatible:  # one frozen coin per state, heads w.p. 0.5 (see the module docstring)
            insists = empty_handed & (rng.integers(0, 2, size=n_states) == 0)
            policies[name] = np.where(insists[:, None], stubborn, optimal)
        else:
            weight = np.where(empty_handed, stubbornness, 0.0)[:, None]
            policies[name] = weight * stubborn + (1.0 - weight) * optimal
    names = tuple(
        "delivered"
        if s == delivered_state
        else "absorbing"
        if s == absorbing
        else "h{}c{}-h{}c{}-t{}b{}-p{}".format(*(int(f[s]) for f in fields))
        for s in range(n_states)
    )
    start = np.zeros(n_states, dtype=bool)
    start[:n_live] = (
        (fields[2] == NOTHING)
        & (fields[3] == NOTHING)
        & (fields[4] == NOTHING)
        & (fields[5] == NOTHING)
        & (fields[6] == 0)
    )
    observation = deterministic_matrix(np.arange(n_states), n_states)
    pomdps = [
        task_pomdp(
            reduce_joint(joint, policies[name]), rewards, observation, start, names, ACTION_NAMES, names
        )
        for name in TEAMMATES
    ]
    settings = {"stubbornness": stubbornness, "bug_compatible": bool(bug_compatible), "bug_seed": bug_seed}
    return ModelLibrary(
        "overcooked",
        TEAMMATES,
        tuple(pomdps),
        (mmdp,) * len(TEAMMATES),
        horizon,
        0.0,
        n_beliefs,
        absorbing,
        "overcooked: the ad hoc helper passes onions and plates to one of four cooks",
        settings,
        teammates={name: (lambda m, policy=policies[name]: policy) for name in TEAMMATES},
    )
