"""Tables of decimal numbers in text, for the readers of ASCII PLY, ASCII PCD and XYZ/PTS/CSV
files: parsed by the core (native/pointcloud/numbers.h) on all cores, in place.

numpy parses such text on one core, a number at a time (np.fromstring, np.loadtxt): about
3 s for the 9 million numbers of a million-point ASCII PLY, thirty times its binary read.
The core parses them with std::from_chars (correctly rounded: the same float64 as float()
and numpy), a piece of the text per worker, and counts each line's tokens, so that a
reader finds a row of the wrong length, or a token that is not a number, by its line.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ... import _core

# A token parse_numbers reads as a number (underscores and exotic spellings are not).
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?|nan|inf|infinity)$", re.IGNORECASE)


@dataclass(frozen=True)
class NumberTable:
    values: np.ndarray     # (V,) float64: every whitespace-separated token in order, NaN where one is not a number
    per_line: np.ndarray   # (L,) int64: tokens on each line (blank lines 0)
    bad_lines: np.ndarray  # int64: the lines (from 0, ascending) holding a token that is not a number

    @property
    def ok(self) -> bool:
        """Every token is a number."""
        return self.bad_lines.size == 0

    def offsets(self) -> np.ndarray:
        """(L + 1,) int64: where each line's values start in `values`, then their end."""
        out = np.zeros(len(self.per_line) + 1, np.int64)
        np.cumsum(self.per_line, out=out[1:])
        return out


def parse_numbers(data, threads: int = 0, chunk_bytes: int = 1 << 20) -> NumberTable:
    """The numbers of `data` (bytes or any contiguous buffer, read in place). Whitespace is
    numpy's (space, tab, CR, LF, VT, FF); lines end at LF (a last line without one counts
    when not empty). A number is what float() reads (less underscores and non-ASCII
    digits, which numpy refuses too): 1, -2.5, +.5, 5., 1e-3, inf, Infinity, nan; beyond
    float64's range +-inf or +-0, as numpy. threads: 0 for all cores; chunk_bytes: the size
    of the pieces the text is cut into at line ends (the result does not depend on either)."""
    values, per_line, bad = _core.parse_numbers(data, threads, chunk_bytes)
    return NumberTable(np.frombuffer(values, np.float64), np.frombuffer(per_line, np.int64),
                       np.frombuffer(bad, np.int64))


def lf_line_ends(data):
    """`data` (bytes or str) with its lines ended by LF, as parse_numbers counts them, when
    some end with a lone CR (classic Mac OS, some exporters), which parse_numbers takes for
    whitespace: every row would be one line. CR LF alone is left as it is: its CR is
    whitespace to the parse, and the line count is the same."""
    cr, crlf, lf = ("\r", "\r\n", "\n") if isinstance(data, str) else (b"\r", b"\r\n", b"\n")
    if cr not in data or data.count(cr) == data.count(crlf):
        return data
    return data.replace(crlf, lf).replace(cr, lf)


def is_number(token: str) -> bool:
    """Whether the whitespace-free `token` is a number (as parse_numbers reads one)."""
    return bool(_NUMBER.match(token))


def first_bad_row(lines, count: int):
    """The first of `lines` (text, each one line) that is not blank and not `count` numbers:
    (its index, its tokens, its first token that is not a number or None); None when every
    row is. For the readers' error paths: the row to name, as a person reads the text."""
    for k, line in enumerate(lines):
        tokens = line.split()
        if tokens:
            bad = next((t for t in tokens if not is_number(t)), None)
            if bad is not None or len(tokens) != count:
                return k, tokens, bad
    return None
