"""The contact → penalty mapping on hand-made events, and the contact debouncing on hand-made
begin/separate sequences (no pymunk involved)."""

from __future__ import annotations

import pytest

from a2cm_phys.config import Rewards
from a2cm_phys.envs.contacts import (
    AGENT_WALL,
    PURSUER_EVADER,
    PURSUER_PURSUER,
    ContactTracker,
    score_events,
)

# Distinct powers of ten, so every term of a reward is visible in the sum.
REWARDS = Rewards(step=-1.0, collision=-100.0, capture=10_000.0, wall=-0.01)
P01 = (PURSUER_PURSUER, "pursuer_0", "pursuer_1")
P02 = (PURSUER_PURSUER, "pursuer_0", "pursuer_2")
P12 = (PURSUER_PURSUER, "pursuer_1", "pursuer_2")
CATCH = (PURSUER_EVADER, "pursuer_1", "evader")
WALL0 = (AGENT_WALL, "pursuer_0", "wall")
WALL_E = (AGENT_WALL, "evader", "wall")


def ev(pair: tuple[str, str, str], step: int = 1) -> tuple[str, str, str, int]:
    return (*pair, step)


# --------------------------------------------------------------------------- score_events


@pytest.mark.parametrize("mode", ["off", "terminate", "penalize"])
def test_no_events_is_the_step_reward(mode):
    s = score_events([], REWARDS, mode)
    assert (s.reward, s.terminated, s.captured, s.collisions, s.wall_contacts) == (
        REWARDS.step,
        False,
        False,
        0,
        0,
    )


@pytest.mark.parametrize("mode", ["off", "terminate", "penalize"])
def test_pursuer_touching_the_evader_captures_and_terminates(mode):
    s = score_events([ev(CATCH)], REWARDS, mode)
    assert s.captured and s.terminated
    assert s.reward == REWARDS.step + REWARDS.capture
    assert s.collisions == 0


@pytest.mark.parametrize(
    ("mode", "penalised", "terminates"),
    [("off", False, False), ("terminate", True, True), ("penalize", True, False)],
)
def test_collision_modes(mode, penalised, terminates):
    s = score_events([ev(P01)], REWARDS, mode)
    assert s.collisions == 1  # counted in every mode, as in grid mode
    assert s.reward == REWARDS.step + (REWARDS.collision if penalised else 0.0)
    assert s.terminated is terminates
    assert not s.captured


def test_each_pair_counts_once_per_step():
    events = [ev(P01), ev(P02), ev(P12), ev((PURSUER_PURSUER, "pursuer_1", "pursuer_0"))]
    s = score_events(events, REWARDS, "penalize")
    assert s.collisions == 3
    assert s.reward == REWARDS.step + 3 * REWARDS.collision


def test_capture_and_collision_in_one_step_both_count():
    s = score_events([ev(P01), ev(CATCH)], REWARDS, "penalize")
    assert s.captured and s.terminated and s.collisions == 1
    assert s.reward == REWARDS.step + REWARDS.collision + REWARDS.capture


def test_wall_contacts_are_recorded_and_rewarded_for_pursuers_only():
    s = score_events([ev(WALL0), ev(WALL_E)], REWARDS, "penalize")
    assert s.wall_contacts == 1 and s.collisions == 0 and not s.terminated
    assert s.reward == REWARDS.step + REWARDS.wall


def test_wall_contacts_cost_nothing_by_default():
    s = score_events([ev(WALL0)], Rewards(), "terminate")
    assert s.reward == Rewards().step and s.wall_contacts == 1 and not s.terminated


def test_unknown_kind_and_mode_are_errors():
    with pytest.raises(ValueError, match="bump"):
        score_events([("bump", "pursuer_0", "pursuer_1", 1)], REWARDS, "off")
    with pytest.raises(ValueError, match="loud"):
        score_events([], REWARDS, "loud")


# --------------------------------------------------------------------------- ContactTracker


def run(tracker: ContactTracker, steps: list[list[tuple[str, tuple]]]) -> list[list]:
    """Feed ``steps`` (per step: ("b"|"s", pair) callbacks) and collect each step's events."""
    out = []
    for k, calls in enumerate(steps, start=1):
        for what, pair in calls:
            (tracker.begin if what == "b" else tracker.separate)(pair)
        out.append(tracker.end_step(k))
    return out


def flat(events: list[list]) -> list:
    return [e for step in events for e in step]


def test_a_begin_is_one_event_at_its_step():
    assert run(ContactTracker(), [[], [("b", P01)], []]) == [[], [ev(P01, 2)], []]


def test_a_lasting_contact_is_one_event():
    steps = [[("b", P01)]] + [[] for _ in range(10)]
    events = run(ContactTracker(), steps)
    assert flat(events) == [ev(P01, 1)]


def test_flicker_within_and_across_steps_is_one_contact():
    flicker = [("s", P01), ("b", P01)] * 3
    steps = [[("b", P01)], flicker, [("s", P01)], [("b", P01), *flicker], flicker]
    assert flat(run(ContactTracker(), steps)) == [ev(P01, 1)]


def test_touching_again_after_a_free_step_is_a_new_contact():
    steps = [[("b", P01)], [("s", P01)], [], [("b", P01)]]
    assert flat(run(ContactTracker(), steps)) == [ev(P01, 1), ev(P01, 4)]


def test_a_separation_shorter_than_a_step_is_not():
    # Separated during step 2, touching again in step 3: step 2 was not free of contact.
    steps = [[("b", P01)], [("s", P01)], [("b", P01)]]
    assert flat(run(ContactTracker(), steps)) == [ev(P01, 1)]


def test_a_brief_touch_inside_one_step_counts():
    steps = [[("b", P01), ("s", P01)], [], [], [("b", P01), ("s", P01)]]
    assert flat(run(ContactTracker(), steps)) == [ev(P01, 1), ev(P01, 4)]


def test_a_pair_touching_through_two_shapes_stays_touching_until_both_separate():
    # A pursuer sliding into a corner touches two wall boxes, then leaves one of them.
    tracker = ContactTracker()
    run(tracker, [[("b", WALL0)], [("b", WALL0)], [("s", WALL0)]])
    assert tracker.touching() == {WALL0}
    events = run(tracker, [[], [("s", WALL0)], [], [("b", WALL0)]])
    assert flat(events) == [ev(WALL0, 4)]  # free in the 3rd of these steps, new in the 4th


def test_pairs_are_independent_and_events_sorted():
    steps = [[("b", WALL0), ("b", P12), ("b", CATCH), ("b", P01)]]
    events = run(ContactTracker(), steps)[0]
    assert events == [ev(P01), ev(P12), ev(CATCH), ev(WALL0)]
