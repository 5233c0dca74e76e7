"""The decoder's column stores (imupipe.io.decode): a column in memory grows by doubling one
mapping, a spilled one keeps each row's shape, and the time bases' non-increasing steps are
counted across batch boundaries too."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from imupipe.io import decode


def test_a_column_in_memory_doubles_its_mapping_and_keeps_every_row() -> None:
    column = decode._Column()
    batch = 1 << 17  # 1 MiB of float64 a batch
    for k in range(40):
        column.add(np.full(batch, float(k)))
    assert len(column.map) == 2 * decode._FIRST_MAP_BYTES  # 32 MiB doubled once, not 40 MiB
    rows = column.join()
    assert rows.shape == (40 * batch,) and rows[batch * 39] == 39.0 and rows[-1] == 39.0


def test_a_spilled_column_keeps_the_shape_of_its_rows(tmp_path: Path) -> None:
    column = decode._SpilledColumn(tmp_path / "rows.bin")
    column.add(np.arange(6, dtype=np.int32).reshape(3, 2))
    column.add(np.arange(6, 10, dtype=np.int32).reshape(2, 2))
    column.seal()
    np.testing.assert_array_equal(column.join(), np.arange(10).reshape(5, 2))


def test_non_increasing_steps_are_counted_across_batches() -> None:
    steps = decode._Steps()
    steps.add(np.array([1, 2, 3]))
    steps.add(np.array([3, 4]))  # the same stamp either side of the batch boundary
    assert steps.count == 1
    steps.add(np.array([2]))  # backwards across the boundary
    assert steps.count == 2
    steps.add(np.array([10, 11]))  # forwards: not counted
    assert steps.count == 2 and steps.nonzero
