"""Training a run: the rollout (:mod:`.rollout`), the teams (:mod:`.teams`), the trainer's
loop (:mod:`.trainer`), its checkpoints (:mod:`.checkpoint`) and run directory
(:mod:`.rundir`: files, the one-writer lock, atomic writes), self-play's opponents
(:mod:`.opponents`), exploitability and its descent (:mod:`.exploitability`,
:mod:`.descent`), every seed stream (:mod:`.seeding`), and a trained run read back
(:mod:`.runs`). Above ``record`` (the trainer writes the log) and ``solve``."""
