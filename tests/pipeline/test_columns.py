"""splat_tracer/util/columns.py: the column-wise and blockwise passes give numpy's own answers."""
import numpy as np
import pytest

from splat_tracer.util import columns

RNG = np.random.default_rng(5)


def test_row_tests_and_bounds_match_numpy():
    a = RNG.normal(size=(1000, 3))
    a[3, 1], a[7, 2], a[9, 0] = np.nan, np.inf, -np.inf
    a[11] = 0.0
    np.testing.assert_array_equal(columns.finite_rows(a), np.isfinite(a).all(axis=1))
    np.testing.assert_array_equal(columns.nonzero_rows(a), (a != 0).any(axis=1))
    b = a[columns.finite_rows(a)]
    lo, hi = columns.bounds(b)
    np.testing.assert_array_equal(lo, b.min(axis=0))
    np.testing.assert_array_equal(hi, b.max(axis=0))
    np.testing.assert_array_equal(columns.rows_outside(b, lo + 0.5, hi - 0.5),
                                  ((b < lo + 0.5) | (b > hi - 0.5)).any(axis=1))


@pytest.mark.parametrize("threads", [1, 2])
def test_compress_is_boolean_indexing_in_blocks(threads):
    n = 3 * columns.BLOCK_ROWS + 123  # several blocks, the last one partial
    keep = RNG.random(n) > 0.3
    keep[:columns.BLOCK_ROWS] = False  # an empty block
    arrays = [RNG.normal(size=(n, 3)), None, RNG.integers(0, 9, n).astype(np.int32), RNG.random((n, 4), np.float32)]
    out = columns.compress(arrays, keep, threads)
    assert out[1] is None
    for a, o in zip(arrays, out):
        if a is not None:
            assert o.dtype == a.dtype
            np.testing.assert_array_equal(o, a[keep])


@pytest.mark.parametrize("drop", [0.0, 1e-4, 0.3, 1.0])
def test_compress_in_place_moves_the_kept_rows_to_the_front(drop):
    n = 3 * columns.BLOCK_ROWS + 123
    keep = RNG.random(n) >= drop
    keep[columns.BLOCK_ROWS + 5] = False  # a row dropped past the first block: the later ones move
    arrays = [RNG.normal(size=(n, 3)), None, RNG.integers(0, 9, n).astype(np.int32), RNG.random((n, 4), np.float32)]
    want = [None if a is None else a[keep] for a in arrays]
    mine = [None if a is None else a.copy() for a in arrays]
    out = columns.compress(mine, keep, in_place=True)
    for a, w, o in zip(mine, want, out):
        assert (o is None) == (w is None)
        if a is not None:
            np.testing.assert_array_equal(o, w)
            assert len(o) == 0 or np.shares_memory(o, a)  # no new array
    # an array that cannot be written (a broadcast) is copied: all of them are then
    fixed = np.broadcast_to(np.float64(7), (n,))
    out = columns.compress([mine[0][:n].copy(), fixed], keep, in_place=True)
    assert not np.shares_memory(out[1], fixed) and (out[1] == 7).all() and len(out[1]) == keep.sum()


def test_kept_rows_is_flatnonzero_in_int32():
    for n in (0, 5, 3 * columns.BLOCK_ROWS + 7):
        keep = RNG.random(n) > 0.4
        got = columns.kept_rows(keep)
        assert got.dtype == np.int32
        np.testing.assert_array_equal(got, np.flatnonzero(keep))


def test_in_blocks_covers_every_row_once_and_passes_errors_on():
    n = 5 * columns.BLOCK_ROWS + 7
    seen = np.zeros(n, np.int32)

    def mark(b, e):
        seen[b:e] += 1

    columns.in_blocks(mark, n, threads=2)
    assert (seen == 1).all()

    def fail(b, e):
        if b > 0:
            raise ValueError("block")

    with pytest.raises(ValueError, match="block"):
        columns.in_blocks(fail, n, threads=2)
    columns.in_blocks(mark, 0)  # nothing to do
