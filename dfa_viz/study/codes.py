"""Participant codes, issued in advance: the only codes the study page accepts.

    DIR/codes.txt    one code per line, in the order to hand them out: P01-K7QX, P02-MV3A, ...

`dfa study new` issues them and prints them. A code is a running number (so the experimenter
can hand them out in order and keep track) and four random letters (so a participant cannot
guess another code and open a second tab as someone else). The page refuses a code that is
not in the file with one line; one that is starts that participant, or resumes them where
they stopped. Participants are numbered, and so given their balanced plan, in the order they
first arrive (dfa_viz.study.answers), and only issued codes arrive.
"""

from __future__ import annotations

import secrets
from pathlib import Path

from sim.core import UserError, files

CODES = "codes.txt"
ALPHABET = "ACDEFHJKLMNPRTUVWXY3479"  # no letters and digits that look alike (0/O, 1/I, 5/S)
RANDOM_CHARS = 4
MAX_CODES = 999
DEFAULT_CODES = 24  # two blocks of the paper's 12 questions


def issue(n: int) -> list[str]:
    """`n` new codes, each distinct: P01-XXXX (the number as wide as n needs, at least 2)."""
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_CODES:
        raise UserError(f"--participants must be a number of codes from 1 to {MAX_CODES}, not {n}")
    width = max(2, len(str(n)))
    return [
        f"P{i:0{width}d}-" + "".join(secrets.choice(ALPHABET) for _ in range(RANDOM_CHARS))
        for i in range(1, n + 1)
    ]


def write_codes(folder: Path, codes: list[str]) -> Path:
    path = Path(folder) / CODES
    files.write_text(path, "".join(f"{c}\n" for c in codes))
    return path


def read_codes(folder: Path) -> dict[str, str]:
    """{code in capitals: code as issued} of a study folder."""
    path = Path(folder) / CODES
    try:
        lines = path.read_text().split()
    except FileNotFoundError:
        raise UserError(
            f"{path}: missing; the page accepts only codes issued in advance (make the study "
            "again with `dfa study new`, or write one code per line in that file)"
        ) from None
    except OSError as e:
        raise UserError(f"{path}: cannot read it ({e.strerror})") from None
    if not lines:
        raise UserError(f"{path}: no codes in it; write one code per line")
    return {c.upper(): c for c in lines}


def issued(codes: dict[str, str], typed: str) -> str:
    """The issued code `typed` names (capitals or not, spaces around it ignored), else a
    one-line UserError."""
    code = codes.get(typed.strip().upper())
    if code is None:
        shown = typed.strip()[:24] or "an empty code"
        raise UserError(f"{shown} is not a code of this study; type the code you were given")
    return code
