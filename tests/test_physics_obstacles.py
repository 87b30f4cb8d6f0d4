"""Static obstacles in physics mode: a contact with one is a wall contact that is also an
obstacle contact (counted, priced, logged as ``agent_obstacle``), bodies never pass
through them, the start-overlap test, placements, pictures and replays."""

from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np
import pymunk
import pytest
from test_record import check_messages, make_log

from a2cm_phys import make_env
from a2cm_phys.analysis.baselines import detour_targets, pursuit_actions, steer
from a2cm_phys.commands.replay import main as replay
from a2cm_phys.config import InvalidKey, load_scenario
from a2cm_phys.envs.contacts import (
    AGENT_OBSTACLE,
    AGENT_WALL,
    count_events,
    count_obstacle_contacts,
    score_events,
)
from a2cm_phys.envs.obstacles import (
    check_thickness,
    clear_of_obstacles,
    obstacle_overlaps,
    substep_reach,
)
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.render import WALL_COLOUR, render_rgb
from a2cm_phys.envs.starts import random_starts
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.envs.world import CollisionType, World, pair_table
from a2cm_phys.record import read_run
from a2cm_phys.record.schemas import schemas_for

BOXES = [  # grid_obstacles' two walls beside the centre
    {"shape": "box", "x": 1.5, "y": 2.5, "width": 1.0, "height": 1.0},
    {"shape": "box", "x": 3.5, "y": 2.5, "width": 1.0, "height": 1.0},
]
ROOMS = load_scenario("phys_diff10_obstacles")
PRICED = {"rewards.wall": -2.0, "rewards.obstacle": -5.0, "collisions.mode": "off"}
IDLE = {"pursuer_1": (4.5, 0.5), "pursuer_2": (0.5, 4.5), "evader": (4.5, 4.5)}
SLOP = 0.011  # m: the solver's allowed overlap (world.COLLISION_SLOP), and rounding


def scene(name: str, overrides: dict, placed: dict) -> PhysicsCore:
    sc = load_scenario(name, {"evader": "static", **PRICED, **overrides})
    core = PhysicsCore(sc, 1)
    core.reset(np.array([0]), np.array([0], dtype=np.uint64), [placed])
    return core


@pytest.mark.parametrize(
    ("name", "overrides", "forward"),
    [
        ("phys_cont", {"obstacles": BOXES}, (1.0, 0.0)),  # holonomic: velocity +x
        ("phys_diff_obstacles", {}, (1.0, 0.0)),  # differential: forward, heading 0 (+x)
        ("phys", {"obstacles": BOXES, "actions": 5}, 3),  # discrete: right
    ],
)
def test_driving_into_an_obstacle_stops_with_one_wall_and_one_obstacle_contact(
    name, overrides, forward
):
    core = scene(name, overrides, {"pursuer_0": (0.5, 2.5), **IDLE})
    sc = core.scenario
    idle = 4 if not sc.continuous else (0.0, 0.0)
    actions = np.array([[forward, idle, idle]])
    steps = [core.step(actions) for _ in range(3 if not sc.continuous else 30)]
    k = next(k for k, out in enumerate(steps, 1) if out.events[0])
    events = [ev for out in steps for ev in out.events[0]]
    assert events == [(AGENT_OBSTACLE, "pursuer_0", "obstacle", k)]
    hit = steps[k - 1]
    assert hit.wall_contacts.tolist() == [1] and hit.obstacle_contacts.tolist() == [1]
    assert hit.reward.tolist() == [sc.rewards.step + sc.rewards.wall + sc.rewards.obstacle]
    others = [o for o in steps if o is not hit]  # a lasting push is one contact, at its start
    assert all(o.wall_contacts[0] == 0 and o.obstacle_contacts[0] == 0 for o in others)
    assert all(o.reward[0] == sc.rewards.step for o in others)
    x = core.positions()[0, 0, 0]  # stopped at the obstacle's face, x = 1, less half a box
    assert abs(x - (1.0 - sc.physics.box_side / 2)) <= SLOP
    np.testing.assert_allclose(core.velocities()[0, 0], 0.0, atol=1e-9)


def test_the_arena_wall_stays_a_plain_wall_contact():
    away = {**IDLE, "pursuer_1": (4.5, 3.5)}  # not in the way along the bottom wall
    core = scene("phys_diff_obstacles", {}, {"pursuer_0": (2.5, 0.5), **away})
    core.step(np.array([[[0.0, -1.0], [0.0, 0.0], [0.0, 0.0]]]))  # turn: the corners sweep
    outs = [core.step(np.array([[[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]]])) for _ in range(20)]
    events = [ev for out in outs for ev in out.events[0]]
    assert [ev[:3] for ev in events] == [(AGENT_WALL, "pursuer_0", "wall")]
    assert sum(int(o.obstacle_contacts[0]) for o in outs) == 0
    assert sum(o.reward[0] for o in outs) == 20 * -1000.0 - 2.0


def test_outcomes_have_obstacle_contacts_only_with_obstacles():
    plain = PhysicsCore(load_scenario("phys_cont"), 2)
    plain.reset(np.arange(2), np.arange(2, dtype=np.uint64))
    assert plain.step(np.zeros((2, 3, 2))).obstacle_contacts is None
    blocked = PhysicsCore(load_scenario("phys_diff_obstacles"), 2)
    blocked.reset(np.arange(2), np.arange(2, dtype=np.uint64))
    out = blocked.step(np.zeros((2, 3, 2)))
    assert out.obstacle_contacts.dtype == np.int64 and out.obstacle_contacts.shape == (2,)


def test_counting_obstacle_contacts():
    """An obstacle contact is also a wall contact: a pursuer touching the wall and an
    obstacle in one step is one wall contact and one obstacle contact; the evader's cost
    nothing."""
    events = [
        (AGENT_WALL, "pursuer_0", "wall", 3),
        (AGENT_OBSTACLE, "pursuer_0", "obstacle", 3),
        (AGENT_OBSTACLE, "pursuer_2", "obstacle", 3),
        (AGENT_OBSTACLE, "evader", "obstacle", 3),
    ]
    assert count_events(events) == (False, 0, 2)
    assert count_obstacle_contacts(events) == 2
    rewards = load_scenario("phys_cont", PRICED).rewards
    score = score_events(iter(events), rewards, "off")
    assert (score.wall_contacts, score.obstacle_contacts) == (2, 2)
    assert score.reward == -1.0 + 2 * -2.0 + 2 * -5.0


def test_obstacles_are_static_shapes_of_every_rebuilt_space():
    sc = load_scenario("phys_diff10_obstacles")
    world = World(sc, np.array([(0.5, 0.5), (9.5, 0.5), (0.5, 9.5), (5.5, 5.5)]), pair_table(sc))
    for _ in range(2):
        blocks = [s for s in world.space.shapes if s.collision_type == CollisionType.OBSTACLE]
        assert len(blocks) == len(sc.obstacles) and all(s.body is world._static for s in blocks)
        bb = sorted((round(s.bb.left, 9), round(s.bb.bottom, 9)) for s in blocks)
        assert bb == sorted((o.x - o.width / 2, o.y - o.height / 2) for o in sc.obstacles)
        world.rebuild(np.array([(0.5, 0.5), (9.5, 0.5), (0.5, 9.5), (5.5, 5.5)]))
    table = pair_table(sc)
    n = sc.pursuers
    assert table[0][n + 2] == (AGENT_OBSTACLE, "pursuer_0", "obstacle")
    assert table[n][n + 2] == (AGENT_OBSTACLE, "evader", "obstacle")


def deepest(core: PhysicsCore) -> float:
    """The deepest overlap (m, negative) of any agent with a static shape (wall, obstacle)."""
    depth = 0.0
    for world in core._worlds:
        for shape in world._shapes:
            for hit in world.space.shape_query(shape):
                if hit.shape.body.body_type == pymunk.Body.STATIC:
                    depth = min(depth, *(p.distance for p in hit.contact_point_set.points))
    return depth


def inside(obstacle, xy: np.ndarray) -> np.ndarray:
    """Whether points ``(..., 2)`` lie inside a box obstacle."""
    dx, dy = np.abs(xy[..., 0] - obstacle.x), np.abs(xy[..., 1] - obstacle.y)
    return (dx < obstacle.width / 2) & (dy < obstacle.height / 2)


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        ("phys_diff10_obstacles", {"start": "fixed", "evader": "flee"}),
        ("phys_cont10", {"obstacles": [asdict(o) for o in ROOMS.obstacles]}),
    ],
)
def test_bodies_never_pass_through_obstacles(name, overrides):
    """Everyone drives flat out (turning hard, with differential drive) at points across
    the walls and through the doorways, pushing one another into them: no body sinks into
    a wall or an obstacle deeper than one substep's reach (detection is discrete) and the
    solver's slop, and no centre is ever inside an obstacle."""
    sc = load_scenario(name, overrides)
    b, n = 8, sc.pursuers
    core = PhysicsCore(sc, b)
    core.reset(np.arange(b), np.arange(b, dtype=np.uint64))
    rng = np.random.default_rng(0)
    worst = 0.0
    for k in range(600):
        if k % 50 == 0:
            targets = rng.uniform(0, sc.size, (b, n, 2))
        gap = targets - core.positions()[:, :n]
        unit = gap / np.maximum(np.linalg.norm(gap, axis=-1, keepdims=True), 1e-9)
        if sc.differential:
            actions = steer(sc, unit, core.headings()).astype(np.float64)
            actions[..., 0] = 1.0  # full speed, also while turning
            actions[..., 1] = np.clip(3 * actions[..., 1], -1, 1)  # hard turns
        else:
            actions = unit
        core.step(actions)
        worst = min(worst, deepest(core))
        for obstacle in sc.obstacles:
            assert not inside(obstacle, core.positions()).any()
    assert -(substep_reach(sc) + SLOP) <= worst < -0.001  # and bodies did press on walls


def test_the_start_overlap_test_is_exact_for_boxes_and_discs():
    circle = {"shape": "circle", "x": 2.5, "y": 4.0, "radius": 0.4}
    sc = load_scenario("phys_diff_obstacles", {"obstacles": [*BOXES, circle]})
    half, r, e = sc.physics.box_side / 2, sc.physics.evader_radius, 1e-6
    far = np.array([(0.5, 0.5), (4.5, 0.5), (0.5, 4.5), (2.5, 1.0)])

    def start(i, xy):
        out = far.copy()
        out[i] = xy
        return out

    no, p0, p2, ev = (
        [False] * 4,
        [True] + [False] * 3,
        [False] * 2 + [True, False],
        [False] * 3 + [True],
    )
    cases = {
        "pursuer touching a box": (start(0, (1.0 - half, 2.5)), no),
        "pursuer into a box": (start(0, (1.0 - half + e, 2.5)), p0),
        "pursuer by a box's corner, diagonally": (start(1, (1.0 - half - e, 2.0 - half - e)), no),
        "evader off a box's rounded corner": (start(3, (2.0 + 0.22, 2.0 - 0.22)), no),
        "evader at a box's side": (start(3, (2.0 + r - e, 2.5)), ev),
        "pursuer off a circle, diagonally": (start(2, (2.5 - half - 0.3, 4.0 - half - 0.3)), no),
        "pursuer into a circle": (start(2, (2.5 - half - 0.3, 4.0)), p2),
        "evader into a circle": (start(3, (2.5, 4.0 - 0.4 - r + e)), ev),
    }
    for what, (xy, hit) in cases.items():
        assert obstacle_overlaps(sc, xy).tolist() == hit, what
    batch = np.stack([xy for xy, _ in cases.values()])
    want = [not any(hit) for _, hit in cases.values()]
    assert clear_of_obstacles(sc, batch).tolist() == want
    assert clear_of_obstacles(load_scenario("phys_diff"), batch).all()  # no obstacles


def test_obstacles_a_body_could_cross_in_one_substep_are_refused():
    thin = {"shape": "box", "x": 1.5, "y": 2.5, "width": 0.2, "height": 2.0}
    with pytest.raises(InvalidKey, match=r"obstacles\[0\] is 0.2 m thick.*0.117 m"):
        PhysicsCore(load_scenario("phys_diff", {"obstacles": [thin]}))
    holonomic = load_scenario("phys_cont", {"obstacles": [thin]})  # 0.05 m a substep
    check_thickness(holonomic)
    assert substep_reach(holonomic) == pytest.approx(0.05)
    finer = load_scenario("phys_diff", {"obstacles": [thin], "physics.substeps": 6})
    check_thickness(finer)


def test_placing_a_body_in_an_obstacle_is_refused():
    env = make_env("phys_diff_obstacles")
    with pytest.raises(ValueError, match=r"positions\['evader'\].*into an obstacle"):
        env.reset(seed=0, options={"positions": {"evader": (1.5, 2.0)}})
    env.reset(seed=0, options={"positions": {"evader": (1.5, 1.7)}})  # touching is fine


def test_frames_draw_the_obstacles():
    sc = load_scenario("phys_diff_obstacles")
    positions = np.array([(0.5, 0.5), (4.5, 0.5), (0.5, 4.5), (2.5, 2.5)])
    frame = render_rgb(sc, positions, headings=np.array([(0.0, 1.0), (1.0, 0.0), (1.0, 0.0)]))
    plain = render_rgb(load_scenario("phys_diff"), positions)
    wall = np.array([int(WALL_COLOUR[i : i + 2], 16) for i in (1, 3, 5)])
    is_wall = (np.abs(frame.astype(int) - wall).max(-1) <= 2).sum()
    was_wall = (np.abs(plain.astype(int) - wall).max(-1) <= 2).sum()
    arena = (frame.shape[1] * 0.9 / 5) ** 2  # pixels of one square metre, about
    assert is_wall - was_wall > 1.5 * arena  # two 1 x 1 boxes (less what the legend adds)


def test_logs_carry_headings_and_replay_verifies_them(tmp_path):
    """A differential-drive log holds each state's headings (schema-valid), pictures and
    scenes turn the pursuers by them, and ``replay --verify`` re-simulates them bit for
    bit with the obstacles' contacts."""
    path = tmp_path / "episodes.mcap"
    make_log(path, scenario="phys_diff_obstacles", envs=2, steps=120, scene_every=3)
    seen = check_messages(path, schemas_for(load_scenario("phys_diff_obstacles")))
    scenes = [msg for topic, msgs in seen.items() if topic.startswith("/scene") for _, msg in msgs]
    cubes = [e.cubes[0] for msg in scenes for e in msg.entities if e.id == "pursuer_0"]
    assert cubes and any(abs(cube.pose.orientation.z) > 0.01 for cube in cubes)  # turned
    arena = next(e for e in scenes[0].entities if e.id == "arena")
    assert len(arena.cubes) == 5 + 2  # floor, four walls and the two obstacles
    log = read_run(path)
    assert log.n_episodes > 0
    traj = log.trajectory(0)
    assert traj.headings.shape == (traj.length + 1, 3, 2)
    np.testing.assert_array_equal(traj.headings[0], np.tile([1.0, 0.0], (3, 1)))
    np.testing.assert_allclose(np.linalg.norm(traj.headings, axis=-1), 1.0)
    assert np.abs(traj.headings[-1, :, 1]).max() > 0.01  # they turned
    assert replay([str(tmp_path), "--verify"]) == 0
    assert load_scenario("phys_cont").differential is False
    plain = tmp_path / "plain"
    plain.mkdir()
    make_log(plain / "episodes.mcap", scenario="phys_cont", envs=4, steps=400)
    plain_log = read_run(plain / "episodes.mcap")
    assert plain_log.n_episodes and plain_log.trajectory(0).headings is None  # as before


def test_pursuit_heads_for_the_next_cell_of_a_shortest_path_around_obstacles():
    sc = load_scenario("grid_obstacles", {"evader": "static"})
    # pursuer 0 left of the left block, pursuer 1 on the evader's row behind the right
    # block, pursuer 2 beside the evader; the evader in the centre (2, 2)
    cells = np.array([[(0, 2), (4, 2), (2, 3), (2, 2)]], dtype=np.float64)
    targets = detour_targets(sc, cells)
    np.testing.assert_array_equal(targets[0, 0], (0, 3))  # around the block: up first
    np.testing.assert_array_equal(targets[0, 1], (4, 3))
    np.testing.assert_array_equal(targets[0, 2], (2, 2))  # next to it: straight at it
    assert pursuit_actions(sc, cells).tolist() == [[0, 0, 1]]  # up, up, down
    bare = replace(sc, obstacles=())
    assert pursuit_actions(bare, cells).tolist() == [[3, 2, 1]]  # straight: into the blocks
    np.testing.assert_array_equal(pursuit_actions(sc, cells[None])[0], [[0, 0, 1]])
    phys = load_scenario("phys_diff_obstacles")
    metres = cells + 0.5
    np.testing.assert_array_equal(detour_targets(phys, metres)[0, :2], [(0.5, 3.5), (4.5, 3.5)])


def test_pursuit_gets_round_the_walls_where_heading_straight_sticks():
    """Against a static evader in the rooms of ``phys_diff10_obstacles``, heading straight
    for it leaves pursuers pressed against walls; the detour catches it far more often."""
    sc = load_scenario("phys_diff10_obstacles", {"evader": "static"})
    bare = replace(sc, obstacles=())  # the straight-line pursuit, in the same rooms
    captures = []
    for rule in (bare, sc):
        env = VectorEnv(sc, 8)
        env.reset(0)
        caught = 0
        for _ in range(500):
            step = env.step(pursuit_actions(rule, env.core.positions(), env.core.headings()))
            caught += int(step.outcome.captured.sum())
        captures.append(caught)
    assert captures[1] >= 2 * max(captures[0], 1)


@pytest.mark.parametrize("name", ["phys_diff_obstacles", "phys_diff10_obstacles"])
def test_random_starts_keep_every_body_clear_of_the_obstacles(name):
    scenario = load_scenario(name)
    xy = random_starts(scenario, np.arange(5000, dtype=np.uint64))
    assert not obstacle_overlaps(scenario, xy).any()
    # without the obstacle test some of the same draws would overlap one
    bare = random_starts(replace(scenario, obstacles=()), np.arange(5000, dtype=np.uint64))
    assert obstacle_overlaps(scenario, bare).any()
