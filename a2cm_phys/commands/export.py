"""``python -m a2cm_phys.export RUN``: a run's actors as ONNX models, for robots and simulators.

Writes one model per actor (``pursuer_0.onnx``, …, and ``evader.onnx`` for a learned evader)
into ``--out``, each taking the observation its agent receives from the env (input
``observation``, ``(batch, obs_dim)`` float32) and returning its action distribution's
parameters (``logits``; or ``mean`` and ``log_std`` for continuous control), with
``policy.json`` beside them: the scenario, the observation's layout and scaling, what the
actions mean, the greedy rule, the run, the package version, the opset and the tensors.
Before it reports done, the export plays its models with onnxruntime against the run's own
actors on ``--check`` observations (outputs within 1e-5, the same greedy actions). Needs
``pip install 'a2cm_phys[deploy]'``. A bad run or output folder is one line, exit 2.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from .options import SEED, Parser, int_range, run_cli, writable_dir


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.export`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.export", description=__doc__.split("\n\n")[0].split(": ", 1)[-1]
    )
    p.add_argument("run", type=Path, metavar="RUN", help="a run directory (or its checkpoint.pt)")
    p.add_argument(
        "--out",
        type=Path,
        help="the folder to write: new, empty, or an earlier export, which is replaced"
        " (default: RUN/onnx)",
    )
    p.add_argument(
        "--check",
        type=int_range(1, 1_000_000),
        default=1000,
        metavar="N",
        help="observations on which the exported actors are compared with the run's",
    )
    p.add_argument(
        "--seed", type=SEED, default=0, help="seed of the --check observations (default: 0)"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Export a run; return the exit status (2 on a bad run or output folder)."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    folder = args.run if args.run.is_dir() else args.run.parent
    out = writable_dir(args.out if args.out is not None else folder / "onnx", "--out")
    from ..training.export import export_run

    done = export_run(args.run, out, check=args.check, seed=args.seed)
    for file in done.files:
        print(f"{file}  {file.stat().st_size:,} bytes")
    print(f"exported to {done.folder} ({done.size:,} bytes); parity: {done.parity}")
    return 0
