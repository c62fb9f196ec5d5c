"""Text point clouds: XYZ/PTS/TXT/CSV (anything else that decodes as UTF-8 text), see read_text."""
from __future__ import annotations

import re

import numpy as np

from ...util.columns import finite_rows
from ..cloud import CloudFileError, PointCloud, make_cloud, srgb_to_linear, unit_colours
from .numbers import first_bad_row, is_number, lf_line_ends, parse_numbers

# Column names a header line may use (lower case), to the roles below.
_NAMES = {
    "x": "x", "y": "y", "z": "z", "//x": "x",
    "r": "r", "red": "r", "g": "g", "green": "g", "b": "b", "blue": "b",
    "nx": "nx", "ny": "ny", "nz": "nz", "normal_x": "nx", "normal_y": "ny", "normal_z": "nz",
    "normalx": "nx", "normaly": "ny", "normalz": "nz",
    "i": "i", "intensity": "i", "scalar_intensity": "i", "a": "a", "alpha": "a",
}
ROLES = ("x", "y", "z", "r", "g", "b", "a", "nx", "ny", "nz", "i", "_")
_SEPARATORS = str.maketrans({",": " ", ";": " ", "\t": " "})
# A file with decimal commas (European exports: `10,50;20,25;1,25`) separates its values by
# semicolons, tabs or spaces: the commas become decimal points (_decimal_comma).
_DECIMAL_COMMA = str.maketrans({",": ".", ";": " ", "\t": " "})
# The decimal mark is decided on the file's first this many characters (some 30,000 rows):
# a later row that does not follow it is refused by the parse, naming its line.
_DECIMAL_SAMPLE = 1 << 20
_NUMERIC_LINE = re.compile(r"^[\d\s;,.+\-eE]*\d[\d\s;,.+\-eE]*$")  # digits and number punctuation only
_COMMA_DECIMAL = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")        # one comma between digits: 10,50  -0,5
_HEADER_LINES = 100  # at most this many lines before the data are taken as a header


def _is_numbers(tokens) -> bool:
    return bool(tokens) and all(is_number(t) for t in tokens)


def _parse_columns(path: str, spec: str, count: int) -> list[str]:
    roles = spec.replace(",", " ").lower().split()
    unknown = [r for r in roles if r not in ROLES and r != "-"]
    if unknown:
        raise CloudFileError(f"{path}: the column mapping '{spec}' has unknown names {', '.join(unknown)} "
                             f"(known: {' '.join(ROLES)}; '_' or '-' skips a column)")
    roles = ["_" if r == "-" else r for r in roles]
    if len(roles) != count:
        raise CloudFileError(f"{path}: the column mapping '{spec}' names {len(roles)} columns but the file's rows "
                             f"have {count}")
    return roles


def _guess_columns(path: str, table: np.ndarray) -> list[str]:
    """Roles of the columns by their count and values: x y z first; then a triplet of
    unit-length rows is a normal, a triplet within a colour range (0..1, 0..255, 0..65535)
    a colour (the last such, as PTS writes x y z intensity r g b), one column left intensity."""
    count = table.shape[1]
    roles = ["x", "y", "z"] + ["?"] * (count - 3)
    free = lambda s: all(roles[c] == "?" for c in range(s, s + 3))  # noqa: E731
    for s in range(3, count - 2):
        t = table[:, s:s + 3]
        length = np.linalg.norm(t, axis=1)
        if free(s) and np.isfinite(t).all() and np.abs(t).max() <= 1 + 1e-3 and np.median(np.abs(length - 1)) < 1e-2:
            roles[s:s + 3] = ["nx", "ny", "nz"]
            break
    for s in reversed(range(3, count - 2)):
        t = table[:, s:s + 3]
        if free(s) and np.isfinite(t).all() and t.min() >= 0 and (t.max() <= 1 or (
                t.max() <= 65535 and np.all(t == np.round(t)))):
            roles[s:s + 3] = ["r", "g", "b"]
            break
    left = [c for c in range(count) if roles[c] == "?"]
    if len(left) == 1:
        roles[left[0]] = "i"
    elif left:
        raise CloudFileError(
            f"{path}: cannot tell what its {count} columns are (guessed: {' '.join(roles)}; '?' unknown); import "
            "with the Columns option naming each, e.g. 'x y z i r g b' (names: x y z r g b a nx ny nz i, '_' to skip)")
    return roles


def _decimal_comma(path: str, text: str) -> bool:
    """Whether the file writes its numbers with decimal commas: a row of at least three
    values separated by semicolons, tabs or spaces, whose commas each stand alone between
    digits and which has no decimal point (`10,50;20,25;1,25`, `10,5\t20\t1,25`). Other
    rows with commas have comma separators (`1.5,2.5,3`, `1, 2, 3`, `1,2,3`). Refused,
    naming the lines: rows of both kinds, or a row separated by semicolons or tabs with both
    '.' and ',' in its numbers (`1,5;2.5;3`, `1.234,5;7`: thousands separators)."""
    if "," not in text:
        return False
    sample = text if len(text) <= _DECIMAL_SAMPLE else text[:text.rfind("\n", 0, _DECIMAL_SAMPLE) + 1]
    decimal = separated = None  # the first row of each kind: (line number, text)
    for k, line in enumerate(sample.split("\n")):
        if "," not in line or not _NUMERIC_LINE.match(line):
            continue  # nothing to decide, or a header
        values = line.replace(";", " ").replace("\t", " ").split()
        with_comma = [v for v in values if "," in v]
        if ("\t" in line or ";" in line) and "." in line:
            raise CloudFileError(f"{path}: line {k + 1} ('{line.strip()[:60]}') has both '.' and ',' in numbers "
                                 "separated by semicolons or tabs (two decimal marks, or thousands separators), so its "
                                 "decimal mark cannot be told; save it with one decimal mark and no thousands "
                                 "separators")
        if len(values) >= 3 and all(_COMMA_DECIMAL.match(v) for v in with_comma) and "." not in line:
            decimal = decimal or (k + 1, line)
        else:
            separated = separated or (k + 1, line)
        if decimal and separated:
            (a, first), (b, second) = sorted([decimal, separated])
            raise CloudFileError(
                f"{path}: cannot tell its decimal mark: line {a} ('{first.strip()[:60]}') and line {b} "
                f"('{second.strip()[:60]}') use ',' differently (one as a decimal comma, the other between values); "
                "save it with one convention")
    return decimal is not None


def read_text(path: str, columns: str = "") -> PointCloud:
    """x y z rows separated by whitespace, commas or semicolons (decimal commas when the
    values are separated otherwise: _decimal_comma), with optional colour
    (0..255, 0..65535 or 0..1), alpha, intensity and normal columns. Lines before the first
    row of numbers are a header (its last line may name the columns; a PTS file's first
    line is its point count, which must match). Columns come from `columns` (e.g.
    'x y z i r g b', '_' skips one), else the header's names, else a guess."""
    with open(path, "rb") as f:
        data = f.read()
    try:
        # utf-8-sig: a byte order mark (Windows tools write one) is not text; kept, it made the
        # first row '\ufeff1.0 2.0 3.0', a header line, and that point was silently lost.
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = len(re.split(rb"\r\n|\r|\n", data[:e.start]))  # any line ending (the error path only)
        raise CloudFileError(f"{path}: not UTF-8 text (byte {e.start}, 0x{data[e.start]:02x}, on line {line}) and no "
                             "other point-cloud format; save it as UTF-8 or ASCII") from None
    text = lf_line_ends(text)
    decimal_comma = _decimal_comma(path, text)
    if any(c in text for c in ",;\t"):  # (a scan for each is far quicker than a translation that changes nothing)
        text = text.translate(_DECIMAL_COMMA if decimal_comma else _SEPARATORS)
    # The header: lines before the first one made of numbers only.
    offset, header, first = 0, [], None
    for _ in range(_HEADER_LINES + 1):
        end = text.find("\n", offset)
        line = text[offset:] if end < 0 else text[offset:end]
        tokens = line.split()
        if tokens and _is_numbers(tokens) and len(tokens) >= 3:
            first = tokens
            break
        if tokens:
            header.append(tokens)
        if end < 0:
            break
        offset = end + 1
    if first is None:
        if not text.strip():
            raise CloudFileError(f"{path}: the file is empty")
        raise CloudFileError(f"{path}: no row of at least three numbers (x y z) within its first "
                             f"{_HEADER_LINES} lines; not a point-cloud text file")
    count = len(first)
    body = text[offset:]
    parsed = parse_numbers(body.encode("utf-8"))
    per_line = parsed.per_line[parsed.per_line > 0]  # the rows: lines that are not blank
    rows = len(per_line)
    if not parsed.ok or (per_line != count).any():
        lines = body.splitlines()  # the error path only: find the row to name
        found = first_bad_row(lines, count)
        if found:
            k, tokens, bad = found
            what = (f"has {len(tokens)} values where the first row has {count}" if bad is None
                    else f"is not all numbers ('{lines[k].strip()[:60]}')")
            raise CloudFileError(f"{path}: data line {k + 1} (after {len(header)} header lines) {what}")
        raise CloudFileError(f"{path}: the rows could not be read as {count} numbers each")
    table = parsed.values.reshape(rows, count)
    # A PTS file's first line is its point count: it must not lie.
    if len(header) == 1 and len(header[0]) == 1 and header[0][0].isdigit() and int(header[0][0]) != rows:
        raise CloudFileError(f"{path}: its first line declares {int(header[0][0]):,} points but {rows:,} rows "
                             "follow (the count is wrong or the file is truncated)")
    named = [_NAMES.get(t.lower()) for t in header[-1]] if header else []
    if columns.strip():
        roles = _parse_columns(path, columns, count)
    elif named and len(named) == count and all(named) and {"x", "y", "z"} <= set(named):
        roles = named
    else:
        roles = _guess_columns(path, table)
    for role in ROLES[:-1]:
        if roles.count(role) > 1:
            raise CloudFileError(f"{path}: the column '{role}' is given {roles.count(role)} times")
    for group in (("x", "y", "z"), ("r", "g", "b"), ("nx", "ny", "nz")):
        present = [r for r in group if r in roles]
        if present and len(present) != 3 or (group[0] == "x" and not present):
            raise CloudFileError(f"{path}: the columns need all of {' '.join(group)} (have: {' '.join(roles)})")
    col = {r: table[:, c] for c, r in enumerate(roles) if r != "_"}
    pos = np.column_stack([col["x"], col["y"], col["z"]])
    finite = finite_rows(pos)
    colours = None
    if "r" in col and finite.any():  # none finite: make_cloud refuses the file, saying so
        rgb = unit_colours(path, {"red": col["r"][finite], "green": col["g"][finite], "blue": col["b"][finite]},
                            ("red", "green", "blue"))
        alpha = (unit_colours(path, {"alpha": col["a"][finite]}, ("alpha",))[:, 0] if "a" in col
                 else np.ones(len(rgb), np.float32))
        colours = np.zeros((rows, 4), np.float32)
        colours[finite] = np.column_stack([srgb_to_linear(rgb), alpha])
    normals = np.column_stack([col["nx"], col["ny"], col["nz"]]) if "nx" in col else None
    attributes = {"intensity": col["i"].astype(np.float32)} if "i" in col else {}
    notes = ["numbers read with decimal commas"] if decimal_comma else []
    return make_cloud(path, pos, normals, colours, None, attributes, drop_non_finite=True, format="TEXT",
                      notes=notes + [f"columns read as: {' '.join(roles)}"])
