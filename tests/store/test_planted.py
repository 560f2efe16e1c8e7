"""Each planted bug (cclogfs.store.planted) makes a check of this suite fail: the checks can
fail. Every case runs the check without the bug (it passes), then with it (it must fail)."""

import functools
import tracemalloc

import pytest
import zstandard

import cclogfs
from bench.crash import check_workloads
from cclogfs.errors import CclogError
from cclogfs.store import planted
import test_corruption as corruption
import test_crash as crash
import test_crash_compaction as crash_compaction
import test_symlinks as symlinks

CASES = [
    ("torn-tail", corruption.test_damage_below_the_synced_point_is_kept_declared_and_never_hidden),
    ("torn-tail", corruption.test_damage_in_the_last_synced_group_is_not_a_torn_tail),
    ("seal-no-fsync", crash.test_seal_after_a_crash_seals_only_durable_data),
    ("seal-no-fsync", crash.test_records_recovered_after_a_crash_are_made_durable_by_the_next_sync),
    ("seal-no-fsync", crash.test_a_reopen_after_a_failed_fsync_rewrites_what_it_cannot_prove_durable),
    ("trust-index", corruption.test_a_forged_index_is_caught_on_read),
    ("skip-bad-record", crash.test_reordered_writes_do_not_leave_a_hole),
    ("trust-length", corruption.test_bad_length_is_caught_before_allocating),
    ("early-delete", crash_compaction.test_a_fixed_rewrite_and_drop_checks_every_image_in_every_mode),
    ("follow-symlink", symlinks.test_a_symlinked_lock_is_refused_and_its_target_untouched),
    ("follow-symlink", symlinks.test_an_active_segment_that_is_a_symlink_is_refused),
    ("follow-symlink", symlinks.test_an_unsealed_segment_symlink_to_a_damaged_file_is_not_truncated),
]


def a_zstd_bomb_is_read_within_a_bounded_memory(tmp_path):
    """A window whose zstd frame declares (and holds) 64 MiB, in a record whose checksummed
    header says 1 KiB: reading it is an error, having allocated about the stated size."""
    bomb = zstandard.ZstdCompressor(level=1).compress(b"\0" * (64 << 20))
    with cclogfs.open_store(tmp_path / "s", create=True, codec="zstd", sync_every_ms=None) as store:
        codec = store.codecs.default
        real = type(codec).compress
        type(codec).compress = lambda self, raw: bomb  # a writer forging the payload
        try:
            store.put_window("/a", [(1, "{}")])
        finally:
            type(codec).compress = real
        (window,) = store.query()
        tracemalloc.start()
        try:
            with pytest.raises(CclogError):
                list(window.messages())
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert peak < 8 << 20, f"reading a 1 KiB window allocated {peak} bytes"


CASES.append(("trust-zstd-size", a_zstd_bomb_is_read_within_a_bounded_memory))


@pytest.mark.parametrize("bug, test", CASES, ids=[f"{b}-{t.__name__}" for b, t in CASES])
def test_a_planted_bug_is_caught(bug, test, tmp_path, monkeypatch, capsys):
    if "capsys" in test.__code__.co_varnames[: test.__code__.co_argcount]:
        test = functools.partial(test, capsys=capsys)
    (tmp_path / "passes").mkdir()
    (tmp_path / "fails").mkdir()
    test(tmp_path / "passes")  # without the bug
    monkeypatch.setattr(planted, "BUGS", {bug})
    with pytest.raises((Exception, pytest.fail.Exception)):  # any failure of the test is the point
        test(tmp_path / "fails")


# Workloads in which each bug the crash states must catch shows: two unsynced writes (a
# reordering can leave a hole), a seal after an unsynced put, a drop, an age step, a kill.
CRASH_WORKLOADS = [("big", "big", "big"), ("put", "seal"), ("seal", "drop"), ("put", "seal", "age"),
                   ("big", "kill", "put")]  # fmt: skip
CRASH_CAUGHT = ["skip-bad-record", "no-dir-fsync", "rename-before-sync", "early-delete", "seal-no-fsync"]


def test_the_crash_states_pass_without_a_planted_bug():
    tally = check_workloads(CRASH_WORKLOADS)
    assert tally.states > 1000 and tally.violations == []


@pytest.mark.parametrize("bug", CRASH_CAUGHT)
def test_the_crash_states_catch_a_planted_bug(bug, monkeypatch):
    monkeypatch.setattr(planted, "BUGS", {bug})
    tally = check_workloads(CRASH_WORKLOADS)
    assert tally.violations, f"{bug}: {tally.states} crash states and no violation"
