"""The live view (``train --live``) and ``replay --serve``: the Foxglove SDK's WebSocket
server, watched by a real WebSocket client (``websockets``) speaking Foxglove's protocol
(offered as ``foxglove.websocket.v1`` and ``foxglove.sdk.v1``, its new name, which the relay
in front of the SDK picks; either alone is accepted); scenes decode with the schema the
server advertises, curve points are JSON."""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from test_record import make_log

from a2cm_phys.base.errors import UserError
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.record import read_run
from a2cm_phys.record.sdk import address
from a2cm_phys.record.serve import serve_episodes
from a2cm_phys.training import live as live_module
from a2cm_phys.training.live import LIVE_PLOT_EVERY, LiveView, live_address

websockets = pytest.importorskip("websockets")

PROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


class Received:
    """What a client got: the advertised channels by topic and the messages by topic."""

    def __init__(self) -> None:
        self.channels: dict[str, dict] = {}
        self.messages: dict[str, list[tuple[int, bytes]]] = {}
        self.protocol = ""

    def decode_scene(self, data: bytes):
        """A ``/scene`` message decoded with the schema the server advertised."""
        c = self.channels["/scene"]
        assert c["encoding"] == "protobuf" and c["schemaName"] == "foxglove.SceneUpdate"
        assert c["schemaEncoding"] == "protobuf"
        schema = Schema(
            id=1, name=c["schemaName"], encoding="protobuf", data=base64.b64decode(c["schema"])
        )
        return DecoderFactory().decoder_for("protobuf", schema)(data)

    def json(self, topic: str) -> list[tuple[int, dict]]:
        return [(t, json.loads(d)) for t, d in self.messages.get(topic, [])]


async def _watch(
    url: str,
    topics: list[str],
    seconds: float,
    done: Callable[[Received], bool],
    protocols: list[str],
):
    got = Received()
    async with websockets.connect(url, subprotocols=protocols, max_size=None) as ws:
        got.protocol = ws.subprotocol
        while not set(topics) <= set(got.channels):
            msg = json.loads(await asyncio.wait_for(ws.recv(), 5))
            if msg["op"] == "advertise":
                got.channels.update({c["topic"]: c for c in msg["channels"]})
        subs = [{"id": i, "channelId": got.channels[t]["id"]} for i, t in enumerate(topics)]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        end = time.monotonic() + seconds
        while time.monotonic() < end and not done(got):
            try:
                msg = await asyncio.wait_for(ws.recv(), 0.2)
            except asyncio.TimeoutError:
                continue
            if isinstance(msg, bytes) and msg[0] == 1:  # messageData
                sub, stamp = struct.unpack_from("<IQ", msg, 1)
                got.messages.setdefault(topics[sub], []).append((stamp, msg[13:]))
    return got


def watch(
    url: str, topics: list[str], seconds: float, done=lambda got: False, protocols=PROTOCOLS
) -> Received:
    """Connect to ``url`` offering ``protocols``, subscribe to ``topics`` and collect for
    ``seconds`` (or until ``done(received)``)."""
    return asyncio.run(_watch(url, topics, seconds, done, protocols))


class Training:
    """A stand-in for the trainer in a thread: random moves on ``grid_collision``, the live
    view called as the trainer calls it (a step hook, then an update every 8 steps)."""

    def __init__(self, live: LiveView, envs: int = 8) -> None:
        self.sc = load_scenario("grid_collision")
        self.env = VectorEnv(self.sc, envs)
        self.env.reset(0)
        self.live, self.stop, self.latency = live, threading.Event(), [0.0]
        live.start(self.env)
        self.thread = threading.Thread(target=self._run)

    def _run(self) -> None:
        rng, update = np.random.default_rng(0), 0
        while not self.stop.is_set():
            for _ in range(8):
                actions = rng.integers(0, self.sc.actions, size=(self.env.num_envs, 3))
                step = self.env.step(actions)
                t = time.perf_counter()
                self.live.step(actions, step)
                self.latency.append(time.perf_counter() - t)
            update += 1
            t = time.perf_counter()
            self.live.update(update, {"policy_loss": 0.5, "entropy": float("nan")})
            self.latency.append(time.perf_counter() - t)

    def __enter__(self) -> Training:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join()


def test_a_client_watches_scenes_and_the_curve_as_it_forms() -> None:
    with LiveView.open(load_scenario("grid_collision"), "127.0.0.1", 0) as live, Training(live):
        topics = ["/scene", "/plot/episodes", "/plot/update"]
        start = time.monotonic()
        got = watch(live.url, topics, 8, lambda g: len(g.messages.get("/scene", [])) >= 8)
        elapsed = time.monotonic() - start
    assert got.protocol == "foxglove.sdk.v1"
    scenes = got.messages["/scene"]
    assert len(scenes) >= 8
    assert len(scenes) <= 4 * elapsed + 2  # a watchable pace (4 states a second on the grid)
    stamps = [t for t, _ in scenes]
    assert stamps == sorted(stamps)  # the run's clock: never back in time
    captions = []
    for stamp, data in scenes:
        scene = got.decode_scene(data)
        ids = {e.id for e in scene.entities}
        assert {"arena", "pursuer_0", "pursuer_2", "evader", "trails", "contacts"} <= ids
        assert all(e.timestamp.seconds * 10**9 + e.timestamp.nanos == stamp for e in scene.entities)
        captions.append(next(e for e in scene.entities if e.id == "arena").texts[0].text)
    first = captions[0].split()[:4]
    assert first[2:] == ["step", "0/" + first[3].split("/")[1]]  # whole episodes, from the start
    points = got.json("/plot/episodes")
    assert points and all(
        {"episode", "episodes", "return", "captured"} <= set(p) for _, p in points
    )
    ids = [p["episode"] for _, p in points]
    assert ids == sorted(ids) and all(p["episodes"] <= LIVE_PLOT_EVERY for _, p in points)
    updates = got.json("/plot/update")
    assert updates and all(p["policy_loss"] == 0.5 and "entropy" not in p for _, p in updates)


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_either_name_of_the_protocol_is_accepted(protocol: str) -> None:
    """A client offering only one name (the SDK itself accepts only ``foxglove.sdk.v1``)
    is answered in that name and gets the same scenes."""
    with LiveView.open(load_scenario("grid_collision"), "127.0.0.1", 0) as live, Training(live):
        got = watch(
            live.url, ["/scene"], 8, lambda g: len(g.messages.get("/scene", [])) >= 2, [protocol]
        )
    assert got.protocol == protocol
    assert len(got.messages["/scene"]) >= 2
    assert {e.id for e in got.decode_scene(got.messages["/scene"][0][1]).entities} >= {"evader"}


def test_a_client_offering_neither_name_is_refused() -> None:
    with LiveView.open(load_scenario("grid_collision"), "127.0.0.1", 0) as live:

        async def offer_another() -> None:
            async with websockets.connect(live.url, subprotocols=["foxglove.other.v9"]):
                pass

        with pytest.raises(websockets.exceptions.InvalidStatus, match="400"):
            asyncio.run(offer_another())


def test_a_stalled_client_never_holds_training_up() -> None:
    """A client that subscribes and then reads nothing: the view sends a frame at every
    step (no pacing), the SDK drops what the client cannot take, and no call waits."""
    sc = load_scenario("grid_collision")
    with LiveView.open(sc, "127.0.0.1", 0, speed=1e9) as live:
        stalled = threading.Event()

        async def subscribe_and_stall() -> None:
            async with websockets.connect(
                live.url, subprotocols=PROTOCOLS, max_size=None, max_queue=1
            ) as ws:
                channels: dict[str, int] = {}
                while "/scene" not in channels:
                    msg = json.loads(await ws.recv())
                    if msg["op"] == "advertise":
                        channels.update({c["topic"]: c["id"] for c in msg["channels"]})
                sub = {"id": 0, "channelId": channels["/scene"]}
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": [sub]}))
                stalled.set()
                await asyncio.sleep(6)  # reads nothing more

        client = threading.Thread(target=lambda: asyncio.run(subscribe_and_stall()))
        client.start()
        assert stalled.wait(5)
        time.sleep(0.3)
        with Training(live) as training:
            time.sleep(3)
        client.join()
    assert live.episodes_shown > 50  # thousands of frames sent into a client that took none
    assert max(training.latency) < 0.25
    assert np.median(training.latency) < 1e-3


def test_nothing_is_drawn_without_a_client(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    monkeypatch.setattr(live_module, "episode_frame", lambda *a: calls.append(a))
    with LiveView.open(load_scenario("grid_collision"), "127.0.0.1", 0) as live, Training(live):
        time.sleep(1.0)
    assert calls == [] and live.episodes_shown == 0


def test_a_busy_port_is_a_user_error_naming_it() -> None:
    sc = load_scenario("grid")
    with LiveView.open(sc, "127.0.0.1", 0) as live:
        port = live.server.port
        with pytest.raises(UserError, match=f"cannot serve Foxglove on 127.0.0.1:{port}: .*in use"):
            LiveView.open(sc, "127.0.0.1", port)


@pytest.mark.parametrize(
    ("text", "address"),
    [
        (None, ("127.0.0.1", 8765)),
        ("9000", ("127.0.0.1", 9000)),
        ("0.0.0.0:9001", ("0.0.0.0", 9001)),
        ("myhost:", ("myhost", 8765)),
        ("0", ("127.0.0.1", 0)),
    ],
)
def test_live_addresses(text: str | None, address: tuple[str, int]) -> None:
    assert live_address(text) == address


@pytest.mark.parametrize("text", ["port", "1:2:x", "70000", "-1"])
def test_bad_addresses_name_their_option(text: str) -> None:
    with pytest.raises(UserError, match="--live"):
        live_address(text)
    with pytest.raises(UserError, match="--serve"):
        address(text, "--serve")


def test_serve_streams_a_finished_logs_episodes(tmp_path: Path) -> None:
    make_log(tmp_path / "episodes.mcap", "grid_collision", envs=4, steps=120)
    log = read_run(tmp_path)
    chosen = [2, 0]
    frames = sum(log.trajectory(e).length + 1 for e in chosen)
    urls: list[str] = []
    result: list[int] = []
    server = threading.Thread(
        target=lambda: result.append(
            serve_episodes(log, chosen, port=0, speed=20.0, wait=10, ready=urls.append, linger=0.5)
        )
    )
    server.start()
    while not urls:
        time.sleep(0.01)
    got = watch(
        urls[0],
        ["/scene", "/plot/episodes"],
        10,
        lambda g: len(g.messages.get("/plot/episodes", [])) >= 2,
    )
    server.join()
    assert result == [2]
    scenes = got.messages["/scene"]
    assert len(scenes) == frames
    stamps = [t for t, _ in scenes]
    assert stamps == sorted(stamps) and stamps[0] == 0
    first = got.decode_scene(scenes[0][1])
    assert next(e for e in first.entities if e.id == "arena").texts[0].text.startswith("episode 2 ")
    points = [p for _, p in got.json("/plot/episodes")]
    ep = log.episodes
    for p, e in zip(points, chosen, strict=True):
        assert p["length"] == ep["length"][e] and p["return"] == ep["return"][e]
