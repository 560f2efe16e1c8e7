"""A private ROS 1 master for tests and benchmarks: roscore on a free port, `rosbag play`,
waiting for subscribers, and ROS 1 bags made from any bag rosbags reads.

Every process started here runs in its own process group and is ended by its id (SIGINT,
then SIGKILL after a timeout), so a failing test leaves nothing behind. The master is asked
through its XML-RPC API directly, so the calling process never imports the system's ROS
packages (only the recorders and players it starts do).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
import xmlrpc.client
from collections.abc import Iterable, Iterator
from pathlib import Path



def ros1_missing() -> str | None:
    """Why ROS 1 cannot be used here (None when roscore, rosbag and rospy are all there).
    rospy is looked for in a child process, as `cclog record ros1://` would find it."""
    for tool in ("roscore", "rosbag"):
        if shutil.which(tool) is None:
            return f"{tool} is not on PATH"
    code = "from cclogfs.ingest.ros1live import import_rospy; import_rospy()"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    return None if r.returncode == 0 else (r.stderr.strip().splitlines() or ["rospy cannot be imported"])[-1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(args: list[str], env: dict[str, str], **kw) -> subprocess.Popen:
    """A process in its own group (so `stop` ends its children too)."""
    return subprocess.Popen(args, env=env, start_new_session=True, **kw)


def stop(proc: subprocess.Popen, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
    """Signal the process group, wait, SIGKILL it if it hangs; the exit status."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode


@contextlib.contextmanager
def roscore(home: Path, *, timeout: float = 30.0) -> Iterator[dict[str, str]]:
    """A roscore on a free port; yields the environment for processes that use it
    (ROS_MASTER_URI and a private ROS_HOME for logs, nothing else ROS-specific)."""
    port = free_port()
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}", "ROS_HOME": str(home)}
    log = open(Path(home) / "roscore.log", "wb")
    proc = start(["roscore", "-p", str(port)], env, stdout=log, stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: _master_online(env["ROS_MASTER_URI"]) or proc.poll() is not None, timeout, "roscore")
        if proc.poll() is not None:
            raise RuntimeError(f"roscore exited with {proc.returncode}; see {home}/roscore.log")
        yield env
    finally:
        stop(proc)
        log.close()


def master(env: dict[str, str]) -> xmlrpc.client.ServerProxy:
    return xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"])


def _master_online(uri: str) -> bool:
    try:
        return xmlrpc.client.ServerProxy(uri).getPid("/cclog_test")[0] == 1
    except OSError:
        return False


def wait_for(cond, timeout: float, what: str, every: float = 0.05) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(every)


def subscribers(env: dict[str, str], topic: str) -> list[str]:
    """Nodes the master lists as subscribed to `topic`."""
    _, subs, _ = master(env).getSystemState("/cclog_test")[2]
    return next((nodes for t, nodes in subs if t == topic), [])


def published(env: dict[str, str]) -> set[str]:
    """Topics the master lists as published."""
    return {t for t, _ in master(env).getPublishedTopics("/cclog_test", "")[2]}


def play(env: dict[str, str], bag: Path, *args: str) -> subprocess.Popen:
    """`rosbag play -q BAG ARGS...` (e.g. --rate 5, --wait-for-subscribers; --topics T... last)."""
    return start(["rosbag", "play", "-q", str(bag), *args], env, stdout=subprocess.DEVNULL,
                 stderr=subprocess.PIPE, stdin=subprocess.DEVNULL)  # fmt: skip


def write_ros1_bag(src: Path, dst: Path, *, latched: Iterable[str] = (), topics: Iterable[str] | None = None) -> Path:
    """A ROS 1 bag of `src` (any bag rosbags reads; ROS 2 types get their ROS 1 form, a
    header the `seq` a ROS 1 publisher gives it: 1, 2, 3... per topic); `latched` topics are
    marked latching, as /tf_static is on a robot."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer

    from ..jsontext.rostypes import ros1_typestore
    from ..jsontext.ros import MessageConverter
    from ..jsontext.rosmsg import from_json
    from .ros1seq import starts_with_header

    latched, wanted = set(latched), None if topics is None else set(topics)
    to_json = MessageConverter().to_json
    with AnyReader([Path(src)]) as reader, Writer(dst) as writer:
        ts = ros1_typestore(reader.typestore)
        chosen = [c for c in reader.connections if wanted is None or c.topic in wanted]
        conns, numbered, seq = {}, set(), {}
        for c in chosen:
            msgdef, md5 = ts.generate_msgdef(c.msgtype, ros_version=1)
            conns[c.id] = writer.add_connection(c.topic, c.msgtype, msgdef=msgdef, md5sum=md5,
                                                latching=1 if c.topic in latched else None)  # fmt: skip
            if starts_with_header(msgdef):
                numbered.add(c.id)
        for c, t, raw in reader.messages(connections=chosen):
            if reader.is2:
                raw = bytearray(ts.serialize_ros1(from_json(ts, c.msgtype, to_json(reader.deserialize(raw, c.msgtype))),
                                                  c.msgtype))  # fmt: skip
                if c.id in numbered:  # the header's seq leads the serialized message
                    seq[c.id] = seq.get(c.id, 0) + 1
                    struct.pack_into("<I", raw, 0, seq[c.id])
            writer.write(conns[c.id], t, bytes(raw))
    return dst
