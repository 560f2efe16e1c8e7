"""A ROS 2 sqlite3 bag whose .db3 files hold fewer messages than its metadata.yaml counts
is said as lost (exit 4), not recorded in part with exit 0: a bag split in two files whose
metadata.yaml lists only the first (the second's 259 messages were left out without a word),
or a .db3 that lost rows. Found by the attack of l-atk8."""

import sqlite3

import pytest

from cclogfs.cli import main
from tests.cli.test_damaged_inputs import ros2_bag_copy


def split_bag(shared_data, tmp_path):
    """tf_example/ as two .db3 files of 259 messages each, metadata.yaml listing the first."""
    bag = ros2_bag_copy(shared_data, tmp_path, "bag")
    whole = bag / "tf_example.db3"
    for name, keep in (("bag_0.db3", "id <= 259"), ("bag_1.db3", "id > 259")):
        (bag / name).write_bytes(whole.read_bytes())
        with sqlite3.connect(bag / name) as db:
            db.execute(f"DELETE FROM messages WHERE NOT ({keep})")
    whole.unlink()
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("tf_example.db3", "bag_0.db3"))
    return bag


@pytest.mark.parametrize("command", ["record", "convert"])
def test_a_db3_file_metadata_does_not_list_is_said_as_lost(shared_data, tmp_path, capsys, command):
    bag = split_bag(shared_data, tmp_path)
    out = ["--store", str(tmp_path / "s")] if command == "record" else ["-o", str(tmp_path / "o.jsonl")]
    assert main([command, str(bag), *out]) == 4
    err = capsys.readouterr().err
    assert "metadata.yaml counts 518 messages" in err and "hold 259" in err and "bag_1.db3" in err, err


def test_a_db3_that_lost_rows_is_said_as_lost(shared_data, tmp_path, capsys):
    bag = ros2_bag_copy(shared_data, tmp_path, "bag")
    with sqlite3.connect(bag / "tf_example.db3") as db:
        db.execute("DELETE FROM messages WHERE id % 10 = 0")
    assert main(["convert", str(bag), "-o", str(tmp_path / "o.jsonl")]) == 4
    err = capsys.readouterr().err
    assert "metadata.yaml counts 518 messages" in err and "hold 467" in err, err
    # a topic selection is held against its own topics' counts
    assert main(["convert", str(bag), "-o", str(tmp_path / "s.jsonl"), "--topic", "/tf_static"]) == 0


def test_a_listed_db3_that_is_missing_is_said_as_lost(shared_data, tmp_path, capsys):
    # the bag reader refuses the bag; the salvage reader read the other .db3 without a word, exit 0
    bag = split_bag(shared_data, tmp_path)
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("- bag_0.db3", "- bag_0.db3\n  - bag_1.db3"))
    (bag / "bag_0.db3").unlink()
    assert main(["record", str(bag), "--store", str(tmp_path / "s")]) == 4
    err = capsys.readouterr().err
    assert "metadata.yaml counts 518 messages" in err and "hold 259" in err and "bag_0.db3, listed in it, is missing" in err, err
