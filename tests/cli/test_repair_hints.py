"""The damage hints of `record` and `info` name the fsck run that clears the damage, and
following one literally leaves the store clean. Before, both said "run `cclog fsck
--repair`" for any damage: for a record that failed its checksum that run ends in "damage
left" (exit 4) and the next recording said the same again; only --discard-damaged clears
it. A segment header that lost no record is mended by plain --repair."""

import json
import re

import pytest

from cclogfs.cli import main
from conftest import shared_data_file
from helpers import SEG, flip, record_at, zero


@pytest.fixture
def tf_store(tmp_path):
    store = tmp_path / "s"
    assert main(["record", str(shared_data_file("tf_example.bag")), "--store", str(store)]) == 0
    return store


def hint_of(text):
    """The fsck command a hint names, as argv."""
    found = re.search(r"run `cclog (fsck [^`]*)`", text)
    assert found, text
    return found.group(1).split()


def follow(store, text, capsys):
    argv = hint_of(text)
    assert main([argv[0], str(store), *argv[1:]]) in (0, 1), capsys.readouterr()
    capsys.readouterr()
    assert main(["fsck", str(store)]) == 0, capsys.readouterr().out
    capsys.readouterr()


def more(tmp_path, i):
    src = tmp_path / f"in{i}.jsonl"
    src.write_text(json.dumps({"topic": "/b", "stamp_ns": 10**12 + i, "msg": {"x": i}}) + "\n")
    return str(src)


@pytest.mark.parametrize("damage, fix", [("record", "--discard-damaged"), ("header", None)])
def test_following_the_hint_clears_the_damage(tf_store, tmp_path, capsys, damage, fix):
    if damage == "record":  # a record of the bag's /tf fails its checksum: seq 1 lost
        path, off, length = record_at(tf_store, 1)
        flip(path, off + length - 5)
    else:  # the active segment's header, after a clean close: no record lost
        zero(tf_store / SEG, 0, 32)
    capsys.readouterr()
    assert main(["record", more(tmp_path, 0), "--store", str(tf_store)]) == 0  # the writer names it
    warning = capsys.readouterr().err
    assert "holds damage below the synced point" in warning
    assert main(["info", str(tf_store)]) == 3
    said = [line for line in capsys.readouterr().out.splitlines() if line.startswith("DAMAGE")]
    assert len(said) == 1 and hint_of(warning) == hint_of(said[0]), said
    assert (fix is None) == ("--discard-damaged" not in said[0]), said
    follow(tf_store, warning, capsys)
    assert main(["record", more(tmp_path, 1), "--store", str(tf_store)]) == 0
    assert "damage" not in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["play", "--rate", "1000"], ["plot", "--out", "p.png"],
                                  ["compact", "--older-than", "1s", "--error", "1e-3"]])  # fmt: skip
def test_a_command_without_skip_damaged_names_those_that_have_it(tf_store, tmp_path, capsys, argv):
    """The store's refusal ends "or read the intact windows with --skip-damaged": play, plot
    and compact have no such flag ("unrecognized arguments" when the user followed it)."""
    path, off, length = record_at(tf_store, 1)
    flip(path, off + length - 5)
    assert main(["record", more(tmp_path, 0), "--store", str(tf_store)]) == 0  # the writer names it
    capsys.readouterr()
    args = [argv[0], str(tf_store), *(str(tmp_path / a) if a == "p.png" else a for a in argv[1:])]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "windows lost to damage" in err and "with --skip-damaged" not in err, err
    assert "`cclog cat --skip-damaged` or `cclog export --skip-damaged`" in err, err
    assert main(["cat", str(tf_store)]) == 1  # cat has the flag: named as it is
    assert "or read the intact windows with --skip-damaged" in capsys.readouterr().err
