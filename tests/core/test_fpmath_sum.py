"""`fpmath.add_reduce` adds in one fixed order under every NumPy: chunks of REDUCE_CHUNK
values in order, each by NumPy's pairwise sum. NumPy 2.3 and later sum a long array as one
pairwise tree instead, which moved every long run by a few ulp per iteration."""

from __future__ import annotations

import numpy as np
import pytest

from core.fpmath import PAIRWISE_BLOCK, REDUCE_CHUNK, add_reduce, add_reduce_rows, add_reducer


def pairwise(a: list[float]) -> float:
    """NumPy's pairwise_sum, written from its description in plain Python floats."""
    n = len(a)
    if n < 8:
        res = 0.0
        for v in a:
            res += v
        return res
    if n <= PAIRWISE_BLOCK:
        r = a[:8]
        i = 8
        while i < n - n % 8:
            r = [r[j] + a[i + j] for j in range(8)]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for v in a[i:]:
            res += v
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return pairwise(a[:n2]) + pairwise(a[n2:])


def reference_sum(a: np.ndarray) -> float:
    """Chunks of REDUCE_CHUNK values in order, each by `pairwise`, added one after another."""
    values = a.tolist()
    total = 0.0
    for start in range(0, len(values), REDUCE_CHUNK):
        total += pairwise(values[start:start + REDUCE_CHUNK])
    return total


@pytest.mark.parametrize("n", [1, 7, 8, 9, 127, 128, 129, 1000, 8191, 8192, 8193, 16384,
                               24577, 50001])
def test_add_reduce_is_chunked_pairwise_bit_for_bit(n: int) -> None:
    rng = np.random.default_rng(n)
    a = rng.standard_normal(n) * 10.0 ** rng.integers(-6, 7, n)
    assert add_reduce(a).hex() == reference_sum(a).hex()


@pytest.mark.parametrize("n", [1, 9, 300, 8192, 8193, 20000])
def test_add_reducer_sums_like_add_reduce_and_returns_a_float(n: int) -> None:
    rng = np.random.default_rng(n + 1)
    a = rng.standard_normal(n) * 10.0 ** rng.integers(-6, 7, n)
    got = add_reducer(n)(a)
    assert type(got) is float
    assert got.hex() == add_reduce(a).hex() == reference_sum(a).hex()


def test_add_reduce_rows_sums_each_row_like_add_reduce() -> None:
    rng = np.random.default_rng(7)
    for n in (300, 20000):
        m = rng.standard_normal((4, n)) * 1e3
        assert [v.hex() for v in add_reduce_rows(m)] == [add_reduce(row).hex() for row in m]


def test_add_reduce_of_a_2d_array_sums_it_in_c_order() -> None:
    m = np.random.default_rng(3).standard_normal((5, 4001))
    assert add_reduce(m) == reference_sum(m.ravel())


def test_add_reduce_differs_from_one_pairwise_tree_on_this_array() -> None:
    """The orders do differ (else the test above would not tell them apart): one pairwise
    tree over 100003 values ends elsewhere than the chunked order."""
    a = np.random.default_rng(2).standard_normal(100003)
    assert add_reduce(a) != pairwise(a.tolist())
