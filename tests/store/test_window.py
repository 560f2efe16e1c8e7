"""cclogfs.store.window: the read handle a query returns, and the receipt a put returns."""

import pytest

import cclogfs
from cclogfs.errors import CorruptionError, InvalidInputError, StoreError
from cclogfs.store import RecordFlag, Replacement
from cclogfs.store.format import Reason
from helpers import SEG, make_store, patch_header, record_at

MESSAGES = [(5, '{"x":1}'), (9, '{"x":"é"}'), (12, "[1,2]")]


def test_receipt_describes_what_was_put(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        r = store.put_window("/odom", MESSAGES, {"run": 3})
        (w,) = store.query()
    assert (r.seq, r.name, r.start_ns, r.end_ns, r.count) == (0, "/odom", 5, 12, 3)
    assert r.stored_bytes == w.stored_bytes > 0 and r.raw_bytes > 0
    with pytest.raises(AttributeError):
        r.seq = 1  # frozen: a receipt is a record of the past


def test_window_reads_back_exactly_what_was_put(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True, codec="zstd") as store:
        store.put_window("/odom", MESSAGES, {"run": 3})
        (w,) = store.query()
        assert (w.name, w.seq, w.start_ns, w.end_ns, w.count) == ("/odom", 0, 5, 12, 3)
        assert list(w.messages()) == MESSAGES
        assert list(w.messages()) == MESSAGES  # a second read gives the same
        assert w.meta == {"run": 3} and w.codec_config["id"] == "zstd"
        assert w.flags == 0 and w.aged is None
        assert w.segment_path.endswith(SEG) and w.offset > 0
        assert repr(w) == "Window('/odom', seq=0, 5..12, count=3)"


def test_aged_is_what_the_meta_says_only_when_the_flag_is_set(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True, sync_every_ms=None) as store:
        with pytest.raises(InvalidInputError, match="'aged' is reserved"):
            store.put_window("/a", [(1, "{}")], {"aged": "not really"})  # only compaction says so
        store.put_window("/a", [(1, "{}")], {"k": 1})
        store.put_window("/a", [(2, '{"v":1.25}')])
        store.seal()
        store.rewrite(lambda w: Replacement([(2, '{"v":1.2}')], {"aged": {"abs": 0.1}}, flags=RecordFlag.AGED)
                      if w.seq == 1 else None)  # fmt: skip
        plain, rounded = sorted(store.query(), key=lambda w: w.seq)
        assert plain.meta == {"k": 1} and plain.aged is None and plain.flags == 0
        assert rounded.flags & RecordFlag.AGED and rounded.aged == {"abs": 0.1}
        assert list(rounded.messages()) == [(2, '{"v":1.2}')]


def test_a_window_of_a_closed_store_says_to_query_again(tmp_path):
    make_store(tmp_path / "s", n=1)
    with cclogfs.open_store(tmp_path / "s") as store:
        (w,) = store.query()
    with pytest.raises(StoreError, match="is closed.*query again"):
        list(w.messages())


def test_a_window_read_before_close_keeps_its_record(tmp_path):
    make_store(tmp_path / "s", n=1)
    with cclogfs.open_store(tmp_path / "s") as store:
        (w,) = store.query()
        first = list(w.messages())
    assert list(w.messages()) == first and len(first) == 20


def test_a_header_codec_that_disagrees_with_the_config_is_corruption(tmp_path):
    make_store(tmp_path / "s", n=2, codec="zstd")
    seg, off, _ = record_at(tmp_path / "s", 1)
    patch_header(seg, off, codec=99)  # header CRC re-sealed: only the codec check can see it
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        w = [w for w in store.query() if w.seq == 1][0]
        with pytest.raises(CorruptionError, match=f"offset {off}.*codec 99") as err:
            list(w.messages())
        assert err.value.reason == Reason.CODEC_MISMATCH
