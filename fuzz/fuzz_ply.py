"""Fuzz harness: the PLY reader and the import preparation behind it.

    python -m fuzz.fuzz_ply [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

Each input is a file's bytes: splat_tracer.pointcloud.readers.ply.read_ply reads it from a temporary file.
The contract: a file is imported or refused with CloudFileError, nothing else. When it is
read, what it gives must be sane (fuzz/reading.py's check_cloud: finite positions, unit
normals, colours in 0..1, positive radii, distinct positions) and prepare.prepare (frame,
outliers, radii) must accept it or refuse it with CloudFileError, giving finite float32
offsets and positive radii (check_prepared). Any other
exception, or a broken promise, is a finding: atheris stops and writes the input.
Seed corpus: fuzz/corpus/ply/ (small valid and broken files).
"""
import os
import sys
import tempfile

import atheris
import numpy as np  # imported before instrumenting: coverage is wanted for our code, not numpy's

with atheris.instrument_imports():
    import plyfile  # noqa: F401  (instrumented: its parser is half of the reader)
    from fuzz.reading import check_cloud, check_prepared
    from splat_tracer.pointcloud import prepare
    from splat_tracer.pointcloud.cloud import CloudFileError
    from splat_tracer.pointcloud.readers import ply

PATH = os.path.join(tempfile.mkdtemp(prefix="fuzz_ply_"), "input.ply")


def TestOneInput(data: bytes) -> None:
    with open(PATH, "wb") as f:
        f.write(data)
    try:
        cloud = ply.read_ply(PATH)
    except CloudFileError:
        return
    check_cloud(cloud)
    try:
        prepared = prepare.prepare(cloud, PATH, workers=1)
    except CloudFileError:
        return
    check_prepared(prepared)


if __name__ == "__main__":
    atheris.Setup(sys.argv, TestOneInput)
    atheris.Fuzz()
