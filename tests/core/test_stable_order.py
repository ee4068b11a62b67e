"""`csr.stable_order` sorts integer keys by 16-bit radix passes: the permutation must be
NumPy's stable argsort exactly (the gather tables and the Z-order renumbering rely on that
order for their bits), for keys of one, two, three and four digits and every integer dtype
the callers pass."""

from __future__ import annotations

import numpy as np
import pytest

from core.mesh.csr import bincount_csr, stable_order

CASES = [(n, dtype) for n in (2, 255, 65536, 65537, 1 << 20, 1 << 31, 1 << 32, 1 << 40, 1 << 63)
         for dtype in (np.int64, np.uint64, np.int32, np.uint32) if n - 1 <= np.iinfo(dtype).max]


@pytest.mark.parametrize(("n", "dtype"), CASES)
def test_stable_order_is_numpys_stable_argsort(n, dtype):
    rng = np.random.default_rng(n % 1000)
    for size in (2, 3, 1000, 70000):
        keys = rng.integers(0, n, size, dtype=np.uint64).astype(dtype)
        keys[: size // 3] = keys[0]  # many ties: the stable order is what is tested
        got = stable_order(keys, n)
        assert got.dtype == np.int64
        assert np.array_equal(got, np.argsort(keys, kind="stable"))


def test_stable_order_of_nothing_and_of_one_key():
    assert stable_order(np.zeros(0, dtype=np.int64), 5).size == 0
    assert stable_order(np.array([3]), 5).tolist() == [0]
    assert stable_order(np.zeros(4, dtype=np.int64), 1).tolist() == [0, 1, 2, 3]


def test_bincount_csr_lists_each_keys_positions_in_ascending_order():
    keys = np.array([70000, 3, 70000, 0, 3, 65536, 0], dtype=np.int64)
    ptr, pos = bincount_csr(keys, 70001)
    rows = {k: pos[ptr[k]:ptr[k + 1]].tolist() for k in (0, 3, 65536, 70000)}
    assert rows == {0: [3, 6], 3: [1, 4], 65536: [5], 70000: [0, 2]}
    assert ptr[-1] == keys.size
