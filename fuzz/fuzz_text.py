"""Fuzz harness: XYZ/PTS/TXT/CSV text through the importer (sniff, text.read_text, preparation).

    python -m fuzz.fuzz_text [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

Each input is a file's bytes, imported by fuzz/reading.py's import_file; its contract holds
(imported and sane, or refused with CloudFileError; MemoryError for a refused allocation).
Half the mutations edit the text as text: every line ending made CR LF, CR or mixed; the
separators made commas, semicolons, tabs or ', '; decimal points made decimal commas, in
the whole file or one line; a header line added (column names, a PTS count, a comment); a
number replaced by an edge value (nan, inf, -0, 1e309, 1e-320, 65535, '1,234.5', digits
from other scripts); a line repeated, dropped or given one value more or less; the file
re-encoded (UTF-16, Latin-1, a UTF-8 byte order mark, a NUL, a no-break space). The
other half are libFuzzer's byte mutations. text.py is instrumented: its branches guide
the search. A file that makes the reader loop is a finding (fuzz/run.py's -timeout).
Seed corpus: fuzz/corpus/text/ (fuzz/make_corpus.py writes them).
"""
import os
import random
import re
import tempfile

import atheris
import numpy as np  # noqa: F401  (imported before instrumenting: coverage of our code, not numpy's)

with atheris.instrument_imports(include=["splat_tracer", "fuzz"]):
    from fuzz import reading

PATH = os.path.join(tempfile.mkdtemp(prefix="fuzz_text_"), "input.xyz")
HEADERS = ["x y z", "X;Y;Z;R;G;B", "//X Y Z Rf Gf Bf", "x,y,z,nx,ny,nz", "x y z intensity", "# scan", "3",
           "12", "0", "x\ty\tz\tred\tgreen\tblue\talpha", "X Y Z", "x y z x"]
VALUES = ["nan", "NaN", "inf", "-inf", "-0", "1e309", "-1e309", "1e-320", "65535", "65536", "256", "-1", "1.5e300",
          "0x10", "1_000", "1,234.5", "1.234,5", "\u0663", "\uff11\uff12", "1e", ".", "-", "+.5", "5.", "1e+", "۱.۵"]
NUMBER = re.compile(r"[-+]?(\d+[.,]?\d*|[.,]\d+)([eE][-+]?\d+)?")


@atheris.instrument_func
def mutate_text(text: str, rng: random.Random) -> bytes:
    lines = text.splitlines() or [""]
    how = rng.randrange(10)
    if how == 0:
        ending = rng.choice(["\r\n", "\r", "\n\r", "\n\n"])
        if rng.random() < 0.5:
            text = ending.join(lines) + ending
        else:
            k = rng.randrange(len(lines))
            text = "\n".join(lines[:k]) + ending + "\n".join(lines[k:])
    elif how == 1:
        new = rng.choice([",", ";", "\t", ", ", "  ", " ;", "\t\t"])
        text = re.sub(r"[ \t]+|[,;]", lambda m: new, text)
    elif how == 2:
        if rng.random() < 0.5:
            text = text.replace(".", ",")
        else:
            k = rng.randrange(len(lines))
            lines[k] = lines[k].replace(".", ",")
            text = "\n".join(lines)
    elif how == 3:
        lines.insert(rng.randrange(len(lines) + 1) if rng.random() < 0.3 else 0, rng.choice(HEADERS))
        text = "\n".join(lines)
    elif how == 4:
        numbers = list(NUMBER.finditer(text))
        if numbers:
            m = rng.choice(numbers)
            text = text[:m.start()] + rng.choice(VALUES) + text[m.end():]
    elif how == 5:
        k = rng.randrange(len(lines))
        action = rng.randrange(3)
        if action == 0:
            lines.insert(k, lines[k])
        elif action == 1:
            del lines[k]
        else:
            lines[k] = lines[k] + rng.choice([" 1", ",1", ";1", "\t1"]) if rng.random() < 0.5 else \
                lines[k].rsplit(None, 1)[0] if lines[k].split() else lines[k]
        text = "\n".join(lines)
    elif how == 6:  # another encoding
        k = rng.randrange(len(text) + 1)
        choice = rng.randrange(5)
        if choice == 0:
            return text.encode("utf-16")
        if choice == 1:
            return (text[:k] + "\u00e9" + text[k:]).encode("latin-1", "replace")
        if choice == 2:
            return b"\xef\xbb\xbf" + text.encode()
        text = text[:k] + ("\0" if choice == 3 else "\u00a0") + text[k:]
    else:
        return b""  # libFuzzer's own mutation
    return text.encode("utf-8", "surrogatepass")


def mutate(data: bytes, max_size: int, seed: int) -> bytes:
    rng = random.Random(seed)
    if rng.random() < 0.5:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = None
        if text is not None:
            out = mutate_text(text, rng)
            if out and len(out) <= max_size:
                return out
    return atheris.Mutate(data, max_size)


if __name__ == "__main__":
    reading.fuzz(PATH, mutate)
