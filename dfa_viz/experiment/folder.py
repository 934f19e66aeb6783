"""A resumable results folder: the settings it keeps to, a CSV of rows and a CSV of timings.

    <out>/config.json   {"settings", "columns"}: a folder keeps to one set of settings
    <out>/<rows file>   one row per finished part of a unit; whole lines appended while the
                        work runs (lines that do not fit on the disk are cut off again),
                        rewritten sorted by key at the end (to a temporary file, then renamed)
    <out>/timings.csv   per row its key, wall time and worker (not part of the results: they
                        differ between executions); appended before the rows, sorted likewise

An interrupted run (a killed process, a full disk) resumes from the folder: a unit is done when
each of its parts has its row; a line cut short by the interruption is never read as a row,
and dropped. `dfa experiment q2` (runs.csv, one row per run) and `dfa experiment explain`
(tasks.csv, one row per explainer of a task) both keep their results here.
"""

from __future__ import annotations

import csv
import io
import json
from collections import defaultdict
from collections.abc import Callable, Hashable, Mapping, Sequence
from pathlib import Path

from sim.core import UserError, files

Row = Mapping[str, object]


def csv_line(columns: Sequence[str], row: Row) -> str:
    """One CSV line of `row`'s `columns`, newline included."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([row[c] for c in columns])
    return buf.getvalue()


def _header(columns: Sequence[str]) -> str:
    return csv_line(columns, dict(zip(columns, columns, strict=True)))


class ResultsFolder:
    """Reads and writes one resumable results folder.

    settings: the JSON form of the settings every row shares (config.json keeps them).
    rows_file, columns: the rows' file name and its columns; timing_columns: timings.csv's.
    key: a row's (or timing's) key; the last row of a key wins.
    unit, parts: the unit a row belongs to, and how many rows with distinct keys make it done.
    """

    def __init__(
        self,
        out: str | Path,
        settings: dict,
        *,
        rows_file: str,
        columns: Sequence[str],
        timing_columns: Sequence[str],
        key: Callable[[Mapping[str, str]], tuple],
        unit: Callable[[Mapping[str, str]], Hashable] | None = None,
        parts: int = 1,
    ) -> None:
        self.out = Path(out)
        self.settings = settings
        self.columns, self.timing_columns = tuple(columns), tuple(timing_columns)
        self.key, self.unit, self.parts = key, unit or key, parts
        self.rows_csv = self.out / rows_file
        self.timings_csv = self.out / "timings.csv"
        self.out.mkdir(parents=True, exist_ok=True)
        self._check_config()
        for path, cols in ((self.rows_csv, self.columns), (self.timings_csv, self.timing_columns)):
            self._repair(path, cols)

    def _check_config(self) -> None:
        path = self.out / "config.json"
        mine = json.loads(json.dumps({"settings": self.settings, "columns": self.columns}))
        if path.is_file():
            theirs = json.loads(path.read_text())
            if theirs != mine:
                raise UserError(
                    f"{self.out} holds results made with {theirs['settings']}; these use "
                    f"{mine['settings']}: choose another --out or the same settings"
                )
        else:
            files.write_text(path, json.dumps(mine, indent=2) + "\n")

    @staticmethod
    def _repair(path: Path, columns: Sequence[str]) -> None:
        """Create the file with its header, or drop a last line an interruption cut short."""
        if not path.is_file() or path.stat().st_size == 0:
            files.write_text(path, _header(columns))
            return
        text = path.read_text()
        header = text.split("\n", 1)[0].split(",")
        if header != list(columns):
            raise UserError(f"{path}: columns {header}, expected {list(columns)}")
        if not text.endswith("\n"):
            files.write_text(path, text[: text.rfind("\n") + 1])

    def _read(self, path: Path) -> list[dict[str, str]]:
        reader = csv.DictReader(io.StringIO(files.whole_lines(path), newline=""))
        rows = [r for r in reader if None not in r.values() and None not in r]
        return list({self.key(r): r for r in rows}.values())

    def rows(self) -> list[dict[str, str]]:
        """Every complete row (the last one wins if a key appears twice)."""
        return self._read(self.rows_csv)

    def timings(self) -> list[dict[str, str]]:
        """Every complete timing (the last one wins if a key appears twice)."""
        return self._read(self.timings_csv)

    def done(self) -> set:
        """The units that have all their parts' rows."""
        have: dict[Hashable, set] = defaultdict(set)
        for r in self.rows():
            have[self.unit(r)].add(self.key(r))
        return {u for u, keys in have.items() if len(keys) >= self.parts}

    def append(self, rows: Sequence[Row], timings: Sequence[Row]) -> None:
        """Append one unit's timings, then its rows, each all on disk as whole lines or none."""
        for path, columns, items in (
            (self.timings_csv, self.timing_columns, timings),
            (self.rows_csv, self.columns, rows),
        ):
            files.append_bytes(path, "".join(csv_line(columns, r) for r in items).encode())

    def finalise(self) -> list[dict[str, str]]:
        """Rewrite both files sorted by key (atomically); returns the rows."""
        rows = sorted(self.rows(), key=self.key)
        for path, columns, items in (
            (self.rows_csv, self.columns, rows),
            (self.timings_csv, self.timing_columns, sorted(self.timings(), key=self.key)),
        ):
            files.write_text(path, _header(columns) + "".join(csv_line(columns, r) for r in items))
        return rows
