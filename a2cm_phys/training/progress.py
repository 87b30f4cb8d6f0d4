"""The progress bar of a training run (tqdm over updates, with episode statistics)."""

from __future__ import annotations

import time

from tqdm import tqdm

from .state import RunState


class ProgressBar:
    """A tqdm bar over updates showing episode statistics; a no-op without a run."""

    def __init__(self, run: RunState | None) -> None:
        self.run = run
        self.bar = None
        self._next_postfix = 0.0

    def __enter__(self) -> ProgressBar:
        t = self.run
        if t is not None:
            self.bar = tqdm(total=t.cfg.updates, initial=t.update, unit="upd", dynamic_ncols=True)
        return self

    def tick(self) -> None:
        """One update done: advance the bar (and refresh its figures twice a second)."""
        if self.bar is None:
            return
        self.bar.update(1)
        now = time.perf_counter()
        if now >= self._next_postfix:  # formatting the postfix costs ~50 µs
            self._next_postfix = now + 0.5
            t = self.run
            s = t.stats
            self.bar.set_postfix(
                episodes=s.episodes,
                len100=f"{s.recent_mean(0, 100):.2f}",
                ret100=f"{s.recent_mean(1, 100):.4g}",
                **({"evader_ret100": f"{s.recent_mean(3, 100):.4g}"} if t.evader else {}),
                **({"opp": t.pairing.kind} if t.pool is not None else {}),
                **({"descent": f"{t.descent.last_value:.4g}"} if t.descent is not None else {}),
                **(
                    {"evader_descent": f"{t.descent.last_evader_value:.4g}"}
                    if t.evader_descends()
                    else {}
                ),
                collisions=s.collisions,
                steps_s=f"{t.session_speed(now):.0f}",
                refresh=False,
            )

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()
