"""Fuzz harness: LAS/LAZ files through the importer (sniff, memory check, las.read_las, preparation).

    python -m fuzz.fuzz_las [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

Each input is a file's bytes, imported by fuzz/reading.py's import_file; its contract holds
(imported and sane, or refused with CloudFileError; MemoryError for a refused allocation).
The mutator knows the format: half the mutations write a chosen value (0, 1, the largest,
a power of two, NaN, inf, a neighbour of the old value...) over one field of the public
header (counts, offsets, sizes, point format, scales, offsets, LAS 1.3/1.4's EVLR start and
64-bit counts), of a VLR or EVLR header (lengths, user and record IDs: the LAZ VLR's
among them) or of a point record, or bytes into a VLR's or EVLR's body (the LAZ item
table); the other half are libFuzzer's own byte mutations. laspy is instrumented, so its
header and VLR parsing guide the search; lazrs (Rust) is not. A file that makes the
reader loop is a finding through libFuzzer's -timeout (fuzz/run.py sets it).
Seed corpus: fuzz/corpus/las/ (LAS 1.2, 1.3 and 1.4, LAZ 1.2 and 1.4, with VLRs and
EVLRs; fuzz/make_corpus.py writes them).
"""
import os
import random
import struct
import tempfile

import atheris
import numpy as np  # noqa: F401  (imported before instrumenting: coverage of our code, not numpy's)

with atheris.instrument_imports(include=["laspy", "splat_tracer", "fuzz"]):
    import laspy  # noqa: F401  (instrumented: its header and VLR parsing are half of the reader)
    from fuzz import reading

PATH = os.path.join(tempfile.mkdtemp(prefix="fuzz_las_"), "input.las")

# The public header's fields (ASPRS LAS 1.4, little-endian): (offset, struct format).
HEADER = [(24, "B"), (25, "B"), (94, "<H"), (96, "<I"), (100, "<I"), (104, "B"), (105, "<H"), (107, "<I"),
          (111, "<I"), (115, "<I"), (131, "<d"), (139, "<d"), (147, "<d"), (155, "<d"), (163, "<d"), (171, "<d"),
          (179, "<d"), (187, "<d"), (227, "<Q"), (235, "<Q"), (243, "<I"), (247, "<Q"), (255, "<Q")]
VLR = [(0, "<H"), (2, "16s"), (18, "<H"), (20, "<H")]     # reserved, user ID, record ID, length after header
EVLR = [(0, "<H"), (2, "16s"), (18, "<H"), (20, "<Q")]    # the same with a 64-bit length
USER_IDS = [b"laszip encoded", b"LASF_Projection", b"LASF_Spec", b"copc", b""]
RECORD_IDS = [22204, 34735, 34736, 34737, 2111, 2112, 100, 0, 65535]
FLOATS = [0.0, -0.0, float("nan"), float("inf"), float("-inf"), 5e-324, 1e-308, 1e308, 1.0, -1.0, 1e-9, 1e9]


def _value(rng: random.Random, fmt: str, old):
    """A value for a field: one of the edge values of its type, or near its old value."""
    if fmt.endswith("s"):
        size = int(fmt[:-1])
        return rng.choice(USER_IDS + [bytes(rng.randrange(256) for _ in range(size))])[:size].ljust(size, b"\0")
    if fmt.endswith("d"):
        return rng.choice(FLOATS + [old * rng.choice([-1, 2, 0.5, 1e6, 1e-6])])
    bits = 8 * struct.calcsize(fmt)
    top = (1 << bits) - 1
    choices = [0, 1, 2, 3, top, top - 1, 1 << (bits - 1), old + 1, old - 1, old * 2, rng.randrange(top + 1)]
    if bits >= 16:
        choices += RECORD_IDS + [54, 227, 235, 375]  # IDs the readers look for, header and VLR sizes
    if bits >= 32:
        choices += [1 << 16, 1 << 31, 1 << 32]
    return min(max(rng.choice(choices), 0), top)


def _put(data: bytearray, at: int, fmt: str, rng: random.Random) -> None:
    size = struct.calcsize(fmt)
    if at < 0 or at + size > len(data):
        return
    (old,) = struct.unpack_from(fmt, data, at)
    struct.pack_into(fmt, data, at, _value(rng, fmt, old))


def _records(data: bytes) -> tuple[list, list]:
    """(at, length) of each VLR (walked from the header's end) and EVLR (from the 1.4 start)."""
    vlrs, evlrs = [], []
    header_size, offset, count = struct.unpack_from("<HII", data, 94)
    at = header_size
    for _ in range(min(count, 16)):
        if at + 54 > min(offset, len(data)):
            break
        length = struct.unpack_from("<H", data, at + 20)[0]
        vlrs.append((at, length))
        at += 54 + length
    if len(data) >= 247 and data[25] >= 4:
        start, count = struct.unpack_from("<QI", data, 235)
        at = start
        for _ in range(min(count, 16)):
            if at + 60 > len(data):
                break
            length = struct.unpack_from("<Q", data, at + 20)[0]
            evlrs.append((at, length))
            at += 60 + length
    return vlrs, evlrs


@atheris.instrument_func
def mutate_fields(data: bytearray, rng: random.Random) -> bytearray:
    vlrs, evlrs = _records(data)
    target = rng.randrange(4)
    if target == 0 or not (vlrs or evlrs):
        at, fmt = rng.choice(HEADER)
        _put(data, at, fmt, rng)
    elif target == 1:  # a VLR's or EVLR's header
        (at, _), fields = rng.choice([(v, VLR) for v in vlrs] + [(e, EVLR) for e in evlrs])
        field, fmt = rng.choice(fields)
        _put(data, at + field, fmt, rng)
    elif target == 2:  # bytes of a VLR's or EVLR's body (the LAZ VLR's compressor, chunk size, items)
        at, length = rng.choice([(a + 54, n) for a, n in vlrs] + [(a + 60, n) for a, n in evlrs])
        for _ in range(rng.randint(1, 4)):
            k = at + rng.randrange(max(min(length, len(data) - at), 1))
            if k < len(data):
                data[k] = rng.choice([0, 1, 0x7F, 0x80, 0xFF, rng.randrange(256)])
    else:  # a point record's field
        offset, record_length = struct.unpack_from("<I", data, 96)[0], struct.unpack_from("<H", data, 105)[0]
        if record_length and offset < len(data):
            at = offset + record_length * rng.randrange(max((len(data) - offset) // record_length, 1))
            _put(data, at + rng.randrange(record_length), rng.choice(["B", "<H", "<I", "<d"]), rng)
    return data


def mutate(data: bytes, max_size: int, seed: int) -> bytes:
    rng = random.Random(seed)
    if len(data) >= 227 and data.startswith(b"LASF") and rng.random() < 0.5:
        out = bytearray(data)
        for _ in range(rng.randint(1, 3)):
            out = mutate_fields(out, rng)
        return bytes(out[:max_size])
    return atheris.Mutate(data, max_size)


if __name__ == "__main__":
    reading.fuzz(PATH, mutate)
