"""open_store refuses a group-commit interval its timer thread cannot wait: NaN spun the thread
at full CPU, inf and 1e300 killed it with an OverflowError, so no group was committed on
time (found by the attack of l-atk8)."""

import math

import pytest

from cclogfs.errors import InvalidInputError
from cclogfs.store import open_store


@pytest.mark.parametrize("value", [math.nan, math.inf, 1e300, -1.0])
def test_open_store_refuses_a_sync_interval_no_timer_can_wait(tmp_path, value):
    with pytest.raises(InvalidInputError, match="sync_every_ms"):
        open_store(tmp_path / "s", create=True, sync_every_ms=value)
    assert not (tmp_path / "s").exists()
