"""A CSV file of rows on the run's clock that a resumed session continues (the CSV logger's,
:class:`~.loggers.CsvLogger`): rows a killed session wrote past the checkpoint, and a row it
tore, are dropped when the file is opened again, the file then rewritten atomically."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .rundir import write_atomic


class CsvTable:
    """One CSV file at ``path`` whose columns start with ``lead`` and include
    ``env_steps``: its header once (the file rewritten when a row brings a new column, e.g.
    a metric computed every K updates only), each row flushed as written; an empty cell is
    a value the row does not have (or a non-finite one). :meth:`open`, :meth:`write`,
    :meth:`close`."""

    def __init__(self, path: Path, lead: tuple[str, ...]) -> None:
        self.path, self.header = path, list(lead)
        self._fh: io.TextIOWrapper | None = None
        self._writer: csv.DictWriter | None = None

    def open(self, env_steps: int) -> None:
        """Open for appending, keeping only the rows at or before ``env_steps``: a killed
        session's rows past the checkpoint, and a row it tore, are dropped (the file is then
        rewritten atomically)."""
        header, rows, whole = self._read()
        if header is None:
            self._rewrite([])
        else:
            self.header = header + [k for k in self.header if k not in header]
            kept = [r for r in rows if _at_or_before(r, env_steps)]
            if not whole or len(kept) < len(rows):
                self._rewrite(kept)
        self._append()

    def write(self, rows: list[dict[str, Any]]) -> None:
        """Append ``rows`` (new keys become columns) and flush."""
        new = [k for k in dict.fromkeys(k for r in rows for k in r) if k not in self.header]
        if new:
            self.close()
            self.header += new
            self._rewrite(self._read()[1])
            self._append()
        assert self._fh is not None and self._writer is not None
        self._writer.writerows(rows)
        self._fh.flush()

    def close(self) -> None:
        """Close the file; idempotent."""
        if self._fh is not None:
            self._fh.close()
            self._fh = self._writer = None

    def _read(self) -> tuple[list[str] | None, list[dict[str, str]], bool]:
        """``(header, rows, whole)`` of the file (``None`` header: no file, or an empty
        one); ``whole`` is false if a row was torn (and left out)."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None, [], True
        lines = text.splitlines(keepends=True)
        whole = not lines or lines[-1].endswith("\n")
        reader = csv.DictReader(lines if whole else lines[:-1])
        if not reader.fieldnames:
            return None, [], whole
        rows = [r for r in reader if None not in r and None not in r.values()]
        return list(reader.fieldnames), rows, whole and reader.line_num == len(rows) + 1

    def _rewrite(self, rows: Iterable[dict[str, Any]]) -> None:
        out = io.StringIO()
        writer = csv.DictWriter(out, self.header, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        write_atomic(self.path, out.getvalue())

    def _append(self) -> None:
        self._fh = open(self.path, "a", newline="", encoding="utf-8")  # noqa: SIM115
        self._writer = csv.DictWriter(self._fh, self.header, lineterminator="\n")


def _at_or_before(row: dict[str, str], env_steps: int) -> bool:
    """Whether a CSV row was logged at or before ``env_steps`` (an unreadable one: no)."""
    try:
        return int(row["env_steps"]) <= env_steps
    except (KeyError, ValueError):
        return False
