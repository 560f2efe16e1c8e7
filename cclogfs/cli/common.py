"""What the subcommands share: argument types, the store selection of `cat` and `export`,
labels files, the progress counter, and the text formatting they print with. Subcommand
modules import this one, never each other. Only light imports here: `cclog --help` loads
every subcommand module."""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import TextIO

from ..errors import CorruptionError, DamagedError, InvalidInputError
from ..textfmt import human_bytes, iso_ns, table
from ..times import TIME_RULE, parse_time

__all__ = ["Progress", "TIME_RULE", "add_selection", "check_range", "check_store_topics", "human_bytes", "iso_ns", "load_labels",
           "nothing_matched", "parse_size", "selected_windows", "table", "time_arg"]  # fmt: skip

_SIZE = re.compile(r"(\d+(?:\.\d*)?)\s*(B|KB|MB|GB|TB|KiB|MiB|GiB|TiB)?", re.IGNORECASE)
_SIZE_UNIT = {"b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "tb": 10**12,
              "kib": 2**10, "mib": 2**20, "gib": 2**30, "tib": 2**40}  # fmt: skip


def parse_size(text: str) -> int:
    """Bytes for "500MB", "20GiB", "1048576" (no unit: bytes)."""
    m = _SIZE.fullmatch(text.strip())
    if m is None:
        raise InvalidInputError(f"Size {text!r} is not understood; give e.g. 500MB, 20GiB or a byte count.")
    return int(float(m.group(1)) * _SIZE_UNIT[(m.group(2) or "b").lower()])


def time_arg(text: str) -> int:
    """parse_time for argparse, so a bad time is reported with its own explanation."""
    try:
        return parse_time(text)
    except InvalidInputError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_selection(p: argparse.ArgumentParser) -> None:
    """STORE, --topic, --start, --end: the arguments cat and export share."""
    p.add_argument("store", help="store directory")
    p.add_argument("--topic", action="append", metavar="T",
                   help="only stream T (repeatable); default: every stream but /cclog/runs, the store's "
                        "record of its recording runs (`cclog info` lists them)")
    p.add_argument("--start", type=time_arg, metavar="TIME", help=f"from this time on ({TIME_RULE})")
    p.add_argument("--end", type=time_arg, metavar="TIME", help="up to this time (inclusive)")
    p.add_argument("--skip-damaged", action="store_true",
                   help="read every intact window of a damaged store; say on stderr what was skipped "
                        f"and exit {EXIT_SKIPPED} (without it, damage is an error)")  # fmt: skip
    add_record_limit(p)


def add_record_limit(p: argparse.ArgumentParser) -> None:
    """--max-record-mib: read records an older cclogfs wrote above the 16 MiB decode limit."""
    p.add_argument("--max-record-mib", type=record_mib, metavar="N",
                   help="decode records of up to N MiB of window (16 to 256; default 16), as older "
                        "versions wrote up to 256 MiB; reading one costs up to 16 x N MiB of memory")  # fmt: skip


def record_mib(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 16 <= value <= 256:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of MiB from 16 to 256")
    return value


# Exit status of a reading command that skipped damaged windows (--skip-damaged): not 0,
# since the answer is partial, and not 1, since it is not a failure (docs/CLI.md).
EXIT_SKIPPED = 3


def cut_tail(store) -> list[str]:
    """The torn tails the reader cut with intact records past them. Such a cut is no torn
    write: the writer's open keeps those records (a side file that `fsck --repair` puts
    back), so an answer without them is partial. A plain torn tail (nothing intact after
    it) is what a crash may lose, and is read without a word."""
    return [str(p) for p in store.recovery.problems if p.intact_after]


def refuse_cut_tail(store, skip: bool | None = False) -> list[str]:
    """`cut_tail`, refused unless `skip` (None: the command has no --skip-damaged to hint at)."""
    cut = cut_tail(store)
    if cut and not skip:
        hint = ", or read the rest with --skip-damaged" if skip is not None else ""
        raise DamagedError(f"{store.path}: intact records lie past a bad one in the unsynced tail "
                           f"({'; '.join(cut)}); a read would leave them out, so it refuses: run "
                           f"`cclog fsck --repair` to put them back{hint}", [])  # fmt: skip
    return cut


class Skipped:
    """What a reading command with --skip-damaged left out: stretches the store knows are
    damaged, and windows whose record failed a check when read."""

    def __init__(self, store, args: argparse.Namespace):
        self.skip = bool(getattr(args, "skip_damaged", False))
        self.stretches = store.damage() if self.skip else []
        self.windows = [f"{p} (past the reader's cut)" for p in refuse_cut_tail(store, self.skip)]

    def report(self) -> int:
        """Say on stderr what was skipped; the exit status."""
        if not (self.stretches or self.windows):
            return 0
        from ..store.store import describe_damage

        where = [describe_damage(d) for d in self.stretches] + self.windows
        print(f"cclog: warning: skipped {len(self.stretches)} damaged stretches and {len(self.windows)} "
              f"damaged windows: {'; '.join(where)}", file=sys.stderr)  # fmt: skip
        return EXIT_SKIPPED


def check_range(args: argparse.Namespace) -> None:
    """A backwards --start/--end is a mistake, not an empty answer."""
    if args.start is not None and args.end is not None and args.start > args.end:
        raise InvalidInputError(f"--start {iso_ns(args.start)} is after --end {iso_ns(args.end)}; "
                                "swap them.")  # fmt: skip


def what_exists(streams: dict[str, dict]) -> str:
    """The topics present and their time spans, for an error that a filter matched nothing."""
    if not streams:
        return "it holds no messages"
    spans = [f"{name} ({iso_ns(t['start_ns'])} to {iso_ns(t['end_ns'])})" if "start_ns" in t else name
             for name, t in sorted(streams.items())]  # fmt: skip
    return "it holds " + ", ".join(spans)


def nothing_matched(store, args: argparse.Namespace) -> InvalidInputError:
    """The error for a --topic/--start/--end selection that matched no message."""
    wanted = " or ".join(args.topic or ["any topic"])
    if args.start is not None and args.end is not None:
        times = f" between {iso_ns(args.start)} and {iso_ns(args.end)}"
    elif args.start is not None or args.end is not None:  # not "between ... and None"
        times = f" from {iso_ns(args.start)} on" if args.start is not None else f" up to {iso_ns(args.end)}"
    else:
        times = ""
    from ..runs import hidden_by_default

    if not any(hidden_by_default(t) for t in args.topic or ()):  # the runs' wall-clock span only when asked for
        streams = {n: st for n, st in store.streams().items() if not hidden_by_default(n)}
    else:
        streams = store.streams()
    return InvalidInputError(f"There is no message of {wanted}{times} in {store.path}; {what_exists(streams)}.")


def check_store_topics(store, args: argparse.Namespace) -> None:
    """Refuse a --topic naming no stream of the store when another --topic does: the
    others' messages came out, exit 0, and the misspelt one was never mentioned. (When none
    does, `nothing_matched` says so.)"""
    if not args.topic or len(args.topic) < 2:
        return
    streams = store.streams()
    missing = [t for t in dict.fromkeys(args.topic) if t not in streams]
    if missing and len(missing) < len(set(args.topic)):
        from ..runs import hidden_by_default

        shown = {n: st for n, st in streams.items() if not hidden_by_default(n) or n in args.topic}
        raise InvalidInputError(f"{store.path} has no stream {' or '.join(missing)}; {what_exists(shown)}.")


def selected_windows(store, args: argparse.Namespace, skipped: Skipped | None = None):
    """The store's windows for the chosen topics and times, in start order. With
    `skipped` collecting (--skip-damaged), damaged windows are left out and noted there."""
    from ..runs import hidden_by_default

    check_range(args)
    check_store_topics(store, args)
    topics = set(args.topic or ())
    name = next(iter(topics)) if len(topics) == 1 else None
    skip = skipped is not None and skipped.skip
    for w in store.query(name, start_ns=args.start, end_ns=args.end, skip_damaged=skip):
        if w.name not in topics if topics else hidden_by_default(w.name):
            continue  # without --topic, the bookkeeping of runs is left out: only messages
        if skip:
            try:
                w.check()
            except CorruptionError as err:
                skipped.windows.append(f"{os.path.basename(err.path)} at offset {err.offset}: {err.reason}")
                continue
        yield w


def newest_window(store, name: str, end_ns: int):
    """The newest intact window of stream `name` (whose last message is at `end_ns`), None
    when there is none: what `info` shows a stream's codec and type from."""
    last = None
    for last in store.query(name, start_ns=end_ns, end_ns=end_ns, skip_damaged=True):
        pass
    return last


# Why a window is held in several records (`windowcount.WindowJoiner.join`): `info` and
# `export` say it beside a count of records that differs from the windows'.
_IN_RECORDS = {
    "part": "a smart logging window is stored in parts, each topic apart, one every --window-max-s of wall time "
            "and every 10,000 messages of a topic",
    "split": "a window whose stamps go back is stored as records each in time order",
    "limit": "a window over the 16 MiB record limit is split into several",
}


def why_records(joined, stream: str | None = None) -> str:
    """Why windows are held in several records: the reasons `WindowCount.joined` found, of
    `stream` or of all."""
    found = {why for (name, why) in joined if stream is None or name == stream}
    return "; ".join(text for why, text in _IN_RECORDS.items() if why in found)


def count_windows(windows) -> tuple:
    """The `WindowCount` of stored windows (any order), as `record` counted them when it
    stored them, and where a record failed its check when read (its meta unknown, it counts
    as a window alone): every record's meta is read."""
    from ..windowcount import count_records, link_of

    records, unreadable = [], []
    for w in windows:
        try:
            records.append((w.seq, w.name, link_of(w.meta), w.continues))
        except CorruptionError as err:
            records.append((w.seq, w.name, link_of(None), False))
            unreadable.append(f"{os.path.basename(err.path)} at offset {err.offset} (seq {w.seq}): {err.reason}")
    return count_records(records), unreadable


def stored_types(store) -> dict[str, str]:
    """Stream -> the message type its newest window names, for the streams that name one
    (the type a recording into the store must keep: `jsontext.rostypes.TypeCheck`)."""
    out = {}
    for name, st in store.streams().items():
        last = newest_window(store, name, st["end_ns"])
        if last is not None and (msgtype := (last.meta or {}).get("msgtype")):
            out[name] = msgtype
    return out


def unmatched_rules_error(flag: str, rules, what: str) -> InvalidInputError:
    """The error for aging rules (`upkeep.Rule`) that match no number field: `compact --error`
    and `record --age-error` refuse them alike. `what`: what became of the data."""
    said = ", ".join(f"'{r.pattern}={r.bound:g}'" for r in rules)
    return InvalidInputError(f"{flag} {said} matches no number field of the windows to age (field patterns start "
                             f"inside msg: 'pose.covariance', not 'msg.pose.covariance'); {what}.")  # fmt: skip


def load_labels(path: str | None, stamp_ns=None, source: str = "", topic: str = ""):
    """The labelled events of a run from a JSON file (None without a path).

    With the run's odometry stamps (`stamp_ns`, of `source`'s `topic`), an event that lies
    wholly outside them is an error: labels of another run (or another clock) would
    otherwise score every event missed, or train on the anomalies, with exit 0."""
    if path is None:
        return None
    from ..classifier import parse_labels

    try:
        labels = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise InvalidInputError(f"cannot read labels {path}: {err}") from err
    try:
        events = parse_labels(labels)
    except InvalidInputError as err:
        raise InvalidInputError(f"labels {path}: {str(err).removeprefix('Labels: ')}") from err
    if stamp_ns is not None and len(stamp_ns):
        first, last = int(min(stamp_ns)), int(max(stamp_ns))
        for i, e in enumerate(events):
            if e["end_ns"] < first or e["start_ns"] > last:
                raise InvalidInputError(
                    f"labels {path}: event {i + 1} ({e['kind'] or 'no kind'}, {e['start_ns']} to {e['end_ns']} ns) "
                    f"lies outside {source}'s {topic} ({first} to {last} ns): labels of another run, or of "
                    "another clock (labels are in header stamps)?")  # fmt: skip
    return labels


class Progress:
    """Counts items; redraws at most ten times a second; silent when not on a terminal."""

    def __init__(self, label: str, *, unit: str = "msgs", stream: TextIO | None = None,
                 total: int | None = None) -> None:  # fmt: skip
        self.label, self.unit, self.total = label, unit, total
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty()
        self.count = 0
        self._t0 = self._drawn = time.monotonic()

    def __call__(self, n: int = 1) -> None:
        self.count += n
        if self.enabled and (now := time.monotonic()) - self._drawn >= 0.1:
            self._drawn = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        rate = self.count / max(now - self._t0, 1e-9)
        if self.total:  # known up front (a bag's message count): how far, and the time left
            left = max(self.total - self.count, 0) / max(rate, 1e-9)
            line = (f"{self.count:,} of {self.total:,} {self.unit} ({100 * min(self.count / self.total, 1.0):.0f} %, "
                    f"{rate:,.0f}/s, {left:,.0f} s left)")  # fmt: skip
        else:
            line = f"{self.count:,} {self.unit} ({rate:,.0f}/s)"
        self.stream.write(f"\r{self.label}: {line}\x1b[K")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self._draw(time.monotonic())
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def source_topics(path: str) -> str:
    """The topics a source holds, as an error message lists them (reads a JSONL file through)."""
    if path == "-" or "://" in path:
        return "its topics are not known up front"
    from ..errors import CclogError
    from ..ingest import open_source

    try:
        with open_source(path, on_error="skip", report=lambda err: None) as src:
            topics = set(src.topics()) or {m.topic for m in src}
    except CclogError as err:
        return f"its topics cannot be listed ({err})"
    return "it holds " + (", ".join(sorted(topics)) or "no messages")


def check_topics_exist(src, path: str, topics: list[str] | None) -> None:
    """Refuse a --topic selection of which the source (when it knows its topics) lacks one:
    with none, nothing would be read; with some, the missing one was silently left out. A
    source that learns its topics by reading (JSONL) lists the selection itself."""
    if not topics:
        return
    known = src.topics()
    missing = [t for t in dict.fromkeys(topics) if t not in known]
    if missing:
        raise InvalidInputError(f"{path} has no topic {' or '.join(missing)}; {source_topics(path)}.")


def no_source_message(path: str, topics: list[str] | None, source=None) -> InvalidInputError:
    """The error for a source that yielded no message of the selection. A damaged file's
    reader (ingest/salvage.py) says why it read nothing: that reason, not "no messages"."""
    what = f"topic {' or '.join(topics)}" if topics else "message"
    lost = getattr(source, "lost", None)
    return InvalidInputError(f"{path} yielded no {what}; " + (lost.rstrip(".") if isinstance(lost, str) else source_topics(path)) + ".")


def model_fits(model, model_path: str, source: str, topic: str, *, force: bool, texts: list | None = None) -> None:
    """Refuse a source without the model's odometry `topic` (naming what it holds and
    --odom-topic), and a robot whose rate or motion is far outside the model's training
    (a warning with --force-model). `texts`: the topic's messages when already read; else up
    to 3,000 are read from the file (a live source or stdin is checked as it is recorded)."""
    import itertools

    from ..classifier import make_features, parse_odometry
    from ..classifier.fit import compare, robot_stats
    from ..ingest import open_source

    read_all = texts is not None
    if texts is None:
        if source == "-" or "://" in source:
            return
        with open_source(source, topics=[topic], on_error="skip", report=lambda err: None) as src:
            texts = [m.text for m in itertools.islice(src, 3000)]
        read_all = len(texts) < 3000
    if not texts:
        raise InvalidInputError(f"{source} has no topic {topic}, the odometry model {model_path} scores; "
                                f"{source_topics(source)}; name the odometry topic with --odom-topic T.")  # fmt: skip
    try:
        odom = parse_odometry(texts)
    except InvalidInputError as err:  # as `cclog train` says it: which file and topic
        raise InvalidInputError(f"{source}, topic {topic}: {err}") from err
    name = source if read_all else f"{source} (the first {len(texts):,} messages)"
    check_odometry(odom, make_features(model.feature_config), name, topic, "score")
    far = compare(model.training, robot_stats([odom]))
    if far:
        said = f"model {model_path} was trained on a robot unlike {source}'s {topic}: {'; '.join(far)}"
        if not force:
            raise InvalidInputError(f"{said[0].upper()}{said[1:]}; pass --force-model to use it anyway, or train a model "
                                    "on this robot (`cclog train`).")  # fmt: skip
        print(f"cclog: warning: {said}", file=sys.stderr)


def check_odometry(odom, feature_set, name: str, topic: str, job: str):
    """Say which odometry messages of `name` the features leave out (NaN/inf values, stamps
    that do not advance; `classifier.usable`): a warning on stderr, or an error when no
    message is left to `job` ("train on", "score"). Returns the `Usable` report."""
    from ..classifier.usable import usable

    report = usable(odom, feature_set)
    if report.left_out and not report.scored:
        # "N usable" and "no feature vector" side by side need the why: usable messages far
        # apart (between left-out ones) never give the features the history they need.
        none = ""
        if report.usable:
            none = f"; none of the {report.usable:,} has the usable history before it that a feature vector needs"
        raise InvalidInputError(f"{report.describe(name, topic)}{none}; no feature vector is left to {job}.")
    if report.left_out:
        print(f"cclog: warning: {report.describe(name, topic)}; {job} the rest.", file=sys.stderr)
    return report


def repair_hint(damage: dict) -> str:
    """What clears one stretch of named damage (`Store.damage()`): the store's own rule
    (`store.repair_hint`), so that a read's refusal, `record` and `info` name one fix."""
    from ..store.store import repair_hint as store_hint  # not at the top: `cclog --help` imports this module

    return store_hint([damage])


def say_dropped_damage(store_path, damage: list[dict]) -> None:
    """Named damage retention dropped with its segment (`CompactReport.damage_dropped`): the
    windows lost there (a run's record on /cclog/runs, say) are in no stream's count, and
    the store names the damage no more, so this is the one place it is said."""
    from ..store.store import describe_damage  # not at the top: `cclog --help` imports this module

    for d in damage:
        print(f"cclog: warning: {store_path}: retention dropped a segment holding damage ({describe_damage(d)}); "
              f"{DAMAGE_LOST}", file=sys.stderr)  # fmt: skip


# What goes with named damage when retention drops its segment (said by compact and its --dry-run).
DAMAGE_LOST = ("the windows lost there (messages, or a run's record on /cclog/runs) are counted in no stream "
               "and are named no more")  # fmt: skip


DAMAGED_EXIT = 4  # the input was damaged: what could be read was kept


def damaged_exit(source) -> int:
    """0, or DAMAGED_EXIT after saying what a damaged input lost (`ingest.salvage`), or when
    --on-error skip left bad lines or messages out (the caller has said how many): a script
    checking the exit code must learn that the output is not the whole input, as it does
    for a skipped MCAP chunk."""
    note = getattr(source, "note", None)
    if note:
        print(f"cclog: note: {note}", file=sys.stderr)
    lost = getattr(source, "lost", None)
    if lost is not None:
        print(f"cclog: input damaged, kept what could be read: {lost}", file=sys.stderr)
        return DAMAGED_EXIT
    return DAMAGED_EXIT if getattr(source, "skipped", 0) else 0


# The store's errors name its Python API; on the command line they name the command.
_API_WORDS = {
    "pass create=True to make one": "`cclog record SOURCE --store PATH` makes one",
    "open it with readonly=True to read": "commands that only read (info, cat, export, play) work meanwhile",
    "raise cclogfs.store.format.DECODE_RAW_LIMIT (at most 256 MiB) before opening the store":
        "pass --max-record-mib N (N at most 256) to cat, export or fsck",
}


# The store's refusal to read past damage ends so; a command without the flag (play, plot)
# named a flag it refuses ("unrecognized arguments").
_SKIP_HINT = "or read the intact windows with --skip-damaged"


def cli_words(message: str, *, skip_damaged: bool = True) -> str:
    """A store error's text with the words of the command line for its Python API.
    `skip_damaged`: whether the command has --skip-damaged; else its hint names those that do."""
    for api, cli in _API_WORDS.items():
        message = message.replace(api, cli)
    if not skip_damaged:
        message = message.replace(_SKIP_HINT, "or read the intact windows with `cclog cat --skip-damaged` or "
                                              "`cclog export --skip-damaged` (this command has no --skip-damaged)")
    return message
