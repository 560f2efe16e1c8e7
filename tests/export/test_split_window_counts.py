"""`cclog export` counts a window once however many records the store split it into (a
window over the 16 MiB record limit: each part but the last flagged PART), as `cclog info`
does, and says the records apart. Before, a keep-all recording of tuc_corridor in one
window (19 MiB of JSON, 2 records) exported as "2 windows" while info said 1."""

import json

import pytest

from cclogfs.cli import main
from conftest import shared_data_file

TUC_START = 1_700_000_000  # s: the TUC runs' relative clock starts here (../shared/data/README.md)


@pytest.fixture(scope="module")
def one_big_window(tmp_path_factory):
    store = tmp_path_factory.mktemp("big") / "s"
    src = str(shared_data_file("long/tuc_corridor.mcap"))
    assert main(["record", src, "--store", str(store), "--chunk", "100000"]) == 0
    return str(store)


def test_info_says_one_window_in_two_records(one_big_window, capsys):
    capsys.readouterr()
    assert main(["info", one_big_window, "--json"]) == 0
    odom = json.loads(capsys.readouterr().out)["streams"]["/odom"]
    assert (odom["windows"], odom["records"], odom["messages"]) == (1, 2, 22692)


@pytest.mark.parametrize("to", ["--mcap", "--rosbag2", "--parquet"])
def test_export_counts_the_window_once_and_its_records_apart(one_big_window, tmp_path, capsys, to):
    out = tmp_path / ("out.mcap" if to == "--mcap" else "out")
    capsys.readouterr()
    assert main(["export", one_big_window, to, str(out)]) == 0
    err = capsys.readouterr().err
    assert "exported 1 windows (stored as 2 records: a window over the 16 MiB record limit is split into " \
           "several), 22692 messages of 1 streams" in err, err


@pytest.mark.parametrize("rng", [["--start", f"{TUC_START + 2000}s"], ["--end", f"{TUC_START + 100}s"],
                                 ["--start", f"{TUC_START + 100}s", "--end", f"{TUC_START + 2000}s"]])
def test_a_window_cut_to_a_range_counts_once_whichever_parts_it_keeps(one_big_window, tmp_path, capsys, rng):
    capsys.readouterr()
    assert main(["export", one_big_window, "--mcap", str(tmp_path / "out.mcap"), *rng]) == 0
    err = capsys.readouterr().err
    assert "exported 1 windows (" in err, err
