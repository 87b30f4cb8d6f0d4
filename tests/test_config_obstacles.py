"""The scenario keys of issue 46 in the config: ``[[obstacles]]``, ``physics.drive`` and the
range sensor's keys; checked where they are read, named in every error, and left out of
what a scenario that does not use them writes."""

from __future__ import annotations

import pytest

from a2cm_phys.config import ConfigError, Scenario, build, load_scenario, scenario_names, to_dict

WALLS = [
    {"x": 1.5, "y": 2.5, "width": 1.0, "height": 1.0},
    {"x": 3.5, "y": 2.5, "width": 1.0, "height": 1.0},
]


@pytest.mark.parametrize("name", scenario_names())
def test_a_scenario_without_the_new_keys_writes_what_it_wrote_before(name):
    data = to_dict(load_scenario(name))
    uses = load_scenario(name)
    if not uses.obstacles:
        assert "obstacles" not in data
    if uses.physics.drive == "holonomic":
        assert {"drive", "max_turn_rate"}.isdisjoint(data["physics"])
    if not uses.sensing.rays:
        assert {"rays", "range", "occlusion"}.isdisjoint(data["sensing"])
    assert build(Scenario, data, name) == uses


def test_obstacles_block_the_cells_whose_centres_they_cover_and_round_trip():
    sc = load_scenario(
        "grid_collision",
        {"obstacles": [*WALLS, {"x": 3.6, "y": 3.5, "shape": "circle", "radius": 0.4}]},
    )
    blocked = {(int(c % 5), int(c // 5)) for c in sc.blocked_cells().nonzero()[0]}
    assert blocked == {(1, 2), (3, 2), (3, 3)}  # the circle covers the centre (3.5, 3.5) only
    assert build(Scenario, to_dict(sc), "again") == sc
    assert load_scenario("grid_collision").blocked_cells().sum() == 0


@pytest.mark.parametrize(
    ("obstacle", "key", "says"),
    [
        ({"y": 1.5, "width": 1.0, "height": 1.0}, "obstacles[0].x", "missing"),
        ({"x": 1.5, "y": 1.5, "width": 1.0}, "obstacles[0].height", "needs width and height"),
        (
            {"x": 1.5, "y": 1.5, "shape": "circle", "radius": 0.4, "width": 1.0},
            "obstacles[0].width",
            "takes radius",
        ),
        ({"x": 1.5, "y": 1.5, "shape": "circle", "radius": -1.0}, "obstacles[0].radius", "> 0"),
        ({"x": 1.5, "y": 1.5, "shape": "star", "radius": 1.0}, "obstacles[0].shape", "one of"),
        ({"x": 4.8, "y": 1.5, "width": 1.0, "height": 1.0}, "obstacles[0]", "outside"),
        (
            {"x": 2.5, "y": 2.5, "width": 1.0, "height": 1.0},
            "obstacles[0]",
            "fixed start of cell (2, 2)",
        ),
        (
            {"x": 2.0, "y": 1.0, "width": 0.5, "height": 0.5},
            "obstacles[0]",
            "covers no cell centre",
        ),
        ({"x": 2.5, "y": 1.5, "width": 5.0, "height": 1.0}, "obstacles", "split the free cells"),
        (
            {"x": 1.5, "y": 1.5, "width": 1.0, "height": 1.0, "colour": "red"},
            "obstacles[0].colour",
            "unknown key",
        ),
    ],
)
def test_a_bad_obstacle_is_named_with_its_key(obstacle, key, says):
    with pytest.raises(ConfigError) as err:
        load_scenario("grid_collision", {"obstacles": [obstacle]})
    assert f"key '{key}'" in str(err.value) and says in str(err.value)


def test_physics_refuses_an_obstacle_a_start_body_touches_and_grid_refuses_physics_keys():
    with pytest.raises(ConfigError, match=r"obstacles\[0\].*fixed start of cell \(0, 0\)"):
        load_scenario(
            "phys_cont", {"obstacles": [{"x": 0.9, "y": 0.9, "shape": "circle", "radius": 0.2}]}
        )
    # the same circle clear of the box's corner (0.8, 0.8) is fine in physics
    load_scenario(
        "phys_cont", {"obstacles": [{"x": 1.2, "y": 1.2, "shape": "circle", "radius": 0.2}]}
    )
    # a random start has no fixed start to cover
    load_scenario("grid_random", {"obstacles": [{"x": 0.5, "y": 0.5, "width": 1.0, "height": 1.0}]})
    for key, value in (
        ("physics.drive", "differential"),
        ("sensing.rays", 8),
        ("rewards.obstacle", -1.0),
    ):
        with pytest.raises(ConfigError, match=rf"key '{key}'.*needs mode = 'physics'"):
            load_scenario("grid", {key: value, "sensing.radius": 1})
    with pytest.raises(ConfigError, match=r"key 'sensing.rays'.*needs sensing.radius"):
        load_scenario("phys_cont", {"sensing.rays": 8})
    with pytest.raises(ConfigError, match=r"key 'obstacles'.*list of tables"):
        load_scenario("grid", {"obstacles": {"x": 1.0}})
