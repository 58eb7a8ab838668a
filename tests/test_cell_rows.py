"""The cell-ordered tables of the NumPy path (spherevm.constraints.cell_rows): every cell's entries
in order across its rows, padding with its head, continuation rows folded back onto their cells."""
import numpy as np
import pytest

from spherevm.constraints.cell_rows import fold, row_table


@pytest.mark.parametrize("overlap, odd", [(0, False), (1, False), (1, True)])
def test_rows_hold_each_cells_entries_in_order(overlap, odd):
    rng = np.random.default_rng(3)
    counts = rng.integers(1, 16, size=200)
    entries = rng.integers(0, 10_000, size=counts.sum())
    heads = -1 - np.arange(len(counts))                    # never an entry
    rows = row_table(counts, entries, heads, overlap=overlap, odd=odd)
    table, owner = rows["table"], rows["owner"]
    width = len(table) - 1
    assert width % 2 == 1 or not odd
    assert table.shape[1] == len(counts) + len(owner) and np.all(np.diff(owner) >= 0)
    start = np.concatenate(([0], np.cumsum(counts)))
    for c, k in enumerate(counts):                          # a test: a loop over cells is fine here
        mine = [c] + list(len(counts) + np.flatnonzero(owner == c))
        assert np.all(table[0, mine] == heads[c])
        body = [table[1:, r] for r in mine]
        got = np.concatenate([body[0]] + [b[overlap:] for b in body[1:]])
        real = got[got != heads[c]]
        assert np.array_equal(real, entries[start[c]:start[c + 1]])
        assert np.all(got[len(real):] == heads[c])          # padding only after the entries
        assert len(mine) == 1 or k > width                  # no row more than needed


def test_fold_adds_continuation_rows_to_their_cells():
    rng = np.random.default_rng(4)
    counts = rng.integers(1, 20, size=50)
    rows = row_table(counts, np.arange(counts.sum()), np.arange(50))
    values = rng.normal(size=(4, rows["table"].shape[1]))
    expected = values[:, :50].copy()
    np.add.at(expected, (slice(None), rows["owner"]), values[:, 50:])
    assert len(rows["owner"]) > 0
    for c in (1, 3, 4):
        got = fold(values[:c].copy(), rows)
        assert np.allclose(got, expected[:c], rtol=0, atol=1e-14)      # the same sums, another order
