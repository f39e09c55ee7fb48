"""GrowingRows: rows appended one at a time read back as the array np.array would stack."""

import numpy as np

from estimators.slam.growing_rows import GrowingRows


def test_rows_read_back_as_the_stacked_list_through_growth_assign_and_copy() -> None:
    rng = np.random.default_rng(0)
    rows, matrices, flags = GrowingRows((3,)), GrowingRows(None), GrowingRows((), bool)
    listed = []
    for _ in range(40):  # past the first capacity (16) twice
        row = rng.normal(size=3)
        rows.append(row)
        matrices.append(np.outer(row, row))
        flags.append(bool(row[0] > 0))
        listed.append(row)
    np.testing.assert_array_equal(rows.rows, np.array(listed))
    np.testing.assert_array_equal(matrices.rows, np.array([np.outer(r, r) for r in listed]))
    np.testing.assert_array_equal(flags.rows, np.array([r[0] > 0 for r in listed]))
    assert flags.rows.dtype == bool and len(rows) == 40
    kept = rows.copy()
    rows.assign(rows.rows[::2])
    np.testing.assert_array_equal(rows.rows, np.array(listed[::2]))
    np.testing.assert_array_equal(kept.rows, np.array(listed))  # the copy is independent
    rows.append(np.ones(3))
    assert len(rows) == 21 and len(kept) == 40
