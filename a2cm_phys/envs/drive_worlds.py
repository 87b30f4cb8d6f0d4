"""A batch of physics games with differential-drive pursuers (:class:`DriveWorlds`):
:class:`~.worlds.Worlds` whose step runs the substeps in lockstep over the games, since
the pursuers' servo targets, their rails and their velocities realigned with their
headings (:mod:`.drive`) are written between every two substeps: one gather and one
scatter per substep for the whole batch.
"""

from __future__ import annotations

import numpy as np

from .chipmunk import BodyMemory
from .drive import DrivePlan, realign
from .worlds import Worlds


class DriveWorlds(Worlds):
    """:class:`~.worlds.Worlds` of a differential-drive scenario: :meth:`drive` steps
    them; where chipmunk's memory can be reached every pursuer's velocity, transform, angle
    and spin are read, and its velocity, servo target, torque and rail written, through
    the same memory view as the bodies' positions."""

    def _map_drive(self, memory: BodyMemory, index: np.ndarray) -> None:
        """Where each substep reads and writes the pursuers in ``memory``, beside the
        bodies' ``index`` (no per-body calls where their memory was found)."""
        if self.drive_addresses is None:
            return
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
