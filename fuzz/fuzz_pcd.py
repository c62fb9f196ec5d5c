"""Fuzz harness: PCD files through the importer (sniff, memory check, pcd.read_pcd, preparation).

    python -m fuzz.fuzz_pcd [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

Each input is a file's bytes, imported by fuzz/reading.py's import_file; its contract holds
(imported and sane, or refused with CloudFileError; MemoryError for a refused allocation).
Half the mutations edit the header as text: a count (POINTS, WIDTH, HEIGHT) made 0, one
off, huge or negative; a SIZE, TYPE or COUNT value changed; DATA switched between the
three encodings (the data then mean something else); VIEWPOINT given NaN, inf or too few
values; a header line dropped, repeated or made lower case; or the binary_compressed sizes
after the header (compressed, decompressed) rewritten; or the data cut short or extended.
The other half are libFuzzer's byte mutations. pcd.py is instrumented (pypcd4 too: its
header model and decoders are what a corrupt file reaches first). A file that makes the
reader loop or allocate what the header alone declares is a finding (fuzz/run.py's -timeout,
-rss_limit_mb). Seed corpus: fuzz/corpus/pcd/ (fuzz/make_corpus.py writes them).
"""
import os
import random
import struct
import tempfile

import atheris
import numpy as np  # noqa: F401  (imported before instrumenting: coverage of our code, not numpy's)

with atheris.instrument_imports(include=["splat_tracer", "fuzz", "pypcd4"]):
    from fuzz import reading

PATH = os.path.join(tempfile.mkdtemp(prefix="fuzz_pcd_"), "input.pcd")
COUNTS = ["0", "1", "-1", "2", "4294967295", "4294967296", "1000000000000", "99999999999999999999", "1.5", "x"]
VALUES = {"SIZE": ["0", "1", "2", "3", "4", "8", "16", "-4"], "TYPE": ["F", "U", "I", "X", "f"],
          "COUNT": ["0", "1", "2", "3", "1000000", "-1"], "DATA": ["ascii", "binary", "binary_compressed", "zip", ""],
          "VIEWPOINT": ["nan nan nan 1 0 0 0", "inf 0 0 1 0 0 0", "0 0 0", "0 0 0 0 0 0 0", "1e308 -1e308 0 1 0 0 0"]}


@atheris.instrument_func
def mutate_pcd(data: bytes, rng: random.Random) -> bytes:
    end = data.find(b"DATA")
    end = data.find(b"\n", end) + 1 if end >= 0 else -1
    if end <= 0:
        return b""
    head, body = data[:end].decode("ascii", "replace").split("\n"), data[end:]
    how = rng.randrange(6)
    lines = [i for i, line in enumerate(head) if line and not line.startswith("#")]
    if not lines:
        return b""
    k = rng.choice(lines)
    key, *values = head[k].split() or [""]
    if how == 0 and key in ("POINTS", "WIDTH", "HEIGHT"):
        head[k] = f"{key} {rng.choice(COUNTS)}"
    elif how == 1 and values:
        if key in VALUES and (key in ("DATA", "VIEWPOINT") or rng.random() < 0.5):
            values = VALUES[key][rng.randrange(len(VALUES[key]))].split() if key in ("DATA", "VIEWPOINT") else values
            if key not in ("DATA", "VIEWPOINT"):
                values[rng.randrange(len(values))] = rng.choice(VALUES[key])
        elif rng.random() < 0.5:
            del values[rng.randrange(len(values))]
        else:
            values.append(rng.choice(values))
        head[k] = " ".join([key, *values])
    elif how == 2:
        action = rng.randrange(3)
        if action == 0:
            del head[k]
        elif action == 1:
            head.insert(k, head[k])
        else:
            head[k] = head[k].lower()
    elif how == 3 and len(body) >= 8:  # binary_compressed: the sizes before the LZF block
        packed, unpacked = struct.unpack_from("<II", body)
        choice = rng.randrange(4)
        packed = rng.choice([0, packed - 1, packed + 1, 0xFFFFFFFF]) if choice < 2 else packed
        unpacked = rng.choice([0, unpacked - 4, unpacked + 4, 0xFFFFFFFF]) if choice >= 1 else unpacked
        body = struct.pack("<II", packed & 0xFFFFFFFF, unpacked & 0xFFFFFFFF) + body[8:]
    elif how == 4 and body:
        cut = rng.randrange(len(body))
        body = body[:cut] if rng.random() < 0.5 else body + body[cut:]
    else:
        return b""  # libFuzzer's own mutation
    return "\n".join(head).encode("ascii", "replace") + body


def mutate(data: bytes, max_size: int, seed: int) -> bytes:
    rng = random.Random(seed)
    if rng.random() < 0.5:
        out = mutate_pcd(data, rng)
        if out and len(out) <= max_size:
            return out
    return atheris.Mutate(data, max_size)


if __name__ == "__main__":
    reading.fuzz(PATH, mutate)
