"""The reproduction report (``python -m a2cm_phys.experiments``), in parts.

- :mod:`.plan`: the groups of cells (the paper's experiments with ``--preset paper`` and
  with our defaults, continuous control, the learning evader), their runs and the
  wall-time estimate;
- :mod:`.measure`: what each finished run is worth (training tallies, greedy evaluation,
  references, cross-play, exact exploitability), cached beside the run;
- :mod:`.claims`: the paper's claims and ours, each with its figure, 95% CI and verdict;
- :mod:`.markdown`: ``RESULTS.md`` and its figures.
"""
