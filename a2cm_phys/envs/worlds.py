"""The worlds of a batch of physics games stepped together (:class:`Worlds`): one
:class:`~.world.World` per game, spare worlds rebuilt ahead, and the batched reads and
writes of every game's bodies through chipmunk's memory where it can be reached
(:data:`~.chipmunk.DIRECT_CALLS`), else through each body's calls.

A holonomic step sets every servo once and runs each game's substeps in a row; a
differential-drive step is :class:`~.drive_worlds.DriveWorlds`'.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import pymunk

from ..config import Scenario
from .chipmunk import BodyMemory
from .world import World, pair_table


class Worlds:
    """The worlds of ``num_envs`` physics games of one scenario, stepped together.

    Holds one :class:`World` per game (``worlds[env]``), the worlds rebuilt ahead at the
    default ``start`` for later restarts (spares: :meth:`build_spare`), and, where chipmunk's
    memory can be reached (:data:`~.chipmunk.DIRECT_CALLS`), every game's body addresses
    (``addresses``, ``(B, 3, N + 1, 2)``; with differential drive also ``drive_addresses``,
    ``(B, N, 12)``, see :func:`~.chipmunk.drive_addresses`) and one memory view over them,
    so that a step steers every servo with one numpy scatter and reads every body with one
    gather."""

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
        self._map_drive(memory, index)

    def _map_drive(self, memory: BodyMemory, index: np.ndarray) -> None:
        """Where a differential-drive step reads and writes (:class:`~.drive_worlds.
        DriveWorlds`); holonomic worlds have nothing to map."""

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
