"""A JSONL message over what one record holds: `record` names the file and line, exits 1,
and loses nothing stored (found by an attack, issue 16: the error named no line)."""

from __future__ import annotations

import json

import pytest

from cclogfs.cli import main
from cclogfs.ingest import format_line
from cclogfs.store.format import MAX_RECORD_RAW

MAX_MESSAGE_TEXT = MAX_RECORD_RAW - 16  # count (4 bytes), stamp and length (12), the text


def test_a_17_mib_message_is_named_by_its_line(tmp_path, capsys, shared_data):
    store = tmp_path / "store"
    first = tmp_path / "odom.jsonl"
    assert main(["convert", str(shared_data("nav2_turtlebot.mcap")), "-o", str(first), "--topic", "/odom"]) == 0
    assert main(["record", str(first), "--store", str(store)]) == 0
    capsys.readouterr()
    assert main(["cat", str(store)]) == 0
    before = capsys.readouterr().out

    big = json.dumps({"data": "x" * (17 << 20)})
    assert len(big) > MAX_MESSAGE_TEXT
    source = tmp_path / "big.jsonl"
    source.write_text(format_line("/a", 1, "{}") + format_line("/a", 2, big) + format_line("/a", 3, "{}"))
    assert main(["record", str(source), "--store", str(store), "--append"]) == 1
    err = capsys.readouterr().err
    assert f"big.jsonl, line 2: the message is {len(big)} bytes of JSON, over the {MAX_MESSAGE_TEXT} bytes" in err
    assert "Traceback" not in err

    assert main(["fsck", str(store)]) == 0
    capsys.readouterr()
    assert main(["cat", str(store), "--topic", "/odom"]) == 0
    assert capsys.readouterr().out == before  # nothing stored before is lost or changed
    assert main(["cat", str(store), "--topic", "/a"]) == 0
    assert capsys.readouterr().out == format_line("/a", 1, "{}")  # the line before it, as for any bad line

    # exit 4: a line left out (b073d7e), the output short of the input
    assert main(["record", str(source), "--store", str(store), "--append", "--on-error", "skip"]) == 4
    assert "skipped: " in capsys.readouterr().err


@pytest.mark.parametrize("segment_records", [16384, 2])  # the split window in the active or a sealed segment
def test_info_counts_a_split_window_once(tmp_path, capsys, segment_records):
    # A window over the 16 MiB record limit is stored as several records (flag PART on each
    # but the last, FORMAT.md); `info` counted each record as a window (issue 16).
    import cclogfs

    big = [(10 + i, json.dumps({"i": i, "data": "x" * (7 << 20)})) for i in range(3)]  # 21 MiB: 2 records
    with cclogfs.open_store(tmp_path / "s", create=True, segment_records=segment_records) as store:
        store.put_window("/a", [(1, "{}")])
        assert store.put_window("/a", big).records == 2
        store.put_window("/a", [(99, "{}")])
        store.put_window("/b", [(5, "{}")])
    assert main(["info", "--json", str(tmp_path / "s")]) == 0
    streams = json.loads(capsys.readouterr().out)["streams"]
    assert (streams["/a"]["windows"], streams["/a"]["records"], streams["/a"]["messages"]) == (3, 4, 5)
    assert (streams["/b"]["windows"], streams["/b"]["records"]) == (1, 1)
    assert main(["info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "/a: its 3 windows are stored as 4 records" in out and "/b: its" not in out
