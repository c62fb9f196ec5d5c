"""Fuzz harness: E57 files through the importer (sniff, memory check, e57.read_e57, preparation).

    python -m fuzz.fuzz_e57 [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

Each input is a file's bytes, imported by fuzz/reading.py's import_file; its contract holds
(imported and sane, or refused with CloudFileError; MemoryError for a refused allocation).
An E57 file is 1024-byte pages, each ending in the CRC-32C of its first 1020 bytes, which
libE57 checks: a byte changed anywhere is refused there. So the mutator works on the
file's logical bytes (the pages without their checksums) and writes the checksums again:
mostly on its XML (a number put to 0, -1, 2^32, 2^63, 1e308, NaN...: record counts, file
offsets, poses, limits, bounds; an element's type or precision changed; an element
deleted or repeated; libFuzzer's byte mutations within the XML, whose length the header
is told), else on the file header's fields or bytes of the binary sections; one in ten
mutations is a raw byte mutation, checksums left wrong. libE57 and pye57 are native
(pybind11): the search is guided by the reader's Python side and this structure only.
libE57 runs in this process, as it does in Blender: a crash inside it is a finding (a
deadly signal, its input written), as is a file that makes it loop (fuzz/run.py's -timeout).
Seed corpus: fuzz/corpus/e57/ (pye57-written scans: colour, intensity, poses, invalid
states; fuzz/make_corpus.py writes them).
"""
import os
import random
import re
import struct
import tempfile

import atheris
import numpy as np  # noqa: F401  (imported before instrumenting: coverage of our code, not numpy's)

with atheris.instrument_imports(include=["splat_tracer", "fuzz", "pye57"]):
    import pye57  # noqa: F401  (its Python side: the scan header, the pose)
    from fuzz import reading

PATH = os.path.join(tempfile.mkdtemp(prefix="fuzz_e57_"), "input.e57")
PAGE, LOGICAL = 1024, 1020  # E57 page: 1020 bytes of data and their CRC-32C (big-endian)
SIGNATURE = b"ASTM-E57"
# The file header (logical bytes 0..47): signature, major, minor, physical length, XML
# physical offset, XML logical length, page size.
FILE_HEADER = struct.Struct("<8sIIQQQQ")
HEADER_FIELDS = [(8, "<I"), (12, "<I"), (16, "<Q"), (24, "<Q"), (32, "<Q"), (40, "<Q")]
NUMBERS = [b"0", b"-1", b"1", b"2", b"255", b"65535", b"2147483647", b"4294967295", b"4294967296",
           b"9223372036854775807", b"-9223372036854775808", b"18446744073709551615", b"1e308", b"-1e308",
           b"1e-320", b"nan", b"inf", b"-inf", b"0.5", b"3.4e38", b"1e30", b"48", b"1024"]
TYPES = [b"Float", b"Integer", b"ScaledInteger", b"String", b"Structure", b"Vector", b"CompressedVector",
         b"Blob"]
NUMBER = re.compile(rb"(?<=[>\"])[-+]?[0-9][0-9.eE+-]*(?=[<\"])")
TYPE = re.compile(rb"(?<=type=\")\w+(?=\")|(?<=precision=\")\w+(?=\")")
ELEMENT = re.compile(rb"<(\w+)[^<>]*?(/>|>)")


def _crc32c_table() -> list:
    table = []
    for n in range(256):
        c = n
        for _ in range(8):
            c = (c >> 1) ^ (0x82F63B78 if c & 1 else 0)
        table.append(c)
    return table


CRC_TABLE = _crc32c_table()


def crc32c(data: bytes) -> int:
    crc = 0xFFFFFFFF
    for byte in data:
        crc = CRC_TABLE[(crc ^ byte) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def unpage(data: bytes) -> bytearray:
    return bytearray(b"".join(data[k:k + LOGICAL] for k in range(0, len(data), PAGE)))


def page(logical: bytes) -> bytes:
    padded = logical + b"\0" * (-len(logical) % LOGICAL)
    pages = [padded[k:k + LOGICAL] for k in range(0, len(padded), LOGICAL)]
    return b"".join(p + struct.pack(">I", crc32c(p)) for p in pages)


def _element_span(xml: bytes, rng: random.Random):
    """(start, end) of a random element of the XML, its children included."""
    tags = list(ELEMENT.finditer(xml))
    if not tags:
        return None
    tag = rng.choice(tags)
    if tag.group(2) == b"/>":
        return tag.start(), tag.end()
    close = xml.find(b"</" + tag.group(1) + b">", tag.end())
    return None if close < 0 else (tag.start(), close + len(tag.group(1)) + 3)


@atheris.instrument_func
def mutate_xml(xml: bytes, rng: random.Random) -> bytes:
    how = rng.randrange(6)
    if how <= 1:  # a number: a count, an offset, a pose, a limit, a bound
        numbers = list(NUMBER.finditer(xml))
        if numbers:
            m = rng.choice(numbers)
            return xml[:m.start()] + rng.choice(NUMBERS) + xml[m.end():]
    elif how == 2:
        types = list(TYPE.finditer(xml))
        if types:
            m = rng.choice(types)
            new = rng.choice(TYPES + [b"single", b"double", b""])
            return xml[:m.start()] + new + xml[m.end():]
    elif how in (3, 4):  # an element deleted, or repeated after itself
        span = _element_span(xml, rng)
        if span:
            a, b = span
            return xml[:a] + xml[b:] if how == 3 else xml[:b] + xml[a:b] + xml[b:]
    return atheris.Mutate(xml, max(len(xml) * 2, 64))


@atheris.instrument_func
def mutate(data: bytes, max_size: int, seed: int) -> bytes:
    rng = random.Random(seed)
    if not data.startswith(SIGNATURE) or len(data) % PAGE or len(data) < PAGE or rng.random() < 0.1:
        return atheris.Mutate(data, max_size)  # raw bytes: checksums mostly wrong, refused where read
    logical = unpage(data)
    _, _, _, _, xml_physical, xml_length, _ = FILE_HEADER.unpack_from(logical)
    xml_at = xml_physical // PAGE * LOGICAL + xml_physical % PAGE
    target = rng.random()
    if target < 0.7 and FILE_HEADER.size <= xml_at and xml_at + xml_length <= len(logical):
        # the XML is written last: what follows it is the last page's padding
        xml = mutate_xml(bytes(logical[xml_at:xml_at + xml_length]), rng)
        logical = logical[:xml_at] + xml
        struct.pack_into("<Q", logical, 32, len(xml))  # the header's XML logical length
        struct.pack_into("<Q", logical, 16, -(-len(logical) // LOGICAL) * PAGE)  # and physical file length
    elif target < 0.85:
        at, fmt = rng.choice(HEADER_FIELDS)
        size = struct.calcsize(fmt)
        (old,) = struct.unpack_from(fmt, logical, at)
        top = (1 << (8 * size)) - 1
        value = rng.choice([0, 1, old + 1, old - 1, old + LOGICAL, top, 1 << (8 * size - 1), rng.randrange(top + 1)])
        struct.pack_into(fmt, logical, at, min(max(value, 0), top))
    else:  # bytes of the binary sections (compressed vector headers, their data packets)
        end = min(xml_at, len(logical))
        for _ in range(rng.randint(1, 4)):
            if end > FILE_HEADER.size:
                logical[rng.randrange(FILE_HEADER.size, end)] = rng.choice([0, 1, 0x7F, 0x80, 0xFF, rng.randrange(256)])
    out = page(bytes(logical))
    return out if len(out) <= max_size else atheris.Mutate(data, max_size)


if __name__ == "__main__":
    reading.fuzz(PATH, mutate)
