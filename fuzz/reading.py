"""What the reader harnesses (fuzz_ply, fuzz_las, fuzz_e57, fuzz_text, fuzz_pcd) check of a file's import.

import_file(path) takes a file the way the importer does (importer.load): its format sniffed
from its first bytes, the points its header declares checked against the free memory, the
reader chosen by readers.read_cloud, then the preparation (frame, outliers, radii). The
contract: the file is imported or refused with CloudFileError, or a refused allocation raises
MemoryError; nothing else escapes. What is read must be sane (check_cloud) and what is
prepared too (check_prepared). Any other exception or a broken promise is a finding.
Import this module inside atheris.instrument_imports() (the harnesses do), after numpy:
coverage is wanted for our code, not numpy's.
"""
from __future__ import annotations

import numpy as np

from splat_tracer.pointcloud import importer, prepare, readers
from splat_tracer.pointcloud.cloud import CloudFileError, PointCloud

OUTCOMES = (CloudFileError, MemoryError)  # a file refused, naming it; an allocation refused


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
    if cloud.scanners is not None:
        assert cloud.scanners.shape == (n, 3) and np.isfinite(cloud.scanners).all()
    for name, values in cloud.attributes.items():
        assert values.shape == (n,), name
    assert len(np.unique(cloud.positions + 0.0, axis=0)) == n  # duplicates were merged


def check_prepared(prepared: prepare.PreparedCloud) -> None:
    m = len(prepared.cloud)
    assert prepared.local.shape == (m, 3) and prepared.local.dtype == np.float32
    assert np.isfinite(prepared.local).all() and np.isfinite(prepared.origin).all()
    assert prepared.cloud.normals.shape == (m, 3)
    assert prepared.radii.shape == (m,) and (np.isfinite(prepared.radii) & (prepared.radii > 0)).all()


def import_bytes(data: bytes, path: str) -> None:
    """A fuzzed input, written to `path`, through import_file (the harnesses' one step)."""
    with open(path, "wb") as f:
        f.write(data)
    import_file(path)


def fuzz(path: str, mutate) -> None:
    """A reader harness's run: libFuzzer's inputs (changed by `mutate`, the harness's own
    custom mutator) imported through import_bytes at `path`."""
    import sys

    import atheris

    atheris.Setup(sys.argv, lambda data: import_bytes(data, path), custom_mutator=mutate)
    atheris.Fuzz()


def import_file(path: str) -> None:
    """The file through the importer's steps, checked (see the module's text)."""
    try:
        importer.check_memory(path, readers.sniff(path), importer.ImportOptions(workers=1))
        cloud = readers.read_cloud(path)
    except OUTCOMES:
        return
    check_cloud(cloud)
    try:
        prepared = prepare.prepare(cloud, path, workers=1)
    except OUTCOMES:
        return
    check_prepared(prepared)
