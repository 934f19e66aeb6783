"""The files `dfa study analyse` writes under the study's analysis/ folder: the answers as CSV,
the accuracy table, the plots and the recording (the numbers are dfa_viz.study.analysis')."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from dfa_viz.study.analysis import ANALYSIS, COLUMNS, Analysis, analyse, table_md
from dfa_viz.study.figures import write_durations, write_plot, write_rrd
from sim.core import files


def write_csv(path: Path, rows: list[dict]) -> Path:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return files.write_text(path, buf.getvalue())


def write_analysis(folder: Path) -> Analysis:
    """analyse(folder) and its files under folder/analysis/."""
    folder = Path(folder)
    a = analyse(folder)
    out = folder / ANALYSIS
    out.mkdir(exist_ok=True)
    paths = [
        write_csv(out / "answers.csv", a.rows),
        files.write_text(out / "accuracy.md", table_md(a)),
        write_plot(out / "accuracy.png", a.cells),
        write_durations(out / "durations.png", a.rows),
        write_rrd(out / "answers.rrd", a),
    ]
    a.files.extend(paths)
    return a
