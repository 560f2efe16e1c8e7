"""Each planted bug (cclogfs.store.planted) makes a test of this suite fail: the tests can fail."""

import pytest

from cclogfs.store import planted
import test_corruption as corruption
import test_crash as crash

CASES = [
    ("torn-tail", corruption.test_damage_below_the_synced_point_is_kept_declared_and_never_hidden),
    ("torn-tail", corruption.test_damage_in_the_last_synced_group_is_not_a_torn_tail),
    ("seal-no-fsync", crash.test_seal_after_a_crash_seals_only_durable_data),
    ("seal-no-fsync", crash.test_records_recovered_after_a_crash_are_made_durable_by_the_next_sync),
    ("seal-no-fsync", crash.test_a_reopen_after_a_failed_fsync_rewrites_what_it_cannot_prove_durable),
    ("trust-index", corruption.test_a_forged_index_is_caught_on_read),
]


@pytest.mark.parametrize("bug, test", CASES, ids=[f"{b}-{t.__name__}" for b, t in CASES])
def test_a_planted_bug_is_caught(bug, test, tmp_path, monkeypatch):
    test(tmp_path / "passes")  # without the bug
    monkeypatch.setattr(planted, "BUGS", {bug})
    with pytest.raises((Exception, pytest.fail.Exception)):  # any failure of the test is the point
        test(tmp_path / "fails")
