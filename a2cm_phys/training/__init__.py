"""Training a run: the rollout (:mod:`.rollout`), the teams (:mod:`.teams`), the run's
state (:mod:`.state`) and the trainer that builds and drives it (:mod:`.trainer`: one
update with :mod:`.update`, a session with :mod:`.session`), its checkpoints
(:mod:`.checkpoint`, :mod:`.run_state`, :mod:`.resume`) and run directory (:mod:`.rundir`:
files, the one-writer lock, atomic writes), self-play's opponents (:mod:`.opponents`),
exploitability and its descent (:mod:`.exploitability`, :mod:`.descent`), every seed
stream (:mod:`.seeding`), and a trained run read back (:mod:`.runs`). Above ``record``
(the trainer writes the log) and ``solve``."""
