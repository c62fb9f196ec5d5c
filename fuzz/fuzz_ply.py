"""Fuzz harness: the PLY reader and the import preparation behind it.

    python -m fuzz.fuzz_ply [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

Each input is a file's bytes: splat_tracer.pointcloud.readers.ply.read_ply reads it from a temporary file.
The contract: a file is imported or refused with CloudFileError, nothing else. When it is
read, what it gives must be sane (finite positions, unit normals, colours in 0..1, positive
radii, distinct positions) and prepare.prepare (frame, outliers, radii) must accept it or
refuse it with CloudFileError, giving finite float32 offsets and positive radii. Any other
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
    from splat_tracer.pointcloud import prepare
    from splat_tracer.pointcloud.cloud import CloudFileError, PointCloud
    from splat_tracer.pointcloud.readers import ply

PATH = os.path.join(tempfile.mkdtemp(prefix="fuzz_ply_"), "input.ply")


def check_cloud(cloud: PointCloud) -> None:
    n = len(cloud)
    assert n > 0 and cloud.positions.shape == (n, 3) and np.isfinite(cloud.positions).all()
    if cloud.normals is not None:  # None: the file has none, prepare() estimates them
        assert cloud.normals.shape == (n, 3)
        assert np.allclose(np.linalg.norm(cloud.normals, axis=1), 1.0, atol=1e-5)
    if cloud.colours is not None:
        assert cloud.colours.shape == (n, 4) and ((cloud.colours >= 0) & (cloud.colours <= 1)).all()
    if cloud.radii is not None:
        assert (np.isfinite(cloud.radii) & (cloud.radii > 0)).all()
    assert len(np.unique(cloud.positions + 0.0, axis=0)) == n  # duplicates were merged


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
    m = len(prepared.cloud)
    assert prepared.local.shape == (m, 3) and prepared.local.dtype == np.float32
    assert np.isfinite(prepared.local).all() and np.isfinite(prepared.origin).all()
    assert prepared.cloud.normals.shape == (m, 3)
    assert prepared.radii.shape == (m,) and (np.isfinite(prepared.radii) & (prepared.radii > 0)).all()


if __name__ == "__main__":
    atheris.Setup(sys.argv, TestOneInput)
    atheris.Fuzz()
