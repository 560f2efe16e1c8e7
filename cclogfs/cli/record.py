"""`cclog record SOURCE --store DIR`: log a bag, an MCAP file or a JSONL stream into a store."""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sys
from typing import TYPE_CHECKING

from ..errors import CclogError, InvalidInputError
from ..times import parse_duration
from ..windowcount import Link, WindowCount, count_records, link_of
from .common import (Progress, check_topics_exist, damaged_exit, human_bytes, iso_ns, load_labels, model_fits,
                     no_source_message, parse_size, repair_hint, say_dropped_damage, stored_types,
                     unmatched_rules_error)

# The engine, sources and classifier are imported where they are used, not here:
# `cclog --help` imports every subcommand module.
if TYPE_CHECKING:
    from ..pipeline import RecordStats
    from ..upkeep import Upkeep

EXAMPLES = """\
examples:
  cclog record run.mcap --store robot.store                     # keep everything (collect mode)
  cclog record run.mcap --store robot.store --model odom.model  # smart logging: anomaly windows only
  cclog record run.bag --store robot.store --model odom.model --topic /tf --before 4s --after 4s
  cclog record sim.mcap --store all.store --features-out vectors/ --labels sim.labels.json  # collect mode
  some-producer | cclog record - --store robot.store            # live JSON Lines on stdin
  cclog record ros1:// --store robot.store --model odom.model   # live ROS 1 topics (ROS_MASTER_URI)
  cclog record ros1://localhost:11311 --store s --topic /odom --topic '/tf.*' --exclude '/rosout.*'
  cclog record - --store robot.store --model odom.model --budget 20GiB \\
      --age-older-than 7d --age-error 1e-3      # the disk never fills; old windows shrink

Each run is kept in the store (stream /cclog/runs: source, options, start, end; `cclog info`
lists them). A file the store holds a run of already (same content, any name) is refused,
since its messages would be stored twice; --append records it again as a new run.

JSON Lines: one message per line, {"topic": "/odom", "stamp_ns": 1432235695834049087, "msg": {...}}.
A damaged ROS 1 bag, MCAP file or ROS 2 .db3 (cut short, index lost) is recorded as far as it
can be read; stderr says what was lost and the exit code is 4. An MCAP chunk that cannot be read
stops the run naming its offset; --on-error skip records the other chunks (exit 4). A ROS 2 bag directory without
metadata.yaml is read from its .db3 files (a note on stderr).
With --model, odometry on the model's topic is scored; each anomaly opens a window of
--before messages (or seconds, "4s") before it and --after after the last anomaly, over
the odometry and the --topic topics (all topics when none is given). Odometry the model
cannot score (NaN or infinite values) is kept, every message (windows of kind "unscored"),
and the end summary says how many and the first. Ctrl-C or SIGTERM
stores what was seen and closes the store cleanly.

ros1:// records live from a ROS 1 master until Ctrl-C or SIGTERM (then exit 0, or 4): every topic,
or those whose name is a --topic or fully matches one as a regular expression, minus
--exclude; topics that appear later are picked up. A message's time is its receive time
(--clock header: its header stamp, else its receive time). Needs rospy (Debian: apt-get install ros-core python3-rospy).
At the end, stderr says per topic what was received and how many messages were lost, told
from each publisher's header.seq (a gap means dropped messages); topics whose type has no
header (tf2_msgs/TFMessage) or whose seq does not count up are listed as not checked.

exit status: 0 done, 1 error, 130 interrupted (file input), 4 ros1:// recorded but
messages were lost (seq gaps, received after the recording stopped, or of another type than
the topic's first: a publisher restarted with another type; such messages are skipped, not stored),
or a damaged input was recorded as far as it could be read, or --on-error skip left bad lines or
messages out (stderr says how many), 3 done but the store is still over --budget (as `cclog compact`), or retention had to
drop every message this run stored to meet it.
"""
LOST = 4  # the exit status when a live recording knows it lost messages
OVER_BUDGET = 3  # as `cclog compact`: done, but the store is larger than --budget


DESCRIPTION = (
    "Record messages into a store: all of them, or with --model only "
    "the logging windows around anomalies."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..pipeline import WINDOW_AFTER, WINDOW_BEFORE

    p.add_argument("source", help="ROS 1/2 bag, MCAP file, JSONL file, - for JSONL on stdin, "
                                  "or ros1:// (ros1://HOST:PORT) for live ROS 1 topics")
    p.add_argument("--exclude", action="append", default=[], metavar="RE",
                   help="with ros1://: leave out topics that fully match RE (repeatable)")
    p.add_argument("--store", required=True, help="store directory (created when missing)")
    p.add_argument("--append", action="store_true",
                   help="record a source the store holds a run of already (else refused: its messages "
                        "would be stored twice)")
    p.add_argument("--topic", action="append", metavar="T", help="record topic T (repeatable; default all)")
    p.add_argument("--model", help="smart logging with this model directory (from `cclog train`)")
    p.add_argument("--before", default=WINDOW_BEFORE, help="window context before an anomaly: N messages or Ds (default %(default)s)")
    p.add_argument("--after", default=WINDOW_AFTER, help="window context after the last anomaly: N or Ds (default %(default)s)")
    p.add_argument("--chunk", type=int, default=200, help="without --model: messages per stored window")
    p.add_argument("--window-max-s", type=float, default=5.0, metavar="S",
                   help="store the open windows at least every S seconds of wall time (default %(default)s), "
                        "so a hard kill loses at most S plus --sync-ms")
    p.add_argument("--clock", choices=["log", "header"], default="log",
                   help="the time a bag's or live topic's message is stored and queried under: log (receive) time, "
                        "one clock for every topic (default), or header.stamp, else log time (docs/JSON.md)")
    p.add_argument("--codec", default="columnar",
                   help="codec for new records: columnar (default, smallest), zstd (fastest), lzma, none")
    p.add_argument("--on-error", choices=["stop", "skip"], default="stop",
                   help="a malformed JSONL line, or a message its stream cannot take (another type than the "
                        "topic's first or the store's stream has, a topic the recording writes itself such as "
                        "/cclog/runs), stops the run (default) or is reported and skipped (exit 4)")
    p.add_argument("--sync-ms", type=float, default=200, help="group commit interval (default 200 ms)")
    p.add_argument("--no-summary", action="store_true", help="with --model: no per-minute summary stream")
    p.add_argument("--features-out", metavar="DIR",
                   help="also write the odometry's feature vectors as a labelled dataset (collect mode; "
                        "`cclog train DIR` learns from it)")
    p.add_argument("--labels", metavar="JSON", help="with --features-out: labelled events of the source")
    p.add_argument("--features", default="default", choices=["default", "paper"],
                   help="with --features-out: the feature set")
    p.add_argument("--odom-topic", metavar="T",
                   help="the odometry topic: with --model, the source's topic to score (default: the model's), "
                        "with --features-out the topic to learn from (default /odom)")
    p.add_argument("--force-model", action="store_true",
                   help="with --model: use it even on a robot whose rate or motion is far outside its training")
    upkeep = p.add_argument_group("upkeep while recording (as `cclog compact`, each time a segment is sealed)")
    upkeep.add_argument("--budget", metavar="SIZE",
                        help="drop the oldest segments while the store is larger (e.g. 20GiB); segments are "
                             "then at most 1/8 of it, so the store stays within about 1/8 over it; at least 32KiB")
    upkeep.add_argument("--age-older-than", metavar="DURATION",
                        help="age windows that ended this long before their stream's newest sealed one "
                             "(e.g. 7d), in a background thread")
    upkeep.add_argument("--age-error", action="append", default=[], metavar="[PATTERN=]BOUND",
                        help="error bound for aged float fields (repeatable; last match wins)")
    upkeep.add_argument("--age-max-rate", type=float, metavar="HZ", help="at most HZ messages per second of aged windows")


def _tee_odometry(messages, topic: str, rows: list):
    """Pass messages on, keeping the odometry as compact rows (not texts) for the dataset."""
    from ..classifier.features import TwistFromPoses, odom_row

    twist = TwistFromPoses()  # pose-only robots: twist from consecutive poses
    for m in messages:
        if m.topic == topic:
            stamp, row = odom_row(m.text)
            rows.append((stamp, twist(stamp, row)))
        yield m


def _write_dataset(args: argparse.Namespace, rows: list) -> None:
    import numpy as np

    from ..classifier import OdomArrays, collect

    if not rows:
        print(f"cclog: no {args.odom_topic} messages, so no feature vectors were written", file=sys.stderr)
        return
    odom = OdomArrays(np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows], dtype=float))
    meta = collect(odom, args.features_out, features=args.features, labels=load_labels(args.labels))
    print(f"feature vectors in {args.features_out}: {meta['nominal']:,} nominal, {meta['anomalous']:,} anomalous "
          f"({args.features} features)", file=sys.stderr)  # fmt: skip


def _upkeep(args: argparse.Namespace) -> Upkeep | None:
    """The Upkeep the flags ask for (None for none)."""
    from ..upkeep import Policy, Upkeep, parse_rule
    from ..upkeep.background import MIN_BUDGET, MIN_SEGMENT_BYTES
    from ..upkeep.job import check_budget

    rules = [parse_rule(r) for r in args.age_error]
    aging = bool(rules) or args.age_max_rate is not None
    if args.age_older_than and not aging:
        raise InvalidInputError("--age-older-than says which windows to age; give --age-error or --age-max-rate too.")
    if aging and not args.age_older_than:
        raise InvalidInputError("Aging while recording needs --age-older-than (else every window ages when sealed).")
    budget = parse_size(args.budget) if args.budget else None
    if budget is not None:
        check_budget(args.budget, budget, MIN_BUDGET, "segments are 1/8 of the budget and at least "
                     f"{human_bytes(MIN_SEGMENT_BYTES)}", "the run")  # fmt: skip
    if not aging and budget is None:
        return None
    policy = Policy(rules, args.age_max_rate) if aging else None
    older = parse_duration(args.age_older_than) if aging else None
    return Upkeep(budget=budget, policy=policy, older_than_ns=older)


class _Skips:
    """Says each bad line `--on-error skip` skips, and counts them: the summary says how
    many, as the lines said one by one scroll away in a long run."""

    def __init__(self) -> None:
        self.count = 0

    def __call__(self, err: Exception) -> None:
        self.count += 1
        print(f"cclog: skipped: {err}", file=sys.stderr)


def _open(args: argparse.Namespace, topics: list[str] | None, policy):
    """The source: a file, stdin, or live ROS 1 topics (ros1://); and the check of each
    message's topic and type it makes (`TypeCheck`: the streams the recording writes itself
    are refused there, naming the line, and the store's types once it is open)."""
    from ..jsontext.rostypes import TypeCheck
    from ..pipeline import reserved_topics

    if args.source.startswith("ros1://"):
        from ..ingest.ros1live import Ros1LiveSource

        source = Ros1LiveSource(args.source, topics=topics, exclude=args.exclude, clock=args.clock)
        return source, source.types
    from ..ingest import open_source
    from ..store.format import MAX_MESSAGE_TEXT

    if args.exclude:
        raise InvalidInputError("--exclude goes with a live source (ros1://); name the topics to read with --topic")
    args.skips = _Skips()
    check = TypeCheck(reserved=reserved_topics(policy))
    return open_source(args.source, topics=topics, on_error=args.on_error, report=args.skips, clock=args.clock,
                       max_text_bytes=MAX_MESSAGE_TEXT, types=check), check  # fmt: skip


def _logging_policy(args: argparse.Namespace):
    """The logging policy the flags ask for, and the topics to read for it (None: all)."""
    from ..pipeline import KeepAll, smart_policy

    topics = args.topic
    if args.features_out and not args.odom_topic:
        args.odom_topic = "/odom"
    if args.labels and not args.features_out:
        raise InvalidInputError("--labels goes with --features-out")
    if args.features_out and topics is not None and args.odom_topic not in topics:
        topics = [*topics, args.odom_topic]
    if not args.model:
        return KeepAll(chunk=args.chunk), topics
    from ..classifier import OneClassModel

    model = OneClassModel.load(args.model)
    args.odom_topic = args.odom_topic or model.topic
    model_fits(model, args.model, args.source, args.odom_topic, force=args.force_model)
    live = args.source.startswith("ros1://")  # the live source itself matches names and patterns
    policy = smart_policy(model, topics=None if live else topics, before=args.before, after=args.after,
                          summary=not args.no_summary, odom_topic=args.odom_topic)  # fmt: skip
    # The scored odometry must be read even when --topic does not name it.
    return policy, None if topics is None else sorted({*topics, policy.odom_topic})


def _warn_damage(store) -> None:
    """Recording into a damaged store goes on, but says so each time: damage stays named
    until fsck mends or drops it (`repair_hint`, docs/FORMAT.md)."""
    from ..store.store import describe_damage

    for d in store.damage():
        print(f"cclog: warning: {store.path} holds damage below the synced point, kept and not cut: "
              f"{describe_damage(d)} ({repair_hint(d)})", file=sys.stderr)  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """Record; a run that fails before storing anything leaves no store it created."""
    from .outputs import refuse_store_dir

    _refuse_store_in_source(args)
    # a store inside another one would sit among its segments
    refuse_store_dir(os.path.dirname(os.path.abspath(args.store)), f"--store {args.store}: its directory")
    existed = os.path.exists(args.store)
    try:
        return _run(args)
    except BaseException as err:
        if not existed and _remove_if_empty(args.store) and getattr(err, "store_failed", None):
            # The error told of the reopened store and its end record: both are gone now.
            from ..errors import StoreFailedError

            raise StoreFailedError(f"{err.store_failed}; nothing of this run was stored, so the store it created was "
                                   "removed: free space, then record again") from err  # fmt: skip
        raise


def _refuse_store_in_source(args: argparse.Namespace) -> None:
    """A store inside the source (a ROS 2 bag directory) writes into an input, and changes
    the bag's fingerprint with every run, so recording it again is not known as a second
    time: its messages were stored twice, exit 0."""
    if args.source != "-" and "://" not in args.source and os.path.isdir(args.source):
        store, source = os.path.realpath(args.store), os.path.realpath(args.source)
        if store == source or store.startswith(source.rstrip(os.sep) + os.sep):
            raise InvalidInputError(f"--store {args.store} is inside the source {args.source}; inputs are never "
                                    "written: choose a store outside it.")  # fmt: skip


def _remove_if_empty(path: str) -> bool:
    """Remove the store at `path` when it holds no message (the run's own records aside);
    True when removed."""
    from ..runs import hidden_by_default
    from ..store import open_store
    from ..store.format import LOCK
    from ..store.fs import FileSystem

    if not os.path.isdir(path):
        return False
    # Under the writer lock: a store another process created meanwhile, and is writing to,
    # is that process's, not this failed run's (two runs creating one store at once).
    fs = FileSystem()
    try:
        lock = fs.lock(os.path.join(path, LOCK))
    except OSError:
        return False
    if lock is None:
        return False
    try:
        try:
            with open_store(path, readonly=True) as store:
                if any(not hidden_by_default(name) for name in store.streams()):
                    return False  # messages were stored (the run's own start record does not count)
        except CclogError:
            return False  # not a store we can read: leave it for the user to look at
        shutil.rmtree(path, ignore_errors=True)
        return not os.path.exists(path)
    finally:
        fs.unlock(lock)


def _options(args: argparse.Namespace) -> dict:
    """The options this run was given that differ from their defaults, as the run keeps them."""
    p = argparse.ArgumentParser(add_help=False)
    add_arguments(p)
    defaults = vars(p.parse_args([args.source, "--store", args.store]))
    return {k: v for k, v in vars(args).items()
            if k in defaults and k not in ("source", "store") and v != defaults[k]}  # fmt: skip


def _begin_run(args: argparse.Namespace, store, source):
    """Refuse a source the store has a run of already (unless --append); write this run's start."""
    from ..runs import begin_run, earlier_run, grown_run, list_runs, source_fingerprint, stopped_run

    fingerprint = source_fingerprint(args.source)
    runs = list_runs(store)  # once: each check below, and the new run's number, look at them
    earlier = earlier_run(runs, fingerprint)
    grown = None if earlier is not None or args.append else grown_run(runs, args.source, fingerprint)
    stopped = None if earlier or grown or args.append or fingerprint is None else stopped_run(runs, args.source)
    if (earlier is not None or grown is not None or stopped is not None) and not args.append:
        run = earlier or grown or stopped
        kept = "its end not recorded" if run.kept is None else f"{run.kept:,} messages kept"
        what = ("already" if earlier is not None else f"when it was {run.fingerprint['bytes']:,} bytes (it has "
                "grown since)" if grown is not None else "before that run stopped (the file has changed since)")
        raise InvalidInputError(
            f"{args.source} was recorded into {args.store} {what}, as run {run.number} "
            f"({iso_ns(run.start_ns)}, {run.status}, {kept}); recording it again would store "
            f"{'its' if earlier is not None else 'those'} messages twice: pass --append to record it again, "
            "or record into another --store.")  # fmt: skip
    if fingerprint is None:  # stdin or a live master: named as given (a master by its URI)
        name, extra = args.source, ({"master": source.master} if hasattr(source, "master") else {})
    else:
        name, extra = os.path.abspath(args.source), {}
    return begin_run(store, name, fingerprint=fingerprint, options=_options(args), runs=runs, **extra)


def _refuse_runs_damage(args: argparse.Namespace, store) -> None:
    """Damage that may have lost a run's start record hides whether this source was
    recorded: going on with a warning stored its messages twice."""
    from ..runs import has_fingerprint, runs_damage
    from ..store.store import describe_damage

    if args.append or not has_fingerprint(args.source):  # stdin or live: never refused as recorded
        return
    damage = runs_damage(store)
    if damage:
        raise InvalidInputError(
            f"{args.store} holds damage that may have lost the record of an earlier run "
            f"({'; '.join(describe_damage(d) for d in damage)}), so it cannot tell whether {args.source} was recorded "
            f"into it already: pass --append to record it anyway, or {repair_hint(damage[0])} (a run record dropped "
            "is not known afterwards: recording again then goes on unrefused).")  # fmt: skip


def _end_run(run, source, stats: RecordStats, received: list[int], error: BaseException | None) -> None:
    """Write the run's end: what it saw and kept, what the source says it lost, and how it
    ended. After an error the store may have failed too; the error that stopped the run is
    what the user must see."""
    interrupted = stats.interrupted or isinstance(error, KeyboardInterrupt)
    status = "interrupted" if interrupted else "error" if error is not None else "done"
    # windows: of the messages kept, as the end summary says; the recorder's own summaries apart
    # (a smart window's parts count once, `windowcount`; `records`: what holds them)
    counts = {"messages_in": stats.messages_in, "messages_kept": stats.messages_kept,
              "windows": stats.windows, "summaries": stats.summaries, "records": stats.records,
              "topics_kept": dict(sorted(stats.topics_kept.items()))}  # fmt: skip
    if received:
        counts["signal"] = signal.Signals(received[0]).name
    if getattr(source, "lost", None):  # a damaged file: where reading stopped
        counts["input_lost"] = source.lost
    if getattr(source, "seq", None) is not None:  # a live source: messages lost, told from header.seq
        counts["seq_lost"] = source.seq.lost
    if error is not None and not interrupted:
        counts["error"] = str(error) or type(error).__name__
    try:
        run.end(status, **counts)
    except CclogError:
        if error is None:
            raise


class _StoreFailed(Exception):
    """The store failed mid-run (disk full, I/O error): carried out of the open store, so that
    the run's end record is tried once the store is closed (`_end_after_failure`)."""

    def __init__(self, err: CclogError, said: str, run, run_seq: int | None, stats: RecordStats, store_id: str) -> None:
        super().__init__(str(err))
        self.err, self.said, self.run, self.run_seq, self.stats = err, said, run, run_seq, stats
        self.store_id = store_id  # the end record goes into this store only, not whatever took its path


def _stored_when_failed(store, run_seq: int | None) -> str:
    """What of this run the failed store holds: its windows fsynced before the failure (kept
    whatever happens), and those handed to the OS but not fsynced (a reopen keeps them
    unless power is lost too)."""
    synced, written = store.synced_seq(), store.synced_seq(written=True)
    kept = _run_records(store, run_seq, written)
    said = f"synced up to seq {synced}: {_counted(kept, synced)}" if synced is not None else "nothing synced"
    if written is not None and written != synced:
        said += (f"; written but not yet fsynced up to seq {written} or further: at least {_counted(kept, written)} "
                 "(a reopen keeps them unless power was lost too)")  # fmt: skip
    return said


def _end_after_failure(path: str, source: str, failed: _StoreFailed) -> CclogError:
    """The store's failure, saying what of this run is stored and that the rest was lost.
    The failed store refuses writes, so the run's end record is written after it closed, by
    reopening it: the recovery any cclog command runs (what is whole is kept, a torn tail
    cut), then one small record, status error with `store_failed`, counting what the store
    keeps of the run. When that fails too (the disk still full), the run stays without an
    end, as a killed run, and the error says so."""
    from ..errors import StoreFailedError
    from ..runs import Run
    from ..store import open_store

    said = (f"{failed.err}. This run's messages stored: {failed.said}; the rest of the "
            f"{failed.stats.messages_in:,} messages it read was lost")  # fmt: skip
    try:
        _same_store(path, failed.store_id)
        with open_store(path) as store:
            kept = _run_records(store, failed.run_seq, store.synced_seq(written=True))
            if kept is None:
                raise StoreFailedError("its windows cannot be counted")
            n, count = _kept(kept)
            Run(store, failed.run.number, failed.run.id).end(
                "error", messages_in=failed.stats.messages_in, messages_kept=n, windows=count.windows,
                summaries=count.summaries, records=count.records, error=str(failed.err), store_failed=True)  # fmt: skip
    except _Moved as moved:
        error = StoreFailedError(f"{said}, and its end record was not written: {moved}")
    except (CclogError, OSError):
        error = StoreFailedError(f"{said}, and its end record could not be written. Reopening the store (any cclog "
                                 f"command) keeps what is stored; {_again(source, 'messages')}")  # fmt: skip
    else:
        error = StoreFailedError(f"{said}. Reopened, the store keeps {n:,} messages of this run in {count.windows:,} "
                                 "windows and its end record (`cclog info`: ended on a store failure); "
                                 f"{_again(source, f'{n:,} messages')}")  # fmt: skip
    error.store_failed = said  # what to say instead when the store turns out empty and is removed (`run`)
    return error


class _Moved(Exception):
    """The path of the failed store holds another store now."""


def _same_store(path: str, store_id: str) -> None:
    """Refuse to reopen `path` for the end record when it holds another store now (the store
    was moved away and another put in its place while recording: the failure was its LOCK
    being replaced). Checked by a reader, which changes nothing, before the writer's open."""
    from ..store import open_store

    with open_store(path, readonly=True) as store:
        now = store.store_id
    if now != store_id:
        raise _Moved(f"{path} holds another store now (id {now}, this run's is {store_id}): the store "
                     "was moved or replaced while recording; look for it where it was moved")  # fmt: skip


def _again(source: str, kept: str) -> str:
    """What to do after a store failure. It said "record the rest again (--append)", but a
    file is recorded whole: --append stores what this run kept a second time."""
    if source == "-" or "://" in source:  # a live source: a new run records what comes next
        return "free space, then record on"
    return (f"free space, then record {source} again into another --store, or into this one with --append, which "
            f"stores the {kept} of this run it keeps a second time")  # fmt: skip


def _run_records(store, run_seq: int | None, upto: int | None) -> list[tuple[int, str, Link, bool, int]] | None:
    """(seq, stream, link, flagged PART, message count) of this run's records up to seq `upto`
    (`windowcount.link_of` says of which window each is part); None when unreadable."""
    from ..runs import hidden_by_default

    if upto is None:
        return []
    try:
        return [(w.seq, w.name, link_of(w.meta), w.continues, w.count) for w in store.query(skip_damaged=True)
                if (run_seq is None or w.seq > run_seq) and w.seq <= upto and not hidden_by_default(w.name)]  # fmt: skip
    except CclogError:
        return None


def _kept(records: list[tuple[int, str, Link, bool, int]], upto: int | None = None) -> tuple[int, WindowCount]:
    """Messages kept (a summary the recorder made is no message that came in) and the windows
    of `records` up to seq `upto`, counted as `RecordStats` counts them."""
    mine = [r for r in records if upto is None or r[0] <= upto]
    return sum(r[4] for r in mine if not r[2][3]), count_records(r[:4] for r in mine)


def _counted(records: list[tuple[int, str, Link, bool, int]] | None, upto: int) -> str:
    if records is None:
        return "count unknown"
    n, count = _kept(records, upto)
    return f"{n:,} messages in {count.windows:,} windows"


def _check_numbers(args: argparse.Namespace) -> None:
    """Refuse option values that cannot work, in the option's words, before anything is opened."""
    import threading

    from ..pipeline import parse_span

    if args.chunk < 1:
        raise InvalidInputError(f"--chunk must be at least 1 message, not {args.chunk}")
    if not args.window_max_s > 0:
        raise InvalidInputError(f"--window-max-s must be positive, not {args.window_max_s}")
    # the group-commit thread waits up to this long: NaN made it spin, inf overflowed its timer
    if not 0 <= args.sync_ms <= threading.TIMEOUT_MAX * 1000:
        raise InvalidInputError(f"--sync-ms must be a number of milliseconds from 0 to "
                                f"{threading.TIMEOUT_MAX * 1000:.0f}, not {args.sync_ms}")
    if args.model:  # before the model is read
        parse_span(args.before), parse_span(args.after)


def _check_pairs(args: argparse.Namespace) -> None:
    """Refuse an option given without the one it goes with, which would ignore it without a word."""
    given = _options(args)
    if not args.model:
        for name in ("before", "after", "no_summary", "force_model"):
            if name in given:
                raise InvalidInputError(f"--{name.replace('_', '-')} goes with --model (smart logging); "
                                        "without it every message is kept")
        if "odom_topic" in given and not args.features_out:
            raise InvalidInputError("--odom-topic goes with --model or --features-out")
    elif "chunk" in given:
        raise InvalidInputError("--chunk goes without --model: smart logging stores the windows around anomalies")
    if "features" in given and not args.features_out:
        raise InvalidInputError("--features goes with --features-out")


def _run(args: argparse.Namespace) -> int:
    from ..pipeline import RecordStats, interrupt_handler
    from ..store import open_store

    _check_numbers(args)
    _check_pairs(args)
    policy, read_topics = _logging_policy(args)
    upkeep = _upkeep(args)
    store_options = upkeep.store_options() if upkeep is not None else {}
    source, check = _open(args, read_topics, policy)
    if not args.source.startswith("ros1://"):
        check_topics_exist(source, args.source, read_topics)
    handler = getattr(source, "signal_handler", interrupt_handler)  # live: the first signal ends the input
    received: list[int] = []  # the signal that stopped the run: exit 128 + its number, as shells expect

    def noted(signum, frame):
        received.append(signum)
        handler(signum, frame)

    previous = {sig: signal.signal(sig, noted) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with source, open_store(args.store, create=True, codec=args.codec, sync_every_ms=args.sync_ms,
                                **store_options) as store, \
                Progress("recording", total=getattr(source, "message_count", None)) as progress:  # fmt: skip
            _refuse_runs_damage(args, store)  # before the warning: the refusal is the one line
            _warn_damage(store)
            # A stream keeps one type, also across runs (--append, or another source).
            stored = stored_types(store)
            check.stored.update(stored)
            run = _begin_run(args, store, source)
            run_seq = store.synced_seq()  # the run's start record, synced by begin_run
            dropped_before = _dropped_messages(store)
            stats = RecordStats()
            try:
                rows, final_bytes = _record_run(args, store, source, policy, upkeep, progress, stats, stored)
            except BaseException as err:
                _end_run(run, source, stats, received, err)
                if store.failed is not None and isinstance(err, CclogError):  # disk full, I/O error
                    raise _StoreFailed(err, _stored_when_failed(store, run_seq), run, run_seq, stats,
                                       store.store_id) from err
                raise
            refused = _refused_rules(upkeep)
            _end_run(run, source, stats, received, refused)
            final_bytes = _fit_budget(store, upkeep, final_bytes)
            retention = _retention(store, run_seq, stats, upkeep, dropped_before)
    except _StoreFailed as failed:  # the store is closed now: its end record may be written yet
        raise _end_after_failure(args.store, args.source, failed) from failed.err
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if args.features_out:
        _write_dataset(args, rows)
    _print_summary(args, source, stats, upkeep, final_bytes, retention, policy)
    if refused is not None:
        raise refused
    status = _exit_status(args, source, stats, policy, read_topics, received)
    if status == 0 and upkeep is not None and upkeep.budget is not None and final_bytes > upkeep.budget:
        return OVER_BUDGET  # said on stderr as "NOT met"; a script must not take it for met
    if status == 0 and _nothing_kept(stats, retention):
        print(f"cclog: --budget {args.budget} is too small for this run: retention dropped all "
              f"{stats.messages_kept:,} messages it stored; give a larger budget", file=sys.stderr)  # fmt: skip
        return OVER_BUDGET  # a run whose every message is gone is not "done" (exit 0 said so)
    return status


def _nothing_kept(stats: RecordStats, retention: tuple[int, int, int] | None) -> bool:
    """True when the run stored messages and retention dropped every one of them."""
    return retention is not None and stats.messages_kept > 0 and retention[0] == 0


def _fit_budget(store, upkeep: Upkeep | None, final_bytes: int | None) -> int | None:
    """Retention once more after the run's end record, which comes after the last pass:
    with retention keeping the runs' records (store/carry.py), the store ended a few
    hundred bytes over --budget while the run said it met it."""
    from ..upkeep import compact

    if upkeep is None or upkeep.budget is None or final_bytes is None:
        return final_bytes
    upkeep.count_drops(compact(store, budget=upkeep.budget))
    return store.data_bytes()


def _refused_rules(upkeep: Upkeep | None) -> InvalidInputError | None:
    """The error for --age-error rules that matched no number field (`Upkeep.check_rules`):
    aging stopped, but the recording went on (nothing lost, nothing to record again, which
    --append would store twice)."""
    if upkeep is None or not upkeep.unmatched:
        return None
    return unmatched_rules_error("--age-error", upkeep.unmatched, "nothing was aged (no value rounded) and the "
                                 "recording went on; age the store with `cclog compact --error` and the right field")  # fmt: skip


def _record_run(args: argparse.Namespace, store, source, policy, upkeep: Upkeep | None, progress,
                stats: RecordStats, stored: dict[str, str]) -> tuple[list, int | None]:  # fmt: skip
    """Record the source into the open store, counting into `stats`; the odometry rows kept
    for --features-out and the store's size once upkeep is done (None without upkeep).
    `stored`: the types the store's streams have (`stored_types`)."""
    from ..jsontext.rostypes import StreamTypes
    from ..pipeline import record
    from ..upkeep import compact

    last = [0]
    said = []

    def tick(stats):
        progress(stats.messages_in - last[0])
        last[0] = stats.messages_in
        if not said and (refused := _refused_rules(upkeep)) is not None:  # a live run must not wait for its end
            said.append(refused)
            print(f"cclog: {refused} (exit 1 at the end)", file=sys.stderr)

    rows: list = []
    messages = _tee_odometry(source, args.odom_topic, rows) if args.features_out else source
    ended = False  # the input ran out, with no error or interrupt
    try:
        record(messages, store, policy, check_json=False, progress=tick, stats=stats, upkeep=upkeep,
               types=StreamTypes(getattr(source, "describe", None), stored), window_s=args.window_max_s)
        ended = not stats.interrupted
        tick(stats)  # the last count (progress is told every 4,096 messages)
    except KeyboardInterrupt:  # arrived once the input had ended: all was stored
        stats.interrupted = True
    finally:
        if upkeep is not None:
            # Before the store closes: its thread may be reading segments. At the end of the
            # input it finishes what is due (the last flush may have sealed a segment); after
            # an error, Ctrl-C or SIGTERM it stops at once.
            if ended:
                upkeep.after_put(store)
            upkeep.close(finish=ended)
            if ended:  # a short run that aged nothing still learns its rule matched no field
                upkeep.check_rules(store)
    if upkeep is None:
        return rows, None
    store.sync()  # first: the active segment's buffered records count toward the budget too
    if upkeep.budget is not None:  # the last records and the final flush come after the last pass
        upkeep.count_drops(compact(store, budget=upkeep.budget))
    return rows, store.data_bytes()


def _exit_status(args: argparse.Namespace, source, stats: RecordStats, policy, read_topics, received: list[int]) -> int:
    """An error for a run that stored nothing useful; else 128 + the signal that stopped it,
    LOST when a live recording knows it lost messages, or the damaged-input code."""
    if stats.messages_in == 0 and not stats.interrupted:
        raise no_source_message(args.source, read_topics, source)
    if args.topic and not stats.interrupted and not args.source.startswith("ros1://"):
        # A JSONL source learns its topics by reading: a --topic it never had is found only
        # now (a bag's is refused before recording), and would else go unmentioned, exit 0.
        if missing := [t for t in dict.fromkeys(args.topic) if t not in stats.topics_in]:
            raise InvalidInputError(f"{args.source} has no message on {' or '.join(missing)}; the other topics "
                                    f"were recorded ({stats.messages_kept:,} messages kept).")  # fmt: skip
    if args.model and policy.scored == 0 and not policy.unscored:  # a live source or stdin, checked only now
        raise InvalidInputError(f"{args.source} sent no message on {args.odom_topic}, the odometry the model scores, "
                                "so nothing was kept; name the odometry topic with --odom-topic T.")  # fmt: skip
    if stats.interrupted:
        return 128 + (received[0] if received else signal.SIGINT)
    seq = getattr(source, "seq", None)
    if seq is not None and (seq.lost or _refused_types(source)):
        return LOST
    return damaged_exit(source)


def _refused_types(source) -> dict[str, int]:
    """Topic -> messages a live source skipped for a type other than their stream's."""
    types = getattr(source, "types", None)
    return getattr(types, "refused", None) or {}


def _dropped_messages(store) -> int:
    """Messages retention has dropped from the store so far (the runs' bookkeeping aside)."""
    from ..runs import hidden_by_default

    return sum(st.get("messages", 0) for name, st in store.dropped().get("streams", {}).items()
               if not hidden_by_default(name))  # fmt: skip


def _retention(store, run_seq: int | None, stats: RecordStats, upkeep: Upkeep | None,
               dropped_before: int) -> tuple[int, int, int] | None:  # fmt: skip
    """With --budget: (this run's messages still stored, this run's messages retention dropped,
    earlier runs' messages it dropped). None without a budget, or when the store cannot say."""
    if upkeep is None or upkeep.budget is None:
        return None
    records = _run_records(store, run_seq, store.synced_seq(written=True))
    if records is None:
        return None
    held, count = _kept(records)
    mine = max(0, stats.messages_kept - upkeep.messages_thinned - held)
    # This run's own summaries (one message each) that retention dropped are not messages
    # of earlier runs: on a store the run had made, they were told as such.
    summaries = max(0, stats.summaries - count.summaries)
    return held, mine, max(0, _dropped_messages(store) - dropped_before - mine - summaries)


def _windows(stats: RecordStats) -> str:
    """The windows of messages kept, apart from the recorder's own summaries: "0 kept in 8
    windows" read as a contradiction when the 8 were all `/cclog/summary` records. A window
    stored in several records (a smart window's parts) counts once, the records said apart."""
    notes = [f"stored as {stats.records:,} records"] if stats.records != stats.windows else []
    if stats.summaries:
        from ..classifier.summary import SUMMARY_TOPIC

        notes.append(f"and {stats.summaries:,} summaries on {SUMMARY_TOPIC}")
    return f"{stats.windows:,} windows" + (f" ({', '.join(notes)})" if notes else "")


def _unscored(args: argparse.Namespace, policy) -> str:
    """The end summary's line on the odometry the model could not score (`KeepUnscored`)."""
    stamp, field = policy.first
    return (f"{args.source}: {policy.unscored:,} {policy.odom_topic} messages had NaN or infinite values (the first at "
            f"{iso_ns(stamp)}, in {field}): the model cannot score them, so every one was kept (windows of kind "
            "\"unscored\"); the other topics were kept around anomalies only")  # fmt: skip


def _print_summary(args: argparse.Namespace, source, stats: RecordStats, upkeep: Upkeep | None, final_bytes: int | None,
                   retention: tuple[int, int, int] | None = None, policy=None) -> None:  # fmt: skip
    mode = "smart logging" if args.model else "every message"
    kept = stats.json_bytes_kept / stats.json_bytes_in if stats.json_bytes_in else 0.0
    said = f"{stats.messages_kept:,} kept ({100 * kept:.1f} % of {human_bytes(stats.json_bytes_in)} JSON)"
    if retention is not None and retention[1]:  # what the store holds of this run, not what it stored once
        said = (f"{retention[0]:,} kept ({stats.messages_kept:,} stored, then retention DROPPED the oldest "
                f"{retention[1]:,} to stay within --budget)")  # fmt: skip
    print(f"{'interrupted: ' if stats.interrupted else ''}recorded {args.source} into {args.store} ({mode}): "
          f"{stats.messages_in:,} messages in, {said} in {_windows(stats)}, {stats.seconds:.1f} s "
          f"({stats.messages_in / max(stats.seconds, 1e-9):,.0f} msg/s)", file=sys.stderr)  # fmt: skip
    if getattr(policy, "unscored", 0):
        print(_unscored(args, policy), file=sys.stderr)
    if retention is not None and retention[2]:
        print(f"{args.store}: retention also dropped {retention[2]:,} messages of earlier runs to stay within "
              "--budget", file=sys.stderr)  # fmt: skip
    skipped = getattr(getattr(args, "skips", None), "count", 0)
    if skipped:
        unit = getattr(source, "bad_unit", "messages")  # a bag or MCAP file has no lines
        print(f"{args.source}: {skipped:,} bad {unit} skipped (--on-error skip), not recorded", file=sys.stderr)
    if getattr(source, "stopped_by", None):
        print(f"{args.source}: stopped by {source.stopped_by}; received "
              + (", ".join(f"{t} {n:,}" for t, n in sorted(source.received.items())) or "nothing"), file=sys.stderr)
        for topic in sorted(t for t, n in source.received.items() if not n):
            print(f"{args.source}: received nothing on {topic} (nothing published while subscribed, or only "
                  "before, and not latched)", file=sys.stderr)  # fmt: skip
    if getattr(source, "skipped", 0):  # --on-error skip
        print(f"{args.source}: SKIPPED {source.skipped:,} bad messages (named above), not stored", file=sys.stderr)
    if refused := _refused_types(source):
        print(f"{args.source}: SKIPPED {sum(refused.values()):,} messages whose type differs from their stream's, not "
              "stored: " + ", ".join(f"{t} {n:,}" for t, n in sorted(refused.items())), file=sys.stderr)  # fmt: skip
    if getattr(source, "seq", None) is not None:
        lost = source.seq.lost
        print(f"{args.source}: {'LOST ' if lost else ''}{lost:,} messages lost (from header.seq)", file=sys.stderr)
        for line in source.seq.lines():
            print(line, file=sys.stderr)
    if upkeep is not None:
        state = ""
        if upkeep.budget is not None:
            met = "met" if final_bytes <= upkeep.budget else "NOT met (the segment being written is larger)"
            if _nothing_kept(stats, retention):
                met = "met only by DROPPING ALL of this run"
            state = f"; budget {human_bytes(upkeep.budget)} {met}"
        print(f"upkeep: {upkeep.dropped_segments} segments dropped, {upkeep.aged_windows:,} windows aged; store "
              f"{human_bytes(final_bytes)}{state}", file=sys.stderr)  # fmt: skip
        say_dropped_damage(args.store, upkeep.damage_dropped)
        for error in upkeep.errors:
            print(f"cclog: upkeep failed (recording went on): {error}", file=sys.stderr)
