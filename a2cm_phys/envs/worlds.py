"""The worlds of a batch of physics games stepped together (:class:`Worlds`): one
:class:`~.world.World` per game, spare worlds rebuilt ahead, and the batched reads and
writes of every game's bodies through chipmunk's memory where it can be reached
(:data:`~.chipmunk.DIRECT_CALLS`), else through each body's calls.

A holonomic step sets every servo once and runs each game's substeps in a row. A
differential-drive step (:mod:`.drive`) runs the substeps in lockstep over the games
instead, since the pursuers' servo targets, their rails and their velocities realigned
with their headings are written between every two substeps: one gather and one scatter
per substep for the whole batch.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import pymunk

from ..config import Scenario
from .chipmunk import BodyMemory
from .drive import DrivePlan, realign
from .world import World, pair_table


class Worlds:
    """The worlds of ``num_envs`` physics games of one scenario, stepped together.

    Holds one :class:`World` per game (``worlds[env]``), the worlds rebuilt ahead at the
    default ``start`` for later restarts (spares: :meth:`build_spare`), and, where chipmunk's
    memory can be reached (:data:`~.chipmunk.DIRECT_CALLS`), every game's body addresses
    (``addresses``, ``(B, 3, N + 1, 2)``; with differential drive also ``drive_addresses``,
    ``(B, N, 12)``, see :func:`~.chipmunk.drive_addresses`) and one memory view over them,
    so that a step steers every servo with one numpy scatter and reads every body with one
    gather.

    Over the layout test's size limit since issue 46 (``KEPT_LARGE``): to be split."""

    def __init__(self, scenario: Scenario, num_envs: int, start: np.ndarray) -> None:
        ph = scenario.physics
        self._scenario = scenario
        self._start = start
        self._table = pair_table(scenario)
        self._dt = ph.dt / ph.substeps
        self._substeps = range(ph.substeps)
        self.worlds = [World(scenario, start, self._table) for _ in range(num_envs)]
        self._spares: list[World] = []  # worlds rebuilt at the default start in advance
        self._retired: list[World] = []  # worlds replaced by spares, to be rebuilt as spares
        self.addresses: np.ndarray | None = None
        self.drive_addresses: np.ndarray | None = None
        self._cp_step = getattr(pymunk.cp, "cpSpaceStep", None)
        if self._cp_step is not None and all(
            world.addresses is not None and world.cp_space is not None for world in self.worlds
        ):
            self.addresses = np.stack([world.addresses for world in self.worlds])
            if ph.drive == "differential" and all(
                world.drive_addresses is not None for world in self.worlds
            ):
                self.drive_addresses = np.stack([w.drive_addresses for w in self.worlds])
            self._map()

    def __getitem__(self, env: int) -> World:
        return self.worlds[env]

    def __iter__(self) -> Iterator[World]:
        return iter(self.worlds)

    def __len__(self) -> int:
        return len(self.worlds)

    def _map(self) -> None:
        """(Re)make the memory view over every game's bodies and its read/write indices."""
        assert self.addresses is not None
        every = self.addresses.ravel()
        if self.drive_addresses is not None:
            every = np.concatenate((every, self.drive_addresses.ravel()))
        memory = BodyMemory(every)
        index = memory.index(self.addresses)
        self._memory = memory.view
        self._read = index[:, :2]  # (B, position|velocity, agent, xy): the state's layout
        self._write = index[:, 2]  # (B, agent, xy): the control bodies' velocities
        if self.drive_addresses is not None:
            n = self.drive_addresses.shape[1]
            drive = memory.index(self.drive_addresses)  # (B, N, 15): chipmunk.DRIVE_COLUMNS
            # Component first, (k, B, N): numpy's arithmetic on whole contiguous planes is
            # what keeps a substep's few dozen operations cheap.
            # (10, B, N) what each substep reads: velocity, transform (a, b, c, d, tx, ty),
            # angle, angular velocity
            read = np.concatenate((index[:, 1, :n], drive[..., :8]), axis=-1)
            self._drive_read = np.ascontiguousarray(read.transpose(2, 0, 1))
            # (11, B, N) what it writes: the realigned velocity, the velocity servo's target,
            # the torque, the rail's rotation and centre; flat, as the values are contiguous
            write = np.concatenate((index[:, 1, :n], index[:, 2, :n], drive[..., 8:]), axis=-1)
            write = np.ascontiguousarray(write.transpose(2, 0, 1))
            self._drive_write = {11: write.ravel(), 9: write[2:].ravel(), 2: write[:2].ravel()}

    def restart(self, envs: Sequence[int], starts: Sequence[np.ndarray | None]) -> None:
        """Put every agent of games ``envs`` at rest in a new space (:meth:`World.rebuild`),
        at the positions ``starts`` gives each (``None``: the default start, where a spare
        world is taken instead when one is waiting)."""
        swapped = False
        for env, xy in zip(envs, starts, strict=True):
            if xy is None and self._spares:
                self._retired.append(self.worlds[env])
                world = self.worlds[env] = self._spares.pop()
                if self.addresses is not None:
                    self.addresses[env] = world.addresses
                    swapped = True
                if self.drive_addresses is not None:
                    self.drive_addresses[env] = world.drive_addresses
            else:
                self.worlds[env].rebuild(self._start if xy is None else xy)
        if swapped:
            self._map()

    def build_spare(self) -> int:
        """Rebuild one world at the default start for a later :meth:`restart` to take, and
        return how many are waiting (see :meth:`~.physics.PhysicsCore.build_spare`)."""
        if self._retired:
            world = self._retired.pop()
            world.rebuild(self._start)
        else:
            world = World(self._scenario, self._start, self._table)
        self._spares.append(world)
        return len(self._spares)

    @property
    def spare_worlds(self) -> int:
        """How many worlds :meth:`build_spare` has prepared that no restart has taken yet."""
        return len(self._spares)

    def advance(self, velocities: np.ndarray, steps: list[int], state: np.ndarray) -> list[list]:
        """Step every game one control period with the servo ``velocities`` ``(B, N + 1, 2)``,
        write the bodies' positions and velocities to ``state`` ``(B, 2, N + 1, 2)`` and
        return each game's contact events, ``steps`` being the games' step numbers.

        Through the bodies' memory where it was found (one scatter steers every control
        body, one gather reads every body), else per body through pymunk. The same numbers
        either way: setting a kinematic body's velocity is only the store (chipmunk wakes
        dynamic bodies alone), and games are independent, so steering all before stepping
        any changes nothing."""
        dt, substeps = self._dt, self._substeps
        events = []
        if self.addresses is not None:
            self._memory[self._write] = velocities
            space_step = self._cp_step
            for world, step in zip(self.worlds, steps, strict=True):
                space = world.cp_space
                for _ in substeps:
                    space_step(space, dt)
                events.append(world.tracker.end_step(step))
            state[:] = self._memory[self._read]
            return events
        flat = []
        for world, row, step in zip(self.worlds, velocities.tolist(), steps, strict=True):
            for steer, v in zip(world.steering, row, strict=True):
                steer(v)
            world_step = world.step
            for _ in substeps:
                world_step(dt)
            events.append(world.tracker.end_step(step))
            for probe in world.probes:
                v = probe()
                flat += v.x, v.y
        state[:] = np.array(flat).reshape(state.shape)
        return events

    def drive(
        self,
        plan: DrivePlan,
        evader: np.ndarray,
        steps: list[int],
        state: np.ndarray,
        headings: np.ndarray,
    ) -> list[list]:
        """Step every game one control period with differential-drive pursuers steered by
        ``plan`` and the evader's servo at ``evader`` ``(B, 2)`` (m/s); write the bodies'
        positions and velocities to ``state`` ``(B, 2, N + 1, 2)`` and the pursuers'
        ``(cos θ, sin θ)`` to ``headings`` ``(B, N, 2)``; return each game's contact events.

        Substep by substep over every game: before each substep the servos' targets are set
        and each rail turned to its pursuer's heading, after it the pursuers' forward speeds
        are realigned with their turned headings (see :mod:`.drive`). Through the bodies'
        memory where it was found, else per body: the same numbers either way (the same
        arithmetic on the same values; a rail copies its pursuer's transform, which
        ``cpBodySetAngle`` computes alike from the same angle; games are independent, so
        stepping them in lockstep changes nothing)."""
        n = headings.shape[1]
        mapped = self.addresses is not None  # positions and velocities in memory
        direct = self.drive_addresses is not None  # headings and spins too
        read, write = self._gather, self._scatter
        if not direct:
            read, write = self._read_each, self._write_each
        if mapped:
            self._memory[self._write[:, n]] = evader
        else:
            for world, v in zip(self.worlds, evader.tolist(), strict=True):
                world.steering[n](v)
        now = read()
        write(self._next(plan, None, now), now)
        dt = self._dt
        space_step = self._cp_step
        spaces = [world.cp_space for world in self.worlds] if mapped else None
        last = len(self._substeps) - 1
        for k in self._substeps:
            if spaces is not None:
                for space in spaces:
                    space_step(space, dt)
            else:
                for world in self.worlds:
                    world.step(dt)
            before, now = now, read()
            if k < last:
                write(self._next(plan, before, now), now)
            else:  # the next step sets the servos and rails anew: the velocities alone
                write(realign(now[:2], before[2:4], now[2:4]), now)
        worlds = zip(self.worlds, steps, strict=True)
        events = [world.tracker.end_step(step) for world, step in worlds]
        headings[:] = now[2:4].transpose(1, 2, 0)
        if mapped:
            state[:] = self._memory[self._read]
        else:
            flat = []
            for world in self.worlds:
                for probe in world.probes:
                    v = probe()
                    flat += v.x, v.y
            state[:] = np.array(flat).reshape(state.shape)
        return events

    @staticmethod
    def _next(plan: DrivePlan, before: np.ndarray | None, now: np.ndarray) -> np.ndarray:
        """What to write after a substep ``(11, B, N)``, from what was read ``(10, B, N)``
        ``before`` it and ``now``: the realigned velocity, the velocity servo's target and
        the torque (:meth:`~.drive.DrivePlan.targets`), the rail's rotation and centre (the
        pursuer's transform, read in that order). Without ``before`` (a step's start)
        ``(9, B, N)``, all but the velocity."""
        at = 0 if before is None else 2
        out = np.empty((at + 9, *now.shape[1:]))
        if before is not None:
            realign(now[:2], before[2:4], now[2:4], out[:2])
        plan.targets(now[2:4], now[8], now[9], out[at : at + 3])
        out[at + 3 :] = now[2:8]
        return out

    def _gather(self) -> np.ndarray:
        """``(10, B, N)``: every pursuer's velocity, transform ``(a, b, c, d, tx, ty)``,
        angle and angular velocity."""
        return self._memory[self._drive_read]

    def _scatter(self, values: np.ndarray, now: np.ndarray) -> None:
        """Write :meth:`_next`'s values, or the realigned velocities alone ``(2, B, N)``
        (the per-body path also reads ``now``)."""
        self._memory[self._drive_write[len(values)]] = values.reshape(-1)

    def _read_each(self) -> np.ndarray:
        """:meth:`_gather` through each body's calls."""
        flat = []
        for world in self.worlds:
            for io in world.turning:
                v, u, p = io.velocity(), io.rotation(), io.position()
                flat += v.x, v.y, u.x, u.y, -u.y, u.x, p.x, p.y, io.angle(), io.spin()
        rows = np.array(flat).reshape(len(self.worlds), -1, 10)
        return np.ascontiguousarray(rows.transpose(2, 0, 1))

    def _write_each(self, values: np.ndarray, now: np.ndarray) -> None:
        """:meth:`_scatter` through each body's calls (a rail takes the pursuer's angle
        from ``now`` and its centre, and chipmunk makes its transform)."""
        at = len(values) - 9
        rows, angles = values.transpose(1, 2, 0).tolist(), now[8].tolist()
        for world, game, turns in zip(self.worlds, rows, angles, strict=True):
            for io, row, angle in zip(world.turning, game, turns, strict=True):
                if at:
                    io.set_velocity((row[0], row[1]))
                if at < 0:  # the velocities alone
                    continue
                io.steer((row[at], row[at + 1]))
                io.set_torque(row[at + 2])
                io.turn_rail(angle)
                io.place_rail((row[at + 7], row[at + 8]))
