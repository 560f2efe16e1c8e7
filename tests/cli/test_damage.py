"""Issue 11: reads never return a partial answer silently; damage stays visible."""

import json

import cclogfs
from cclogfs.cli import main
from helpers import SEG, flip, make_store


def _damaged_active(path):
    """A cleanly closed store (one unsealed segment), one flipped byte in record seq 1."""
    recs = make_store(path, n=6)
    seq, off, length = recs[1]
    flip(path / SEG, off + length - 5)
    return off


def test_cat_refuses_a_partial_answer_then_skips_with_a_distinct_exit(tmp_path, capsys):
    # A reader takes the checkpointed records from the index the clean close wrote, as it
    # does a sealed segment's (issue 14): the damage is found when the record is read.
    off = _damaged_active(tmp_path / "s")
    assert main(["cat", str(tmp_path / "s")]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and f"{SEG}: record at offset {off}" in err
    assert "payload checksum mismatch" in err
    assert main(["cat", str(tmp_path / "s"), "--skip-damaged"]) == 3
    out, err = capsys.readouterr()
    assert sorted({json.loads(line)["msg"]["i"] for line in out.splitlines()}) == [0, 2, 3, 4, 5]
    assert "1 damaged windows" in err and f"offset {off}" in err


def test_damage_survives_a_further_write_in_fsck_and_info(tmp_path, capsys):
    _damaged_active(tmp_path / "s")
    for _ in range(2):
        assert main(["fsck", str(tmp_path / "s")]) == 1
        assert "damage below the synced point" in capsys.readouterr().out
        with cclogfs.open_store(tmp_path / "s") as store:  # the next recording
            store.put_window("/a", [(10_000, "1")])
    assert main(["info", str(tmp_path / "s")]) == 3
    assert "DAMAGE" in capsys.readouterr().out
    assert not list((tmp_path / "s").glob("*.tail-*"))


def test_damage_in_a_sealed_segment_can_be_skipped(tmp_path, capsys):
    # Item 2: cat used to fail at the first bad record with no way to read the rest.
    make_store(tmp_path / "s", n=9, segment_records=3)
    seg = tmp_path / "s" / "00000000000000000003.seg"
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        (w,) = [w for w in store.query() if w.seq == 4]
    flip(seg, w.offset + w.stored_bytes - 5)
    assert main(["cat", str(tmp_path / "s")]) == 1
    assert "offset" in capsys.readouterr().err
    assert main(["cat", str(tmp_path / "s"), "--skip-damaged"]) == 3
    out, err = capsys.readouterr()
    assert sorted({json.loads(line)["msg"]["i"] for line in out.splitlines()}) == [0, 1, 2, 3, 5, 6, 7, 8]
    assert "1 damaged windows" in err and f"offset {w.offset}" in err


def test_export_skips_damage_only_when_asked(tmp_path, capsys):
    _damaged_active(tmp_path / "s")
    assert main(["export", str(tmp_path / "s"), "--mcap", str(tmp_path / "o.mcap")]) == 1
    assert not (tmp_path / "o.mcap").exists()
    assert main(["export", str(tmp_path / "s"), "--mcap", str(tmp_path / "o.mcap"), "--skip-damaged"]) == 3
    assert (tmp_path / "o.mcap").exists() and "1 damaged windows" in capsys.readouterr().err


def test_fsck_reports_a_side_file_holding_intact_records(tmp_path, capsys):
    # Item 9: a `.seg.tail-N` side file of an older version holding intact records.
    recs = make_store(tmp_path / "s", n=4)
    data = (tmp_path / "s" / SEG).read_bytes()
    (tmp_path / "s" / f"{SEG}.tail-{recs[2][1]}").write_bytes(data[recs[2][1]:])
    (tmp_path / "s" / "notes.txt").write_text("x")
    assert main(["fsck", str(tmp_path / "s")]) == 1
    out = capsys.readouterr().out
    assert "hold 2 intact records" in out and "notes.txt" in out


def test_a_read_checks_the_record_against_its_index_entry(tmp_path, capsys):
    # Item 10: an index with a valid checksum but reversed offsets answered wrong data.
    from cclogfs.store.index import SegmentIndex

    make_store(tmp_path / "s", n=6, segment_records=3)
    idx = tmp_path / "s" / "00000000000000000000.idx"
    seg_size = (tmp_path / "s" / SEG).stat().st_size
    index = SegmentIndex.decode(idx.read_bytes(), 0, seg_size)
    e = index.entries
    rows = [(index.names[x[0]], *x[1:5], *y[5:7], x[7]) for x, y in zip(e, e[::-1])]  # offset, length of another
    idx.write_bytes(SegmentIndex.build(rows).encode(0, seg_size))
    assert main(["cat", str(tmp_path / "s")]) == 1
    assert "the time index says" in capsys.readouterr().err


def test_record_into_a_damaged_store_says_so_every_time(tmp_path, capsys):
    _damaged_active(tmp_path / "s")
    for i in range(2):  # two inputs: the same one again would be refused as recorded already
        (tmp_path / "in.jsonl").write_text(json.dumps({"topic": "/b", "stamp_ns": 10**12 + i, "msg": {"x": 1}}) + "\n")
        assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s")]) == 0
        assert "damage below the synced point" in capsys.readouterr().err
