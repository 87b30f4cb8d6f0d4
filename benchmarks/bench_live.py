"""What ``train --live`` costs the main job (issue 32: at most 5%, and never a block).

    python benchmarks/bench_live.py [--updates 1500] [--repeats 5]

Runs ``python -m a2cm_phys.train --scenario grid_collision --updates N`` as a user types
it, in three modes interleaved: without ``--live``, with ``--live`` and no client, and
with one Foxglove WebSocket client (``websockets``, in this process) subscribed to every
channel and reading all it gets. Prints each mode's wall times, their medians, and the
ratios to the run without ``--live``; the client's message counts show that it was fed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import websockets

PROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


async def _read_all(url: str, stop: threading.Event, counts: dict[str, int]) -> None:
    async with websockets.connect(url, subprotocols=PROTOCOLS, max_size=None) as ws:
        channels: dict[int, str] = {}
        while not stop.is_set():
            try:
                msg = await asyncio.wait_for(ws.recv(), 0.2)
            except asyncio.TimeoutError:
                continue
            except websockets.ConnectionClosed:
                return
            if isinstance(msg, str):
                data = json.loads(msg)
                if data.get("op") == "advertise":
                    new = {c["id"]: c["topic"] for c in data["channels"]}
                    subs = [{"id": i, "channelId": i} for i in new]
                    channels.update(new)
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            elif msg[0] == 1:
                sub = int.from_bytes(msg[1:5], "little")
                topic = channels.get(sub, "?")
                counts[topic] = counts.get(topic, 0) + 1


def client(url: str, stop: threading.Event, counts: dict[str, int]) -> threading.Thread:
    """A thread reading everything ``url`` serves until ``stop``."""
    thread = threading.Thread(target=lambda: asyncio.run(_read_all(url, stop, counts)))
    thread.start()
    return thread


def one_run(mode: str, updates: int) -> tuple[float, dict[str, int]]:
    """Wall seconds of one main job in ``mode`` (off, live, client), and what a client got."""
    argv = [sys.executable, "-m", "a2cm_phys.train", "--scenario", "grid_collision"]
    argv += ["--updates", str(updates), "--no-progress"]
    if mode != "off":
        argv += ["--live", "0"]
    counts: dict[str, int] = {}
    stop = threading.Event()
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            argv, cwd=folder, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        reader = None
        if mode != "off":
            for line in proc.stderr:
                found = re.search(r"live view: (ws://\S+)", line)
                if found:
                    if mode == "client":
                        reader = client(found.group(1), stop, counts)
                    break
        proc.stderr.read()
        proc.wait()
        wall = time.perf_counter() - t0
        stop.set()
        if reader is not None:
            reader.join()
    if proc.returncode != 0:
        raise SystemExit(f"{mode}: train exited {proc.returncode}")
    return wall, counts


def main() -> None:
    """Interleave the three modes; print medians and ratios."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--updates", type=int, default=1500)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    modes = ("off", "live", "client")
    times: dict[str, list[float]] = {m: [] for m in modes}
    got: dict[str, int] = {}
    for _ in range(args.repeats):
        for mode in modes:
            wall, counts = one_run(mode, args.updates)
            times[mode].append(wall)
            for topic, n in counts.items():
                got[topic] = got.get(topic, 0) + n
    base = statistics.median(times["off"])
    print(f"python -m a2cm_phys.train --scenario grid_collision --updates {args.updates}")
    for mode in modes:
        med = statistics.median(times[mode])
        each = ", ".join(f"{v:.1f}" for v in times[mode])
        print(f"{mode:>7}: median {med:.2f} s ({each}); ratio {med / base:.3f}")
    print(f"the client got (all repeats): {dict(sorted(got.items()))}")
    print(f"{Path(__file__).name}: {args.repeats} interleaved repeats")


if __name__ == "__main__":
    main()
