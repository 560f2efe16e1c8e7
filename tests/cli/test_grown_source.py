"""A file recorded once and recorded again after it grew (an appended JSONL log, a bag
still being written) is refused like the same content: its first messages would be stored
twice, exit 0, without a word (found by the attack of l-atk6). --append records it again."""

import json

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.runs import begin_run, earlier_run, list_runs, source_fingerprint


def lines(first, n):
    return "".join(json.dumps({"topic": "/odom", "stamp_ns": i, "msg": {"i": i}}) + "\n" for i in range(first, first + n))


def messages(store):
    with cclogfs.open_store(store, readonly=True) as s:
        return s.streams()["/odom"]["messages"]


def test_a_grown_file_is_refused_then_appended_with_append(tmp_path, capsys):
    log, store = tmp_path / "log.jsonl", str(tmp_path / "s")
    log.write_text(lines(0, 50))
    assert main(["record", str(log), "--store", store]) == 0
    with open(log, "a") as f:
        f.write(lines(50, 30))
    capsys.readouterr()
    assert main(["record", str(log), "--store", store]) == 1
    err = capsys.readouterr().err
    assert "it has grown since), as run 1" in err and "--append" in err and err.count("\n") == 1
    assert messages(store) == 50
    assert main(["record", str(log), "--store", store, "--append"]) == 0
    assert messages(store) == 130


def test_another_file_with_a_shorter_prefix_in_common_is_not_refused(tmp_path):
    a, b, store = tmp_path / "a.jsonl", tmp_path / "b.jsonl", str(tmp_path / "s")
    a.write_text(lines(0, 50))
    b.write_text(lines(0, 49) + lines(100, 10))  # shares 49 lines, not the whole of a
    assert main(["record", str(a), "--store", store]) == 0
    assert main(["record", str(b), "--store", store]) == 0


def test_a_run_fingerprinted_before_head_was_kept_still_counts_as_the_same_content(tmp_path):
    log = tmp_path / "log.jsonl"
    log.write_text(lines(0, 5))
    new = source_fingerprint(str(log))
    old = {k: v for k, v in new.items() if k != "head"}  # as versions before this one wrote it
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        begin_run(store, str(log), fingerprint=old, options={}).end(messages_kept=5)
        assert earlier_run(list_runs(store), new).number == 1


def test_a_store_inside_the_source_bag_directory_is_refused(tmp_path, capsys):
    """It wrote into the input and, the bag's fingerprint changing with each run, a second
    recording of the bag was not refused: every message stored twice, exit 0."""
    from cclogfs.sim import simulate

    simulate(seed=1, duration_s=5.0, rate_hz=20.0).write(tmp_path / "sim")
    bag = tmp_path / "sim" / "run"
    before = sorted(p.name for p in bag.iterdir())
    for store in (bag / "st", bag):
        assert main(["record", str(bag), "--store", str(store)]) == 1
        assert "is inside the source" in capsys.readouterr().err
    assert sorted(p.name for p in bag.iterdir()) == before


def test_record_reads_the_runs_once_to_check_its_source(tmp_path, monkeypatch):
    # It read the whole /cclog/runs stream four times before its first message: for the
    # same content, a grown file, a stopped run, and the new run's number.
    import cclogfs.runs

    log, store = tmp_path / "log.jsonl", str(tmp_path / "s")
    log.write_text(lines(0, 5))
    assert main(["record", str(log), "--store", store]) == 0
    reads = []
    real = cclogfs.runs.list_runs
    monkeypatch.setattr(cclogfs.runs, "list_runs", lambda store: reads.append(1) or real(store))
    log.write_text(lines(10, 5))  # another content: every check runs, none refuses
    assert main(["record", str(log), "--store", store]) == 0
    assert len(reads) == 1
    with cclogfs.open_store(store, readonly=True) as s:
        assert [r.number for r in real(s)] == [1, 2]


def _bag_copied_in_writing(shared_data, tmp_path):
    """tf_example.bag written again by rosbags' Writer (16 KiB chunks): its bytes when 300
    of its 518 messages were written, and once closed (the bag header record rewritten)."""
    from rosbags.rosbag1 import Reader, Writer

    with Reader(shared_data("tf_example.bag")) as reader:
        messages = list(reader.messages())
    path, conns = tmp_path / "w.bag", {}
    writer = Writer(path)
    writer.chunk_threshold = 16 << 10
    writer.open()
    for i, (c, stamp, raw) in enumerate(messages):
        if c.topic not in conns:
            conns[c.topic] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
        writer.write(conns[c.topic], stamp, raw)
        if i == 300:
            in_writing = path.read_bytes()
    writer.close()
    return in_writing, path.read_bytes()


def _db3_copied_in_writing(shared_data, tmp_path):
    """tf_example's messages written by rosbags' ROS 2 Writer (sqlite3): the .db3 when 300
    of them were committed, and once closed."""
    from rosbags.rosbag2 import Reader, Writer

    with Reader(shared_data("tf_example")) as reader:
        messages = list(reader.messages())
    path, conns = tmp_path / "w", {}
    writer = Writer(path, version=8)
    writer.open()
    for i, (c, stamp, raw) in enumerate(messages):
        if c.topic not in conns:
            conns[c.topic] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest,
                                                   offered_qos_profiles=c.ext.offered_qos_profiles)  # fmt: skip
        writer.write(conns[c.topic], stamp, raw)
        if i == 300:
            writer.storage.conn.commit()  # as rosbag2 commits as it goes
            in_writing = (path / "w.db3").read_bytes()
    writer.close()
    return in_writing, (path / "w.db3").read_bytes()


@pytest.mark.parametrize("make, name", [(_bag_copied_in_writing, "run.bag"), (_db3_copied_in_writing, "run.db3")])
def test_a_bag_recorded_in_writing_is_known_once_closed(shared_data, tmp_path, capsys, make, name):
    # Closing rewrites a ROS 1 bag's header record (index position, counts) and a .db3's
    # sqlite header and pages, so the first MiB differed: the 301 messages recorded from the
    # copy in writing were stored again with the closed bag, exit 0.
    in_writing, closed = make(shared_data, tmp_path)
    src, store = tmp_path / name, str(tmp_path / "s")
    src.write_bytes(in_writing)
    assert main(["record", str(src), "--store", store]) == 0
    kept = messages_in(store)
    assert 100 < kept < 518  # what was written out (a bag: its closed chunks)
    src.write_bytes(closed)
    capsys.readouterr()
    assert main(["record", str(src), "--store", store]) == 1
    err = capsys.readouterr().err
    assert "(it has grown since), as run 1" in err and "--append" in err and err.count("\n") == 1
    assert messages_in(store) == kept
    assert main(["record", str(src), "--store", store, "--append"]) == 0
    assert messages_in(store) == kept + 518


def test_another_bag_with_the_same_messages_is_not_refused(shared_data, tmp_path):
    # The head of a ROS 1 bag is its records past the bag header: tf_example.bag holds the
    # same messages in other chunks, so it is another recording.
    _in_writing, closed = _bag_copied_in_writing(shared_data, tmp_path)
    (tmp_path / "run.bag").write_bytes(closed)
    store = str(tmp_path / "s")
    assert main(["record", str(shared_data("tf_example.bag")), "--store", store]) == 0
    assert main(["record", str(tmp_path / "run.bag"), "--store", store]) == 0


def messages_in(store):
    with cclogfs.open_store(store, readonly=True) as s:
        return sum(st["messages"] for name, st in s.streams().items() if not name.startswith("/cclog/"))


def test_a_ros1_bag_head_stops_at_the_chunk_rosbag_still_has_open(shared_data, tmp_path):
    """rosbag's recorder writes a chunk's header with its sizes 0 (the `size` field and the
    data length) and its messages after it, filling the sizes in when the chunk closes: the
    head of a bag copied then is its chunks before that one, as they stay once closed."""
    import struct

    from cclogfs.growth import head

    _in_writing, closed = _bag_copied_in_writing(shared_data, tmp_path)
    chunks, pos = [], 13
    while pos < len(closed):
        (header_len,) = struct.unpack_from("<I", closed, pos)
        (data_len,) = struct.unpack_from("<I", closed, pos + 4 + header_len)
        if b"op=\x05" in closed[pos + 4:pos + 4 + header_len]:
            chunks.append((pos, header_len, data_len))
        pos += 8 + header_len + data_len
    pos, header_len, data_len = chunks[2]
    open_chunk = bytearray(closed[:pos + 8 + header_len + data_len // 2])
    size_at = open_chunk.index(b"size=", pos) + 5  # the chunk header's uncompressed size
    open_chunk[size_at:size_at + 4] = bytes(4)
    open_chunk[pos + 4 + header_len:pos + 8 + header_len] = bytes(4)  # its data length
    (tmp_path / "open.bag").write_bytes(open_chunk)
    (tmp_path / "closed.bag").write_bytes(closed)
    seen = len(open_chunk)
    assert head(str(tmp_path / "open.bag"), seen) == head(str(tmp_path / "closed.bag"), seen) is not None
    (tmp_path / "other.bag").write_bytes(closed[:chunks[1][0]] + bytes(seen - chunks[1][0]))
    assert head(str(tmp_path / "other.bag"), seen) != head(str(tmp_path / "closed.bag"), seen)
