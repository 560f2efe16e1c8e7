"""A file whose run stopped at a bad line, fixed in place and recorded again, is refused
without --append: the first run's messages were stored twice (12,197 lines for 8,197), exit
0, without a word; its new content hid it from the same-content check (found by the attack
of l-atk8)."""

from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.store import open_store


def test_a_file_fixed_after_its_run_stopped_is_refused_without_append(tmp_path, capsys):
    lines = [format_line("/a", i, f'{{"i": {i}}}') for i in range(300)]
    src, store = tmp_path / "run.jsonl", tmp_path / "s"
    src.write_text("".join(lines[:200]) + '{"topic": "/a", "stamp_ns": 200, "msg": {\n' + "".join(lines[201:]))
    assert main(["record", str(src), "--store", str(store), "--chunk", "50"]) == 1
    assert "line 201: invalid JSON" in capsys.readouterr().err
    src.write_text("".join(lines))  # the bad line fixed
    assert main(["record", str(src), "--store", str(store), "--chunk", "50"]) == 1
    err = capsys.readouterr().err
    assert "as run 1" in err and "error" in err and "200 messages kept" in err and "--append" in err, err
    with open_store(store, readonly=True) as s:
        assert s.streams()["/a"]["messages"] == 200  # nothing stored twice
    assert main(["record", str(src), "--store", str(store), "--chunk", "50", "--append"]) == 0


def test_a_file_rewritten_after_a_run_that_finished_is_recorded(tmp_path, capsys):
    # a log file rewritten with a new run under the same name is new data, not a retry
    src, store = tmp_path / "run.jsonl", tmp_path / "s"
    src.write_text("".join(format_line("/a", i, "{}") for i in range(10)))
    assert main(["record", str(src), "--store", str(store)]) == 0
    src.write_text("".join(format_line("/a", i, "{}") for i in range(100, 120)))
    assert main(["record", str(src), "--store", str(store)]) == 0


def test_a_bag_directory_that_has_grown_since_its_run_is_refused(shared_data, tmp_path, capsys):
    # a ROS 2 bag recorded while its recorder was still writing (a .db3 added since) stored
    # the first file's 259 messages twice, exit 0: the grown-file check was for files only
    import sqlite3

    from tests.cli.test_damaged_inputs import ros2_bag_copy

    whole = ros2_bag_copy(shared_data, tmp_path, "whole")
    bag = tmp_path / "bag"
    bag.mkdir()
    for name, keep in (("bag_0.db3", "id <= 259"), ("bag_1.db3", "id > 259")):
        (tmp_path / name).write_bytes((whole / "tf_example.db3").read_bytes())
        with sqlite3.connect(tmp_path / name) as db:
            db.execute(f"DELETE FROM messages WHERE NOT ({keep})")
    (tmp_path / "bag_0.db3").rename(bag / "bag_0.db3")
    store = tmp_path / "s"
    assert main(["record", str(bag), "--store", str(store)]) == 0
    (tmp_path / "bag_1.db3").rename(bag / "bag_1.db3")
    capsys.readouterr()
    assert main(["record", str(bag), "--store", str(store)]) == 1
    err = capsys.readouterr().err
    assert "as run 1" in err and "twice" in err and "--append" in err, err
    assert main(["record", str(bag), "--store", str(store), "--append"]) == 0
