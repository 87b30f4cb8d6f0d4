"""Range sensing in closed form (:mod:`a2cm_phys.envs.rays`) against pymunk's own segment
queries on the same shapes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pymunk
import pytest
from foxglove.messages import SceneUpdate
from test_record import decode_scene

from a2cm_phys.config import Obstacle, load_scenario
from a2cm_phys.envs.rays import cast_rays, ray_angles, visible
from a2cm_phys.envs.render import render_rgb
from a2cm_phys.envs.sensing import agent_slice, ray_segments, sensed
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.record.scene import scene_update

SIZE, SIDE, RADIUS, REACH = 5.0, 0.6, 0.3, 3.0
OBSTACLES = (
    Obstacle(x=1.5, y=2.5, width=1.0, height=1.0),
    Obstacle(x=3.7, y=3.6, shape="circle", radius=0.45),
    Obstacle(x=3.5, y=1.0, width=0.2, height=1.6),
)


def _space(xy: np.ndarray, headings: np.ndarray | None) -> tuple[pymunk.Space, list]:
    """A pymunk space with the arena's walls outside [0, SIZE]², the obstacles, the
    pursuers' boxes and the evader's disc; every pursuer's box in a filter group of its own."""
    space = pymunk.Space()
    static = space.static_body
    t = 1.0
    for x0, y0, x1, y1 in (
        (-t, -t, 0.0, SIZE + t),
        (SIZE, -t, SIZE + t, SIZE + t),
        (0.0, -t, SIZE, 0.0),
        (0.0, SIZE, SIZE, SIZE + t),
    ):
        space.add(pymunk.Poly(static, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]))
    for o in OBSTACLES:
        if o.shape == "box":
            hx, hy = o.half_extents
            pts = [
                (o.x - hx, o.y - hy),
                (o.x + hx, o.y - hy),
                (o.x + hx, o.y + hy),
                (o.x - hx, o.y + hy),
            ]
            space.add(pymunk.Poly(static, pts))
        else:
            space.add(pymunk.Circle(static, o.radius, (o.x, o.y)))
    filters = []
    n = len(xy) - 1
    for i in range(n + 1):
        filters.append(pymunk.ShapeFilter(group=i + 1))
        body = pymunk.Body(1.0, 1.0)
        body.position = tuple(xy[i])
        if i < n:
            body.angle = 0.0 if headings is None else float(headings[i])
            shape = pymunk.Poly.create_box(body, (SIDE, SIDE), radius=0.0)
        else:
            shape = pymunk.Circle(body, RADIUS)
        shape.filter = filters[i]
        space.add(body, shape)
    return space, filters


def _layouts(rng: np.random.Generator, games: int, n: int = 3) -> np.ndarray:
    """Random centres (B, N + 1, 2) of bodies clear of each other, the walls and obstacles."""
    out = []
    while len(out) < games:
        xy = rng.uniform(0.5, SIZE - 0.5, size=(n + 1, 2))
        apart = all(np.hypot(*(xy[i] - xy[j])) > 2 * SIDE for i in range(n + 1) for j in range(i))
        clear = all(not o.covers(xy[:, 0], xy[:, 1], margin=SIDE).any() for o in OBSTACLES)
        if apart and clear:
            out.append(xy)
    return np.stack(out)


@pytest.mark.parametrize("turned", [False, True])
def test_rays_equal_pymunk_segment_queries(turned):
    rng = np.random.default_rng(7 + turned)
    xy = _layouts(rng, 12)
    headings = rng.uniform(-np.pi, np.pi, size=(12, 3)) if turned else None
    rays = 16
    got = cast_rays(xy, headings, rays, REACH, SIZE, SIDE, RADIUS, OBSTACLES)
    assert got.shape == (12, 4, rays)
    hits = 0
    for g in range(12):
        space, filters = _space(xy[g], None if headings is None else headings[g])
        turns = np.zeros(4) if headings is None else np.append(headings[g], 0.0)
        angles = ray_angles(rays, turns, (4,))
        for i in range(4):
            for r in range(rays):
                start = tuple(xy[g, i])
                end = tuple(
                    xy[g, i] + REACH * np.array([np.cos(angles[i, r]), np.sin(angles[i, r])])
                )
                query = space.segment_query_first(start, end, 0.0, filters[i])
                want = REACH if query is None else query.alpha * REACH
                hits += query is not None
                assert got[g, i, r] == pytest.approx(want, abs=1e-6), (g, i, r)
    assert hits > 12 * 4 * rays // 4  # the layouts put shapes in the rays' way


def test_readings_stop_at_the_range_and_never_see_the_own_box():
    xy = np.array([[[2.5, 2.5], [0.5, 0.5], [4.5, 0.5], [4.5, 4.5]]])
    got = cast_rays(xy, None, 4, 10.0, SIZE, SIDE, RADIUS)
    # from the centre: +x, +y, -x, -y all reach the walls 2.5 m away (no box in the way)
    np.testing.assert_allclose(got[0, 0], [2.5, 2.5, 2.5, 2.5], atol=1e-12)
    short = cast_rays(xy, None, 4, 1.0, SIZE, SIDE, RADIUS)
    assert short.max() <= 1.0


def test_obstacles_hide_bodies_behind_them():
    xy = np.array([[[0.5, 2.5], [2.5, 2.5], [1.5, 4.5]]])  # the box at (1.5, 2.5) between 0 and 1
    seen = visible(xy, OBSTACLES)
    assert seen.shape == (1, 3, 3)
    assert not seen[0, 0, 1] and not seen[0, 1, 0]
    assert seen[0, 0, 2] and seen[0, 2, 0] and seen[0].diagonal().all()
    assert visible(xy, ()).all()


def _env_with_rays(name: str, **overrides):
    scenario = load_scenario(name, {"sensing.rays": 6, "sensing.range": 2.5, **overrides})
    return scenario, VectorEnv(scenario, num_envs=3)


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        ("phys_cont_pomdp", {}),
        ("phys_diff_obstacles", {"sensing.radius": 1.5, "sensing.occlusion": True}),
    ],
)
def test_every_agents_observation_ends_with_its_range_readings(name, overrides):
    scenario, env = _env_with_rays(name, **overrides)
    env.reset(3)
    rng = np.random.default_rng(0)
    for _ in range(15):
        step = env.step(rng.uniform(-1, 1, size=(3, 3, 2)).astype(np.float32))
        headings = None
        if step.headings is not None:
            headings = np.arctan2(step.headings[..., 1], step.headings[..., 0])
        want = (
            cast_rays(
                env.core.positions(), headings, 6, 2.5, scenario.size, 0.6, 0.3, scenario.obstacles
            )
            / 2.5
        )
        for agent in range(4):
            got = step.obs[:, agent_slice(scenario, agent)][:, -6:]
            np.testing.assert_allclose(got, want[:, agent], atol=1e-6)
    assert scenario.obs_dim == scenario.body_features * 4 + 3 + 6
    env.close()


def test_occlusion_hides_a_body_behind_an_obstacle_from_radius_sensing():
    base = {"sensing.radius": 3.0}
    xy = np.array([[[0.5, 2.5], [2.5, 2.5], [0.5, 0.5], [4.5, 4.5]]])  # box at (1.5, 2.5)
    plain = sensed(load_scenario("phys_diff_obstacles", base), xy)
    hidden = sensed(load_scenario("phys_diff_obstacles", {**base, "sensing.occlusion": True}), xy)
    assert plain[0, 0, 1] and plain[0, 1, 0]
    assert not hidden[0, 0, 1] and not hidden[0, 1, 0]
    assert (hidden <= plain).all() and hidden[0, 0, 2]


def decoded(scene: SceneUpdate) -> object:
    """A scene as Foxglove reads it: its protobuf bytes decoded with the SDK's schema."""
    schema = SimpleNamespace(
        id=1, name="foxglove.SceneUpdate", encoding="protobuf", data=SceneUpdate.get_schema().data
    )
    return decode_scene(schema, SimpleNamespace(message_encoding="protobuf"), scene.encode())


def test_pictures_and_scenes_draw_each_pursuers_rays_where_they_stop():
    """The rays drawn (Foxglove scene and GIF frame) end where the sensor's readings say,
    turned by the headings; a scenario without rays draws none."""
    sc = load_scenario("phys_diff_obstacles", {"sensing": {"radius": 2.0, "rays": 6}})
    env = VectorEnv(sc, 1)
    env.reset(5)
    rng = np.random.default_rng(1)
    for _ in range(12):
        env.step(rng.uniform(-1, 1, (1, 3, 2)).astype(np.float32), validate=False)
    positions, headings = env.core.positions()[0], env.core.headings()[0]
    angle = np.arctan2(headings[:, 1], headings[:, 0])
    reach = cast_rays(positions[None], angle[None], 6, sc.sensing.range, sc.size, 0.6, 0.3,
                      sc.obstacles)[0, :3]  # fmt: skip
    starts, ends = ray_segments(sc, positions, headings)
    np.testing.assert_allclose(np.linalg.norm(ends - starts, axis=-1), reach, atol=1e-12)
    first = (ends - starts)[:, 0] / reach[:, :1]  # ray 0 points along the heading
    np.testing.assert_allclose(first, headings, atol=1e-12)
    masks = np.asarray(sensed(sc, positions[None])[0])
    scene = decoded(scene_update(sc, positions, 0, sensing=masks, headings=headings))
    sensing = next(e for e in scene.entities if e.id == "sensing")
    rays = [line for line in sensing.lines if len(line.points) == 2 * 6]
    assert len(rays) == 3
    for i, line in enumerate(rays):
        drawn = np.array([(p.x, p.y) for p in line.points]).reshape(6, 2, 2)
        np.testing.assert_allclose(drawn[:, 0], starts[i], atol=1e-12)
        np.testing.assert_allclose(drawn[:, 1], ends[i], atol=1e-12)
    for i in range(3):  # each pursuer's heading as an arrow in its colour
        arrows = next(e for e in scene.entities if e.id == f"pursuer_{i}").arrows
        q = arrows[-1].pose.orientation
        np.testing.assert_allclose(2 * np.arctan2(q.z, q.w), angle[i], atol=1e-9)
    plain = load_scenario("phys_diff_obstacles", {"sensing": {"radius": 2.0}})
    scene = decoded(scene_update(plain, positions, 0, sensing=masks, headings=headings))
    lines = next(e for e in scene.entities if e.id == "sensing").lines
    assert all(len(line.points) != 12 for line in lines)
    drawn = render_rgb(sc, positions, headings=headings)
    bare = render_rgb(plain, positions, headings=headings)
    assert drawn.shape == bare.shape and (drawn != bare).any(-1).sum() > 500
