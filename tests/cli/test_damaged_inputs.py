"""Issue 12 item 7: a ROS 1 bag or MCAP file cut short is recorded and converted as far as
it can be read, what was lost is said, the exit code is 4; a failed run leaves no empty store."""


import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Bag1Writer

import cclogfs
from cclogfs.cli import main
from cclogfs.runs import hidden_by_default, list_runs


def many_chunk_bag(src, dst):
    """tf_example.bag rewritten uncompressed in 4 KiB chunks, as `rosbag record` writes long runs."""
    with AnyReader([src]) as reader, Bag1Writer(dst) as writer:
        writer.chunk_threshold = 4096
        conns = {}
        for con, t, raw in reader.messages():
            if con.id not in conns:
                conns[con.id] = writer.add_connection(con.topic, con.msgtype, typestore=reader.typestore)
            writer.write(conns[con.id], t, raw)
    return dst


def many_chunk_mcap(src, dst):
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = McapWriter(out, chunk_size=8192)
        w.start(profile="ros2", library="test")
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        chans = {cid: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id])
                 for cid, c in summary.channels.items()}  # fmt: skip
        for _, ch, m in reader.iter_messages(log_time_order=False):
            w.add_message(chans[ch.id], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    return dst


def cut(path, fraction):
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    return path


@pytest.mark.parametrize("kind", ["bag", "mcap"])
def test_truncated_inputs_keep_what_can_be_read(shared_data, tmp_path, capsys, kind):
    if kind == "bag":
        whole = many_chunk_bag(shared_data("tf_example.bag"), tmp_path / "whole.bag")
    else:
        whole = many_chunk_mcap(shared_data("nav2_turtlebot.mcap"), tmp_path / "whole.mcap")
    assert main(["convert", str(whole), "-o", str(tmp_path / "whole.jsonl")]) == 0
    full = (tmp_path / "whole.jsonl").read_text().splitlines(True)
    damaged = tmp_path / f"cut.{kind}"
    damaged.write_bytes(whole.read_bytes())
    cut(damaged, 0.6)
    capsys.readouterr()
    assert main(["convert", str(damaged), "-o", str(tmp_path / "cut.jsonl")]) == 4
    err = capsys.readouterr().err
    assert "damaged" in err and "could not be read" in err and f"({damaged.stat().st_size:,} bytes)" in err
    got = (tmp_path / "cut.jsonl").read_text().splitlines(True)
    # Most of the 60 % kept, and each kept message as the whole file gives it (same stamp, same text).
    assert 0.3 * len(full) < len(got) < len(full)
    assert sorted(got) == sorted(set(got) & set(full))
    assert main(["record", str(damaged), "--store", str(tmp_path / "s")]) == 4
    assert "damaged" in capsys.readouterr().err
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        kept = [t["messages"] for n, t in store.streams().items() if not hidden_by_default(n)]  # not the run's records
        assert sum(kept) == len(got)
        (run,) = list_runs(store)  # the run says what its input lost
    assert run.status == "done" and "damaged" in run.end["input_lost"] and run.kept == len(got)


def test_a_failed_run_leaves_no_empty_store(tmp_path, capsys):
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{oops\n')
    assert main(["record", str(bad), "--store", str(tmp_path / "s")]) == 1
    assert not (tmp_path / "s").exists()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(b"#ROSBAG V2.0\n" + bytes(10))  # nothing readable at all
    assert main(["record", str(cut), "--store", str(tmp_path / "s")]) != 0
    assert not (tmp_path / "s").exists()
    pre = tmp_path / "existing"
    with cclogfs.open_store(pre, create=True):
        pass
    assert main(["record", str(bad), "--store", str(pre)]) == 1
    assert pre.exists()  # not ours to remove


def test_a_bag_read_to_nothing_says_why(shared_data, tmp_path, capsys):
    """A bag whose definition names an unknown type: rosbags' reason, not "it holds no
    messages" (the salvage reader's report was dropped; found by an attack)."""
    data = shared_data("tf_example.bag").read_bytes()
    bad = tmp_path / "bad_def.bag"
    bad.write_bytes(data.replace(b"TransformStamped[] transforms", b"TransformStampex[] transforms"))
    for args in (["record", str(bad), "--store", str(tmp_path / "s")], ["convert", str(bad), "-o", str(tmp_path / "o.jsonl")]):
        assert main(args) == 1
        err = capsys.readouterr().err
        assert "TransformStampex' is unknown" in err and "holds no messages" not in err, err


def ros2_bag_copy(shared_data, tmp_path, name):
    """A copy of the real ROS 2 bag tf_example/ (shared data is read-only)."""
    src = shared_data("tf_example")
    dst = tmp_path / name
    dst.mkdir()
    for f in src.iterdir():
        (dst / f.name).write_bytes(f.read_bytes())
    return dst


def test_ros2_bag_without_metadata_is_read_whole(shared_data, tmp_path, capsys):
    bag = ros2_bag_copy(shared_data, tmp_path, "bag")
    assert main(["convert", str(bag), "-o", str(tmp_path / "whole.jsonl")]) == 0
    whole = (tmp_path / "whole.jsonl").read_text()
    (bag / "metadata.yaml").unlink()  # the recorder died before writing it
    capsys.readouterr()
    assert main(["convert", str(bag), "-o", str(tmp_path / "unindexed.jsonl")]) == 0
    assert "no metadata.yaml" in capsys.readouterr().err
    assert (tmp_path / "unindexed.jsonl").read_text() == whole  # every message, byte for byte
    assert main(["record", str(bag), "--store", str(tmp_path / "s")]) == 0
    assert "no metadata.yaml" in capsys.readouterr().err
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        kept = [t["messages"] for n, t in store.streams().items() if not hidden_by_default(n)]
    assert sum(kept) == len(whole.splitlines()) == 518


@pytest.mark.parametrize("fraction", [0.5, 0.7, 0.9])
@pytest.mark.parametrize("metadata", [True, False])
def test_truncated_ros2_db3_keeps_what_can_be_read(shared_data, tmp_path, capsys, fraction, metadata):
    bag = ros2_bag_copy(shared_data, tmp_path, "bag")
    assert main(["convert", str(bag), "-o", str(tmp_path / "whole.jsonl")]) == 0
    full = (tmp_path / "whole.jsonl").read_text().splitlines(True)
    cut(bag / "tf_example.db3", fraction)
    if not metadata:
        (bag / "metadata.yaml").unlink()
    capsys.readouterr()
    assert main(["convert", str(bag), "-o", str(tmp_path / "cut.jsonl")]) == 4
    err = capsys.readouterr().err
    assert "damaged" in err and "could not be read" in err and "message rows" in err
    got = (tmp_path / "cut.jsonl").read_text().splitlines(True)
    assert 0 < len(got) < len(full)
    assert set(got) <= set(full)  # none changed
    assert got == sorted(got, key=full.index)  # in the intact read's order
    assert main(["record", str(bag), "--store", str(tmp_path / "s")]) == 4
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        (run,) = list_runs(store)
    assert "damaged" in run.end["input_lost"] and run.kept == len(got)


def test_unreadable_ros2_db3_fails_and_leaves_no_store(shared_data, tmp_path, capsys):
    bag = ros2_bag_copy(shared_data, tmp_path, "bag")
    (bag / "metadata.yaml").unlink()
    db = bag / "tf_example.db3"
    db.write_bytes(db.read_bytes()[: 7 * 4096])  # the schema pages only: no message page left
    capsys.readouterr()
    assert main(["record", str(bag), "--store", str(tmp_path / "s")]) != 0
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and "tf_example.db3" in err
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("what", [b"Transform transform", b"/tf_static"])
def test_a_flip_in_an_mcap_summary_renames_nothing(shared_data, tmp_path, capsys, what):
    """Found by attack: the bag reader takes schemas and channels from an MCAP's summary
    section, which no chunk CRC covers. One flipped byte of a field name there (a CDR export
    of this project, recorded again) stored every /tf message with `tvansform` for
    `transform`, exit 0, not a word; one in a topic name moves messages to another topic.
    The footer's summary CRC catches it; the file is read record by record instead."""
    store = tmp_path / "s"
    assert main(["record", str(shared_data("tf_example.bag")), "--store", str(store)]) == 0
    whole = tmp_path / "whole.mcap"
    assert main(["export", str(store), "--mcap", str(whole)]) == 0
    assert main(["convert", str(whole), "-o", str(tmp_path / "whole.jsonl")]) == 0
    data = bytearray(whole.read_bytes())
    start = int.from_bytes(data[-37 + 1 + 8 : -37 + 1 + 16], "little")  # the footer's summary_start
    at = data.index(what, start) + 1
    data[at] ^= 0x04
    damaged = tmp_path / "flipped.mcap"
    damaged.write_bytes(bytes(data))
    capsys.readouterr()
    assert main(["convert", str(damaged), "-o", str(tmp_path / "flipped.jsonl")]) == 0
    err = capsys.readouterr().err
    assert f"{damaged}: its summary section (offset {start} " in err and "fails its CRC" in err, err
    assert "every message read (518)" in err, err
    assert (tmp_path / "flipped.jsonl").read_text() == (tmp_path / "whole.jsonl").read_text()
