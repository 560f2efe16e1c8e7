"""An export's work file is its own: two exports to one output at once, or a file of the
user's named like the work file, must not share or lose it. The MCAP export wrote to the
fixed name OUT.mcap.tmp: a second export to OUT.mcap truncated and wrote into the first's
file, the first renamed the mix into place and said "exported N messages" (exit 0) over a
file holding the other's, and a user's OUT.mcap.tmp was overwritten and renamed away."""

from __future__ import annotations

import os
import subprocess
import sys

from _windows import FakeWindow
from mcap.reader import make_reader

from cclogfs.export import export_mcap


def _windows(stream: str, n: int, per: int = 50) -> list[FakeWindow]:
    msgs = [(t, f'{{"i": {t}}}') for t in range(1, n + 1)]
    return [FakeWindow(stream, k, msgs[i : i + per]) for k, i in enumerate(range(0, n, per))]


def _topics(path) -> dict[str, int]:
    with open(path, "rb") as f:
        got: dict[str, int] = {}
        for _, chan, _msg in make_reader(f).iter_messages():
            got[chan.topic] = got.get(chan.topic, 0) + 1
    return got


def test_an_export_started_during_another_to_the_same_file_does_not_mix_them(tmp_path):
    out = tmp_path / "out.mcap"
    done = []

    def progress(_n: int) -> None:
        if not done:  # the first export is half written: another runs to its end
            done.append(export_mcap(_windows("/b", 300), out, compression="none"))

    stats = export_mcap(_windows("/a", 2000, per=100), out, compression="none", progress=progress)
    assert done and done[0].messages == 300 and stats.messages == 2000
    assert _topics(out) == {"/a": 2000}  # the last to finish, whole, and only it
    assert sorted(os.listdir(tmp_path)) == ["out.mcap"]


def test_a_file_named_like_the_work_file_is_left_alone(tmp_path):
    out = tmp_path / "out.mcap"
    mine = tmp_path / "out.mcap.tmp"
    mine.write_bytes(b"the user's own file")
    export_mcap(_windows("/a", 10), out)
    assert mine.read_bytes() == b"the user's own file"
    assert _topics(out) == {"/a": 10}


def test_the_output_gets_the_mode_a_new_file_gets(tmp_path):
    """Not the 0600 of a private temporary file: others may play what was exported."""
    old = os.umask(0o022)
    try:
        export_mcap(_windows("/a", 10), tmp_path / "out.mcap")
    finally:
        os.umask(old)
    assert os.stat(tmp_path / "out.mcap").st_mode & 0o777 == 0o644


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_killed_exports_work_file_goes_at_the_next_run_a_live_ones_stays(tmp_path):
    """Found by attack: a killed export left its hidden `.OUT.*.tmp` for good. The next run
    removes those whose writer is dead, never one of a live concurrent export."""
    out = tmp_path / "out.mcap"
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        dead_tmp = tmp_path / f".out.mcap.{_dead_pid()}.0badf00d.tmp"
        live_tmp = tmp_path / f".out.mcap.{live.pid}.0badf00d.tmp"
        other = tmp_path / f".other.mcap.{_dead_pid()}.0badf00d.tmp"  # another output's: not this run's to judge
        for p in (dead_tmp, live_tmp, other):
            p.write_bytes(b"half an export")
        export_mcap(_windows("/a", 10), out)
        assert sorted(os.listdir(tmp_path)) == sorted(["out.mcap", live_tmp.name, other.name])
    finally:
        live.kill()
        live.wait()


def test_the_work_file_is_synced_before_the_rename_and_the_directory_after(tmp_path, renames_and_fsyncs):
    """Found by attack: without an fsync before the rename, a power cut could leave an empty
    or partial file under the final name."""
    out = tmp_path / "out.mcap"
    ops = renames_and_fsyncs
    export_mcap(_windows("/a", 10), out)
    at = ops.index(("replace", str(out)))
    assert any(op == "fsync" and os.path.basename(p).startswith(".out.mcap.") for op, p in ops[:at]), ops
    assert ("fsync", str(tmp_path)) in ops[at:], ops


def test_an_older_versions_work_files_go_once_old_and_a_parquet_exports_too(tmp_path):
    """l-left8: what the pid naming above does not match stayed for good: an older version's
    `.OUT.XXXXXXXX.tmp` (mkstemp's, or work_file's before the pid; files, or a rosbag2
    export's directory) and a killed Parquet export's `.robot=R.partial-PID` directory. The
    old names hold no pid: one untouched for OLD_WORK_FILE_S goes, a fresh one stays."""
    from cclogfs.export import export_parquet
    from cclogfs.export.base import OLD_WORK_FILE_S

    out = tmp_path / "out.mcap"
    old_file, old_dir, fresh = (tmp_path / n for n in (".out.mcap.k2j_x9qa.tmp", ".out.mcap.0badf00d.tmp",
                                                          ".out.mcap.1234abcd.tmp"))  # fmt: skip
    old_file.write_bytes(b"half an export")
    old_dir.mkdir()
    (old_dir / "metadata.yaml").write_text("half a bag")
    fresh.write_bytes(b"maybe an older export still writing")
    when = os.stat(fresh).st_mtime - OLD_WORK_FILE_S - 60
    for p in (old_file, old_dir):
        os.utime(p, (when, when))
    export_mcap(_windows("/a", 10), out)
    assert sorted(os.listdir(tmp_path)) == sorted(["out.mcap", fresh.name])

    pq = tmp_path / "pq"
    killed = pq / f".robot=r.partial-{_dead_pid()}"
    killed.mkdir(parents=True)
    (killed / "half.parquet").write_bytes(b"half")
    export_parquet(_windows("/a", 10), pq, robot="r")
    assert sorted(os.listdir(pq)) == ["robot=r"]
    # Killed between its two renames: the previous export is only in `.old-PID`, and stays.
    os.rename(pq / "robot=r", pq / (aside := f".robot=r.old-{_dead_pid()}"))
    from cclogfs.export.base import remove_stale_work_files

    assert remove_stale_work_files(pq / "robot=r") == [] and (pq / aside).is_dir()
