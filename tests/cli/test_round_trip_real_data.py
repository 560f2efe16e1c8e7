"""Issue 12 (held-out style check): `convert` -> `record` -> `cat` is byte-exact, in the
source's order, on every topic of every file in ../shared/data (long/ included)."""

import pytest

from cclogfs.cli import main
from conftest import shared_data_file

FILES = ["tf_example.bag", "tf_example", "nav2_turtlebot.mcap", "long/slamfail_cps_lab.mcap",
         "long/slamfail_hospital.mcap", "long/slamfail_long_passage.mcap", "long/slamfail_study_center.mcap",
         "long/tuc_corridor.mcap", "long/tuc_lecture_hall.mcap"]  # fmt: skip


@pytest.mark.parametrize("name", FILES)
def test_convert_record_cat_is_byte_exact(name, tmp_path, capsys):
    src = shared_data_file(name)
    converted = tmp_path / "c.jsonl"
    assert main(["convert", str(src), "-o", str(converted)]) == 0
    assert main(["record", str(converted), "--store", str(tmp_path / "s")]) == 0
    capsys.readouterr()
    assert main(["cat", str(tmp_path / "s")]) == 0
    assert capsys.readouterr().out == converted.read_text()
