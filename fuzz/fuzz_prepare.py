"""Fuzz harness: the import preparation on fuzzed point arrays.

    python -m fuzz.fuzz_prepare [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

The input bytes are decoded (atheris.FuzzedDataProvider) into a point cloud as
ply.read_ply hands it over -- finite float64 positions of any magnitude (clusters,
outliers, near-duplicates, values up to 1e300), unit normals, optional colours and
radii -- and passed to:
- first_of_duplicates, on the raw positions with NaN, inf and -0.0 mixed in: must
  give a (N,) bool mask keeping the first of every set of equal rows;
- prepare.bulk_mask: (N,) bool, never raises;
- prepare.prepare (frame, outliers, k-NN radii, closed guess), with a fuzzed k and
  Outliers: Drop or Keep: accepts with finite float32 offsets, a float32-exact origin and
  positive finite radii, or refuses with CloudFileError. Anything else is a finding.
Seed corpus: fuzz/corpus/prepare/ (raw byte strings; any bytes decode to some cloud).
"""
import sys

import atheris
import numpy as np  # imported before instrumenting: coverage is wanted for our code, not numpy's

with atheris.instrument_imports():
    from splat_tracer.pointcloud import prepare
    from splat_tracer.pointcloud.cloud import CloudFileError, PointCloud
    from splat_tracer.pointcloud.neighbours import first_of_duplicates
    from splat_tracer.pointcloud.readers import ply

SPECIAL = [0.0, -0.0, 1.0, -1.0, 1e-300, 1e-45, 1e7, -1e7, 1e15, 1e16, 1e300, -1e300, 3.4e38, 0.1, 1e-7]


def positions(fdp: atheris.FuzzedDataProvider, n: int) -> np.ndarray:
    mode = fdp.ConsumeIntInRange(0, 3)
    if mode == 0:  # arbitrary finite values
        vals = [fdp.ConsumeRegularFloat() for _ in range(3 * n)]
    elif mode == 1:  # special values
        vals = [SPECIAL[fdp.ConsumeIntInRange(0, len(SPECIAL) - 1)] for _ in range(3 * n)]
    elif mode == 2:  # a cluster at a fuzzed place, a few points elsewhere
        centre = [fdp.ConsumeRegularFloat() for _ in range(3)]
        spread = 10.0 ** fdp.ConsumeFloatInRange(-12, 12)
        vals = [centre[k % 3] + spread * fdp.ConsumeFloatInRange(-1, 1) for k in range(3 * n)]
    else:  # a grid (many equal spacings, exact ties in the k-NN query)
        step = 10.0 ** fdp.ConsumeIntInRange(-8, 8)
        vals = [step * fdp.ConsumeIntInRange(-3, 3) for _ in range(3 * n)]
    return np.array(vals, np.float64).reshape(n, 3)


def TestOneInput(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    n = fdp.ConsumeIntInRange(0, 80)
    pos = positions(fdp, n)

    raw = pos.copy()
    if n and fdp.ConsumeBool():  # NaN, inf and -0.0 where they hurt the duplicate search
        raw[fdp.ConsumeIntInRange(0, n - 1), fdp.ConsumeIntInRange(0, 2)] = [np.nan, np.inf, -0.0][fdp.ConsumeIntInRange(0, 2)]
    keep = first_of_duplicates(raw)
    assert keep.shape == (n,) and keep.dtype == bool and (n == 0 or keep[0])

    pos = pos[first_of_duplicates(pos)]  # read_ply merges duplicates
    pos = pos[np.isfinite(pos).all(axis=1)]
    m = len(pos)
    if m:
        mask = prepare.bulk_mask(pos)
        assert mask.shape == (m,) and mask.dtype == bool
    nrm = np.array([fdp.ConsumeFloatInRange(-1, 1) for _ in range(3 * m)]).reshape(m, 3) + [0.0, 0.0, 1e-3]
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).astype(np.float32)
    radii = None
    if fdp.ConsumeBool():
        radii = np.array([10.0 ** fdp.ConsumeFloatInRange(-30, 30) for _ in range(m)], np.float32)
        radii = np.where(np.isfinite(radii) & (radii > 0), radii, np.float32(1.0))
    colours = np.full((m, 4), 0.5, np.float32) if fdp.ConsumeBool() else None
    cloud = PointCloud(pos, nrm, colours, radii, merged_duplicates=fdp.ConsumeIntInRange(0, 3),
                       rows=np.arange(m))
    k = fdp.ConsumeIntInRange(1, 30)
    try:
        prepared = prepare.prepare(cloud, "fuzzed.ply", k=k, drop_outliers=fdp.ConsumeBool(), workers=1)
    except CloudFileError:
        return
    kept = len(prepared.cloud)
    assert 0 < kept <= m
    assert prepared.local.shape == (kept, 3) and prepared.local.dtype == np.float32
    assert np.isfinite(prepared.local).all()
    assert np.isfinite(prepared.origin).all() and (prepared.origin.astype(np.float32) == prepared.origin).all()
    assert prepared.radii.shape == (kept,) and (np.isfinite(prepared.radii) & (prepared.radii > 0)).all()
    prepared.notes(k)


if __name__ == "__main__":
    atheris.Setup(sys.argv, TestOneInput)
    atheris.Fuzz()
