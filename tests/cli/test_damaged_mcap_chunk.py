"""l-atk6: an MCAP file with one damaged chunk mid-file was refused whole with "Chunk
checksum mismatch." and no offset; with a chunk cut out entirely it was recorded with exit 0
(or "it holds no messages") although its statistics counted the lost messages."""

import json

from mcap.reader import make_reader

import cclogfs
from cclogfs.cli import main
from cclogfs.runs import list_runs

HOSPITAL = "long/slamfail_hospital.mcap"  # 4 zstd chunks of /odom, 5,486 messages


def chunk_indexes(path):
    with open(path, "rb") as f:
        return make_reader(f).get_summary().chunk_indexes


def stored(store) -> int:
    with cclogfs.open_store(store, readonly=True) as s:
        return s.streams()["/odom"]["messages"]


def flip_chunk(shared_data, tmp_path):
    """The file with one byte flipped in the middle of its second chunk; that chunk."""
    data = bytearray(shared_data(HOSPITAL).read_bytes())
    chunk = chunk_indexes(shared_data(HOSPITAL))[1]
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    (bad := tmp_path / "bad.mcap").write_bytes(bytes(data))
    return bad, chunk


def chunk_count(path, chunk) -> int:
    with open(path, "rb") as f:
        return sum(1 for _, _, m in make_reader(f).iter_messages()
                   if chunk.message_start_time <= m.log_time <= chunk.message_end_time)  # fmt: skip


def test_a_damaged_chunk_is_named_by_its_offset(shared_data, tmp_path, capsys):
    bad, chunk = flip_chunk(shared_data, tmp_path)
    capsys.readouterr()
    assert main(["record", str(bad), "--store", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert f"{bad}: the chunk at byte {chunk.chunk_start_offset:,}" in err, err
    assert "Chunk checksum mismatch" in err and "--on-error skip" in err and "Traceback" not in err


def test_on_error_skip_keeps_the_other_chunks_and_says_what_was_lost(shared_data, tmp_path, capsys):
    bad, chunk = flip_chunk(shared_data, tmp_path)
    lost = chunk_count(shared_data(HOSPITAL), chunk)
    assert 0 < lost < 5486
    capsys.readouterr()
    assert main(["record", str(bad), "--store", str(tmp_path / "s"), "--on-error", "skip"]) == 4
    err = capsys.readouterr().err
    assert f"the chunk at byte {chunk.chunk_start_offset:,} ({lost:,} messages" in err, err
    assert stored(tmp_path / "s") == 5486 - lost
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        (run,) = list_runs(s)
        assert f"byte {chunk.chunk_start_offset:,}" in run.end["input_lost"]
    # What was kept is the undamaged chunks' messages, byte for byte as from the whole file.
    assert main(["record", str(shared_data(HOSPITAL)), "--store", str(tmp_path / "whole")]) == 0
    assert main(["cat", str(tmp_path / "s")]) == 0
    ours = capsys.readouterr().out.splitlines()
    assert main(["cat", str(tmp_path / "whole")]) == 0
    whole = capsys.readouterr().out.splitlines()
    gone = [line for line in whole if chunk.message_start_time <= json.loads(line)["stamp_ns"] <= chunk.message_end_time]
    assert len(gone) == lost and ours == [line for line in whole if line not in set(gone)]


def test_a_chunk_cut_out_is_counted_against_the_statistics(shared_data, tmp_path, capsys):
    data = shared_data(HOSPITAL).read_bytes()
    chunk = chunk_indexes(shared_data(HOSPITAL))[1]
    spliced = tmp_path / "spliced.mcap"
    spliced.write_bytes(data[: chunk.chunk_start_offset] + data[chunk.chunk_start_offset + chunk.chunk_length:])
    lost = chunk_count(shared_data(HOSPITAL), chunk)
    capsys.readouterr()
    assert main(["record", str(spliced), "--store", str(tmp_path / "s")]) == 4  # was 0
    err = capsys.readouterr().err
    assert f"its statistics count {lost:,} more (/odom {lost:,})" in err, err
    assert stored(tmp_path / "s") == 5486 - lost


def test_the_only_chunk_cut_out_says_the_statistics_not_no_messages(shared_data, tmp_path, capsys):
    data = shared_data("nav2_turtlebot.mcap").read_bytes()
    (chunk,) = chunk_indexes(shared_data("nav2_turtlebot.mcap"))
    spliced = tmp_path / "spliced.mcap"
    spliced.write_bytes(data[: chunk.chunk_start_offset] + data[chunk.chunk_start_offset + chunk.chunk_length:])
    capsys.readouterr()
    assert main(["record", str(spliced), "--store", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert "its statistics count 8,197 more" in err and "it holds no messages" not in err, err


def json_mcap(shared_data, tmp_path, capsys):
    """nav2_turtlebot as a plain JSON MCAP (what export --mcap --encoding json writes); its chunk indexes."""
    assert main(["record", str(shared_data("nav2_turtlebot.mcap")), "--store", str(tmp_path / "whole")]) == 0
    out = tmp_path / "j.mcap"
    assert main(["export", str(tmp_path / "whole"), "--mcap", str(out), "--encoding", "json"]) == 0
    capsys.readouterr()
    return out, chunk_indexes(out)


def test_a_damaged_chunk_of_a_json_mcap_is_named_by_its_offset(shared_data, tmp_path, capsys):
    """l-left8: mcap's reader said only "decompression error: Destination buffer is too small"."""
    good, chunks = json_mcap(shared_data, tmp_path, capsys)
    assert len(chunks) > 2
    chunk = chunks[1]
    data = bytearray(good.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    (bad := tmp_path / "bad.mcap").write_bytes(bytes(data))
    assert main(["record", str(bad), "--store", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    lost = chunk_count(good, chunk)
    assert f"{bad}: the chunk at byte {chunk.chunk_start_offset:,} ({lost:,} messages logged" in err, err
    assert "--on-error skip" in err and "Traceback" not in err
    assert main(["convert", str(bad), "-o", str(tmp_path / "x.jsonl")]) == 1
    assert f"the chunk at byte {chunk.chunk_start_offset:,}" in capsys.readouterr().err
    # --on-error skip keeps the other chunks, says what was lost and exits 4, as for a ROS 2 MCAP.
    assert main(["record", str(bad), "--store", str(tmp_path / "skip"), "--on-error", "skip"]) == 4
    assert f"the chunk at byte {chunk.chunk_start_offset:,} ({lost:,} messages" in capsys.readouterr().err
    with cclogfs.open_store(tmp_path / "skip", readonly=True) as s:
        assert sum(v["messages"] for k, v in s.streams().items() if not k.startswith("/cclog")) == 8197 - lost


def test_a_json_mcap_is_read_as_mcap_read_it(shared_data, tmp_path, capsys):
    """The chunk-by-chunk reader gives the messages in mcap's order: the store is the same."""
    good, _ = json_mcap(shared_data, tmp_path, capsys)
    assert main(["record", str(good), "--store", str(tmp_path / "s")]) == 0
    capsys.readouterr()
    assert main(["cat", str(tmp_path / "s")]) == 0
    ours = capsys.readouterr().out
    assert main(["cat", str(tmp_path / "whole")]) == 0
    assert ours == capsys.readouterr().out
