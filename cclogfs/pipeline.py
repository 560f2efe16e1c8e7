"""The pipeline: messages from a source, through a window policy, into the store.

With the CLI, this is the only place that knows both the classifier and the store. A
*window policy* is any object with `push(topic, stamp_ns, text) -> [window]` and
`flush() -> [window]`, each a `PendingWindow` (topic, messages, meta):
`KeepAll` keeps every message (the paper's collect mode), the classifier's `SmartLogger`
keeps only logging windows around anomalies (smart mode).
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from itertools import groupby, repeat
from operator import eq, itemgetter, le
from typing import Any, Protocol

from ._signals import signals_deferred as _signals_deferred
from .classifier.features import RAW_NAMES, PoseOnly, odom_row, odom_rows_flagged
from .classifier.summary import SUMMARY_TOPIC
from .classifier.windows import PendingWindow
from .errors import InvalidInputError, StoreError
from .jsontext.check import text_error
from .jsontext.rostypes import StreamTypes, reserved_refusal
from .runs import RUNS_STREAM
from .store import Store, open_store
from .upkeep import Upkeep
from .windowcount import CountedTotals, WindowCount, link_of

# Default logging-window extents, in seconds so they mean the same at any odometry rate.
# The window starts `before` ahead of where the anomaly's evidence starts, not of the first
# flagged message: a feature seen over an 8 s window (a spin's net rotation, a stuck robot's
# reversals) makes the window reach back to where that feature's evidence starts, at most
# 8 s (WindowBuilder lookback, classifier.evidence; issue 15's seventh pass: no longer its
# whole span), also when it flags after a quicker feature opened the window, so the slow
# anomalies recognised seconds after they start keep their start without 8 s of context
# around every jolt. 0.5 s after,
# with hysteresis and a 4.5 s merge gap (classifier.api HOLD_SCORE, MERGE_S): the window
# closes soon after the score falls, and the flagged stretches of one event stay one window.
# Issue 15's sixth pass halved both (2 s and 1 s before): the short features look 0.55 s
# back, so 1 s before covers a first flag up to 1.55 s late, and the last flag already comes
# ~0.5 s after an event's end; the long runs lost no event and kept 2-3 % less of the log
# at one anomaly a minute (bench/classifier_long.py --breakdown, docs/CLASSIFIER.md).
WINDOW_BEFORE = "1s"
WINDOW_AFTER = "0.5s"


class WindowPolicy(Protocol):
    def push(self, topic: str, stamp_ns: int, text: str) -> list[PendingWindow]: ...

    # Optional, for sources that hand over lists: `push` of each (topic, stamp_ns, text, ...).
    # def push_many(self, messages: Sequence[Any]) -> list[PendingWindow]: ...

    def cut(self) -> list[PendingWindow]: ...

    def flush(self) -> list[PendingWindow]: ...


# A message's (stamp_ns, text): what a window holds of it.
_STAMP_TEXT = itemgetter(1, 2)


class KeepAll:
    """Every message kept, cut per topic into windows of `chunk` messages or `chunk_s` seconds."""

    def __init__(self, *, chunk: int = 200, chunk_s: float | None = None):
        if chunk < 1:
            raise ValueError("chunk must be at least 1 message")
        self.chunk = chunk
        self.chunk_ns = None if chunk_s is None else int(chunk_s * 1e9)
        self.open: dict[str, list[tuple[int, str]]] = {}

    def push(self, topic: str, stamp_ns: int, text: str) -> list[PendingWindow]:
        buf = self.open.setdefault(topic, [])
        out = []
        if buf and self.chunk_ns is not None and stamp_ns - buf[0][0] >= self.chunk_ns:
            out.append(self._close(topic))
            buf = self.open.setdefault(topic, [])
        buf.append((stamp_ns, text))
        if len(buf) >= self.chunk:
            out.append(self._close(topic))
        return out

    def push_many(self, messages: Sequence[Any]) -> list[PendingWindow]:
        """`push` of each (topic, stamp_ns, text, ...) in turn, the windows closed in order:
        for a source that hands over many messages at once (issue 14)."""
        if self.chunk_ns is not None:
            return [w for m in messages for w in self.push(m[0], m[1], m[2])]
        out = []
        open_, chunk = self.open, self.chunk
        for topic, run in groupby(messages, itemgetter(0)):  # a run of one topic: slices of it
            pairs = list(map(_STAMP_TEXT, run))
            start = 0
            while start < len(pairs):
                buf = open_.get(topic)
                if buf is None:  # (re)opened only for a message: flush keeps `push`'s order
                    buf = open_[topic] = []
                end = start + chunk - len(buf)
                buf += pairs[start:end]
                start = end
                if len(buf) >= chunk:
                    out.append(self._close(topic))
        return out

    def _close(self, topic: str) -> PendingWindow:
        return PendingWindow(topic, self.open.pop(topic), {"kind": "all"})

    def cut(self) -> list[PendingWindow]:
        """Every open window now, however short: a bound on what a hard kill loses."""
        return self.flush()

    def flush(self) -> list[PendingWindow]:
        return [self._close(t) for t in list(self.open) if self.open[t]]


def monotonic_runs(messages: list[tuple[int, str]]) -> Iterator[list[tuple[int, str]]]:
    """Split where a stamp goes backwards (header stamps of some topics do): the store keeps
    each window's messages in time order, and a split keeps every message, in put order."""
    stamps = list(map(itemgetter(0), messages))
    if all(map(le, stamps, stamps[1:])):  # the usual window, checked in C, not a step a message
        yield messages
        return
    start = 0
    for i in range(1, len(messages)):
        if messages[i][0] < messages[i - 1][0]:
            yield messages[start:i]
            start = i
    yield messages[start:]


@dataclass
class RecordStats(CountedTotals):
    """What a recording run saw and kept."""

    messages_in: int = 0
    json_bytes_in: int = 0
    messages_kept: int = 0
    json_bytes_kept: int = 0
    seconds: float = 0.0
    topics_in: dict[str, int] = field(default_factory=dict)
    topics_kept: dict[str, int] = field(default_factory=dict)
    interrupted: bool = False
    # the windows stored, each counted once however many records hold it (`windowcount`)
    counted: WindowCount = field(default_factory=WindowCount)

    def saw(self, topic: str, text: str) -> None:
        """Count one message that came in."""
        self.messages_in += 1
        self.json_bytes_in += len(text)
        self.topics_in[topic] = self.topics_in.get(topic, 0) + 1

    def saw_many(self, topics: Iterable[str], texts: list[str]) -> None:
        """Count messages that came in (`saw` of each)."""
        self.messages_in += len(texts)
        self.json_bytes_in += sum(map(len, texts))
        for topic, n in Counter(topics).items():  # first seen first, as `saw` adds them
            self.topics_in[topic] = self.topics_in.get(topic, 0) + n


def reserved_topics(policy: Any) -> frozenset[str]:
    """The streams a recording writes itself, which no source message may join: the runs
    (else `cat` would leave the source's messages out as bookkeeping, and `cclog info` read
    them as runs), and the summary of a policy that writes one (a keep-all recording of a
    smart store's export keeps that store's summary as it was)."""
    if getattr(policy, "summary", None) is not None:
        return frozenset((RUNS_STREAM, SUMMARY_TOPIC))
    return frozenset((RUNS_STREAM,))


def check_message(topic: str, stamp_ns: Any, text: Any, *, check_json: bool = True,
                  reserved: frozenset[str] = frozenset()) -> None:  # fmt: skip
    """InvalidInputError for a message the store would refuse, before any policy holds it
    (a window refused later would lose the good messages it holds too). The store's own
    check (`text_error`); `check_json=False` skips only the JSON parse. `reserved`: topics
    the recording writes itself (`reserved_topics`)."""
    if topic in reserved:  # a backstop: the sources refuse it first, naming the line (`TypeCheck`)
        raise InvalidInputError(f"message at {stamp_ns}: {reserved_refusal(topic)}")
    if (why := text_error(text, check_json=check_json)) is not None:
        raise InvalidInputError(f"message on {topic!r} at {stamp_ns} {why}")


def first_bad_text(texts: list[Any], *, check_json: bool = True) -> int | None:
    """The index of the first text `check_message` refuses, None when it takes them all:
    for many texts at once, without JSON checks, first the cheap one of each text (a str,
    all ASCII: a flag each)."""
    if not check_json:
        try:
            if all(map(str.isascii, texts)):  # no copy of the texts, as a join made
                return None
        except TypeError:  # not all str: the loop below names the first
            pass
    return next((i for i, text in enumerate(texts) if text_error(text, check_json=check_json) is not None), None)


def store_window(store: Store, window: PendingWindow, stats: RecordStats, types: StreamTypes | None = None) -> None:
    """Put one window (several records when its stamps go backwards). Its messages were
    checked when they came in (`check_message`), so the store does not parse them again.
    `types`: the streams' message types, added to the window's metadata."""
    runs = list(monotonic_runs(window.messages))
    base = window.meta if types is None else types.meta(window.topic, window.meta)
    records = 0
    for k, part in enumerate(runs):
        meta = base if len(runs) == 1 else {**base, "split": [k, len(runs)]}
        records += store.put_window(window.topic, part, meta, check_json=False).records
    # one window however many records hold it, as `cclog info` counts it in the store
    stats.counted.add(window.topic, link_of(window.meta), records=records)
    if window.meta.get("kind") == "summary":  # made by the recorder, not a message that came in
        return
    n = len(window.messages)
    stats.messages_kept += n
    stats.json_bytes_kept += sum(map(len, map(itemgetter(1), window.messages)))
    stats.topics_kept[window.topic] = stats.topics_kept.get(window.topic, 0) + n


def record(messages: Iterable[Any], store: Store, policy: WindowPolicy, *,
           check_json: bool = True, progress: Callable[[RecordStats], None] | None = None,
           stats: RecordStats | None = None, upkeep: Upkeep | None = None,
           types: StreamTypes | None = None, window_s: float | None = None) -> RecordStats:  # fmt: skip
    """Feed messages (objects with .topic, .stamp_ns, .text) through `policy` into `store`.

    On any exit, Ctrl-C included, the policy's open windows are flushed into the store, so
    nothing already seen is lost; the caller closes (and so syncs) the store.
    `check_json=False`: the source already parsed every text (JSONL, bags), skip the
    JSON re-parse (the cheap checks still run: a window the store refused would lose the
    good messages it holds).
    `upkeep`: retention and aging as segments are sealed (`compact.Upkeep`); the caller
    closes it before the store. `types`: keep each stream's message type (`m.msgtype`) in
    its windows' metadata (`jsontext.rostypes.StreamTypes`). `window_s`: every this many
    seconds of wall time the policy's open windows are cut and stored (`policy.cut()`), so a
    hard kill loses at most that much plus the store's sync interval.
    """
    stats = stats or RecordStats()
    started = time.perf_counter()
    cut = _Cutter(store, policy, stats, types, window_s)
    batches = getattr(messages, "batches", None)
    loop_args = {"check_json": check_json, "progress": progress, "stats": stats, "upkeep": upkeep, "types": types,
                 "reserved": reserved_topics(policy)}
    try:
        if batches is not None and hasattr(policy, "push_many"):  # JSONL: a list of messages at a time
            _record_batches(batches(), store, policy, cut, **loop_args)
        else:
            _record_each(messages, store, policy, cut, **loop_args)
    except KeyboardInterrupt:
        stats.interrupted = True
    finally:
        with _signals_deferred():  # a second Ctrl-C must not cut the flush short
            for window in policy.flush():
                store_window(store, window, stats, types)
        stats.seconds = time.perf_counter() - started
    return stats


class _Cutter:
    """Every `window_s` seconds of wall time, the policy's open windows cut and stored."""

    def __init__(self, store: Store, policy: WindowPolicy, stats: RecordStats, types: StreamTypes | None,
                 window_s: float | None) -> None:  # fmt: skip
        self.store, self.policy, self.stats, self.types = store, policy, stats, types
        self.window_s = window_s
        self.at = time.monotonic() + window_s if window_s else math.inf

    def if_due(self) -> None:
        if (now := time.monotonic()) >= self.at:
            self.at = now + self.window_s
            for window in self.policy.cut():
                store_window(self.store, window, self.stats, self.types)


def _after_put(store: Store, upkeep: Upkeep | None) -> None:
    """After a critical section (the windows taken are stored): upkeep, then a Ctrl-C
    that waited for the section."""
    if upkeep is not None:
        upkeep.after_put(store)
    if INTERRUPTS.pending:
        INTERRUPTS.pending = False
        raise KeyboardInterrupt


def _record_each(messages: Iterable[Any], store: Store, policy: WindowPolicy, cut: _Cutter, *,
                 check_json: bool, progress: Callable[[RecordStats], None] | None, stats: RecordStats,
                 upkeep: Upkeep | None, types: StreamTypes | None, reserved: frozenset[str]) -> None:  # fmt: skip
    """`record`'s loop, a message at a time."""
    for m in messages:
        check_message(m.topic, m.stamp_ns, m.text, check_json=check_json, reserved=reserved)
        stats.saw(m.topic, m.text)
        if types is not None:
            types.saw(m.topic, getattr(m, "msgtype", ""))
        # A window taken from the policy must reach the store: with interrupt_handler
        # installed, Ctrl-C waits for the end of this section.
        INTERRUPTS.critical = True
        try:
            for window in policy.push(m.topic, m.stamp_ns, m.text):
                store_window(store, window, stats, types)
            cut.if_due()
        finally:
            INTERRUPTS.critical = False
        _after_put(store, upkeep)
        if progress is not None and stats.messages_in % 4096 == 0:
            progress(stats)


def _record_batches(batches: Iterable[Sequence[Any]], store: Store, policy: Any, cut: _Cutter, *,
                    check_json: bool, progress: Callable[[RecordStats], None] | None, stats: RecordStats,
                    upkeep: Upkeep | None, types: StreamTypes | None, reserved: frozenset[str]) -> None:  # fmt: skip
    """`record`'s loop for a policy with `push_many` (KeepAll, SmartLogger) and a source
    that hands over lists of messages, each a (topic, stamp_ns, text, msgtype) tuple
    (`JsonlSource.batches`): the checks, counts and pushes of a list at once, the same
    windows stored in the same order, the same error for the first bad message after the
    messages before it (per message, these cost 1.3-2 us; issue 14)."""
    for batch in batches:
        texts = list(map(itemgetter(2), batch))
        bad = first_bad_text(texts, check_json=check_json)
        if not reserved.isdisjoint(map(itemgetter(0), batch)):
            first = next(i for i, m in enumerate(batch) if m[0] in reserved)
            bad = first if bad is None else min(bad, first)
        refused = None
        if bad is not None:
            refused, batch, texts = batch[bad], batch[:bad], texts[:bad]
        before = stats.messages_in
        stats.saw_many(map(itemgetter(0), batch), texts)
        if types is not None and any(map(itemgetter(3), batch)):  # JSONL lines seldom name a type
            for m in batch:
                types.saw(m[0], m[3])
        INTERRUPTS.critical = True  # as in `record`: the windows taken reach the store
        try:
            for window in policy.push_many(batch):
                store_window(store, window, stats, types)
            cut.if_due()
        finally:
            INTERRUPTS.critical = False
        _after_put(store, upkeep)
        if progress is not None and stats.messages_in // 4096 > before // 4096:
            progress(stats)
        if refused is not None:  # after the messages before it, as message by message
            check_message(refused.topic, refused.stamp_ns, refused.text, check_json=check_json, reserved=reserved)


class _Interrupts:
    """State shared by `interrupt_handler` and the critical sections of `record`."""

    critical = False
    pending = False


INTERRUPTS = _Interrupts()


def interrupt_handler(signum: int, frame: Any) -> None:
    """A SIGINT/SIGTERM handler for programs that run `record` (the CLI installs it): it
    raises KeyboardInterrupt, but not in the middle of storing a window."""
    if INTERRUPTS.critical:
        INTERRUPTS.pending = True
    else:
        raise KeyboardInterrupt




class Logger:
    """cclogfs inside a running robot program: hand it each message, it logs into a store.

        with Logger("robot.store", model="odom.model", topics=["/odom", "/tf"]) as log:
            log("/odom", stamp_ns, json_text)      # or log(source_message), e.g. as the
                                                   # sink of ingest.live.LiveSource
    Without `model` every message is kept (in windows of `chunk`); with it, only logging
    windows around anomalies. Thread-safe: executor callbacks may call it concurrently.
    Puts become durable by the store's group commit (`sync_every_ms`); `close()` flushes
    the open windows and syncs. With `upkeep` (`compact.Upkeep`), the oldest segments are
    dropped to a budget and old windows aged (in a background thread) as segments seal.
    """

    def __init__(self, store_path: str, *, model: Any = None, topics: Iterable[str] | None = None,
                 before: str = WINDOW_BEFORE, after: str = WINDOW_AFTER, chunk: int = 200, codec: Any = "columnar",
                 sync_every_ms: float | None = 200, upkeep: Upkeep | None = None) -> None:  # fmt: skip
        self.topics = None if topics is None else frozenset(topics)
        self.policy = (smart_policy(model, topics=topics, before=before, after=after)
                       if model is not None else KeepAll(chunk=chunk))  # fmt: skip
        options = upkeep.store_options() if upkeep is not None else {}
        self.store: Store | None = open_store(store_path, create=True, codec=codec, sync_every_ms=sync_every_ms,
                                              **options)  # fmt: skip
        self.stats = RecordStats()
        self.types = StreamTypes()  # filled when called with messages that carry .msgtype
        self.upkeep = upkeep
        self._lock = threading.Lock()

    def __call__(self, topic_or_message: Any, stamp_ns: int | None = None, text: str | None = None) -> None:
        msgtype = ""
        if stamp_ns is None:
            m = topic_or_message
            topic_or_message, stamp_ns, text = m.topic, m.stamp_ns, m.text
            msgtype = getattr(m, "msgtype", "")
        topic = topic_or_message
        if self.topics is not None and topic not in self.topics and topic != getattr(self.policy, "odom_topic", None):
            return
        # at the door: a bad message must not take a window with it
        check_message(topic, stamp_ns, text, reserved=reserved_topics(self.policy))
        with self._lock:
            if self.store is None:
                raise StoreError("this Logger is closed")
            self.stats.saw(topic, text)
            self.types.saw(topic, msgtype)
            for window in self.policy.push(topic, stamp_ns, text):
                store_window(self.store, window, self.stats, self.types)
            if self.upkeep is not None:
                self.upkeep.after_put(self.store)

    def close(self) -> None:
        with self._lock:
            if self.store is None:
                return
            try:
                with _signals_deferred():
                    for window in self.policy.flush():
                        store_window(self.store, window, self.stats, self.types)
            finally:
                try:
                    if self.upkeep is not None:
                        self.upkeep.close()  # before the store: its thread may be reading segments
                finally:
                    self.store.close()
                    self.store = None

    def __enter__(self) -> Logger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- smart logging: the classifier's policy, built from a model file ------------------------


def parse_span(text: str) -> tuple[int, float | None]:
    """A window extent: "100" (messages) or "4s" / "2.5s" (seconds) -> (messages, seconds)."""
    from .errors import InvalidInputError

    t = str(text).strip()
    try:
        if t.endswith("s"):
            secs = float(t[:-1])
            if not 0 <= secs < math.inf:  # NaN and inf passed `secs < 0`, then failed as ints
                raise ValueError
            return 0, secs
        n = int(t)
        if n < 0:
            raise ValueError
        return n, None
    except ValueError as err:
        raise InvalidInputError(f"window extent {text!r} must be a message count like 100 or "
                                "a duration like 4s") from err  # fmt: skip


def smart_policy(model: Any, *, topics: Iterable[str] | None = None, before: str = WINDOW_BEFORE,
                 after: str = WINDOW_AFTER, summary: bool = True, odom_topic: str | None = None) -> Any:  # fmt: skip
    """The classifier's SmartLogger for `model` (a path or a loaded OneClassModel), keeping
    the odometry it cannot score (`KeepUnscored`).

    `topics`: the topics to log over each window (None: every topic seen); the odometry
    topic (`odom_topic`, by default the model's own) is always scored and logged.
    """
    from .classifier import Detector, OneClassModel, SmartLogger

    if not hasattr(model, "score"):
        model = OneClassModel.load(model)
    b_n, b_s = parse_span(before)
    a_n, a_s = parse_span(after)
    return KeepUnscored(SmartLogger(Detector(model), odom_topic=odom_topic or model.topic, topics=topics,
                                    before=b_n, after=a_n, before_s=b_s, after_s=a_s, batch=64,
                                    summary_period_s=60.0 if summary else None))  # fmt: skip


class KeepUnscored:
    """Smart logging (`policy`, a SmartLogger) that keeps the odometry its model cannot judge.

    The features skip an odometry message with a NaN or infinite value (`classifier.usable`):
    it gets no score of its own, so the SmartLogger kept it only inside a window some other
    message opened, and a run whose odometry broke (an estimator that diverged, a sensor
    fault) lost those messages with exit 0. Here each one bypasses the classifier and is
    kept, in windows of kind "unscored" on the odometry topic; `unscored` and `first` (stamp,
    field) say how many and which, for the end summary. The other topics are kept as the
    classifier's windows decide. Every other attribute is the SmartLogger's.
    """

    def __init__(self, policy: Any, *, chunk: int = 200) -> None:
        self.policy = policy
        self.keep = KeepAll(chunk=chunk)
        self.unscored = 0
        self.first: tuple[int, str] | None = None

    def __getattr__(self, name: str) -> Any:  # odom_topic, scored, summary, detector, ...
        return getattr(self.__dict__["policy"], name)

    def push(self, topic: str, stamp_ns: int, text: str) -> list[PendingWindow]:
        if topic == self.policy.odom_topic and (field := _nonfinite_field(text)) is not None:
            return self._keep(stamp_ns, text, field)
        return self.policy.push(topic, stamp_ns, text)

    def push_many(self, messages: Sequence[Any]) -> list[PendingWindow]:
        """`push` of each, the runs between unscored messages handed on at once."""
        odom = self.policy.odom_topic
        if all(map(eq, map(itemgetter(0), messages), repeat(odom))):  # the usual list: odometry alone
            rows, flagged = odom_rows_flagged(list(map(itemgetter(2), messages)))
        else:
            at = [i for i, m in enumerate(messages) if m[0] == odom]
            rows, flagged = odom_rows_flagged([messages[i][2] for i in at])
            flagged = [at[k] for k in flagged]
        # The compiled reader flags the rows it declined or found a NaN or infinite value in:
        # only those are read again here, for the field to name (issue 14).
        bad = [(i, f) for i in flagged if (f := _nonfinite_field(messages[i][2])) is not None]
        if not bad:  # the policy takes the rows read here: one compiled read of each message, not two
            return self.policy.push_many(messages, rows=rows)
        out: list[PendingWindow] = []
        start = 0
        for i, field in bad:
            out += self.policy.push_many(messages[start:i])
            out += self._keep(messages[i][1], messages[i][2], field)
            start = i + 1
        return out + self.policy.push_many(messages[start:])

    def _keep(self, stamp_ns: int, text: str, field: str) -> list[PendingWindow]:
        self.unscored += 1
        if self.first is None:
            self.first = (stamp_ns, field)
        return [self._mark(w) for w in self.keep.push(self.policy.odom_topic, stamp_ns, text)]

    def _mark(self, window: PendingWindow) -> PendingWindow:
        window.meta = {"kind": "unscored", "why": "NaN or infinite odometry values",
                       "model_id": self.policy.windows.model_id}
        return window

    def cut(self) -> list[PendingWindow]:
        return self.policy.cut() + [self._mark(w) for w in self.keep.cut()]

    def flush(self) -> list[PendingWindow]:
        return self.policy.flush() + [self._mark(w) for w in self.keep.flush()]


def _finite(row: Sequence[float]) -> bool:
    return math.isfinite(sum(row)) or all(map(math.isfinite, row))


def _nonfinite_field(text: str) -> str | None:
    """The first odometry value (`classifier.features.RAW_NAMES`) of `text` that is NaN or
    infinite, None when the features can use them all. A pose-only message's twist is NaN
    until the classifier fills it from the poses; a text the reader refuses is the
    classifier's to name (None here)."""
    try:
        _, row = odom_row(text)
    except InvalidInputError:
        return None
    values = row[:7] if isinstance(row, PoseOnly) else row
    if _finite(values):
        return None
    return next(RAW_NAMES[k] for k, v in enumerate(values) if not math.isfinite(v))


def read_topic(path: str, topic: str) -> list[tuple[int, str]]:
    """(stamp_ns, JSON text) of one topic of any source (bag, MCAP, JSONL)."""
    from .ingest import open_source

    with open_source(path, topics=[topic]) as source:
        return [(m.stamp_ns, m.text) for m in source]


def evaluate_run(messages: list[tuple[str, int, str]], model: Any, labels: Any, *, before: str = WINDOW_BEFORE,
                 after: str = WINDOW_AFTER, odom_topic: str | None = None) -> dict:  # fmt: skip
    """Score a labelled run as smart logging would: the paper's per-message Table 1, the
    per-event figures, and what fraction of messages and JSON bytes would be kept."""
    from .classifier import event_table, message_table, parse_odometry, window_spans

    policy = smart_policy(model, before=before, after=after, summary=False, odom_topic=odom_topic)
    topic = policy.odom_topic
    windows = policy.replay(messages)
    odom = parse_odometry(text for t, _, text in messages if t == topic)
    scores, flags = policy.detector.score_batch(odom)
    total_bytes = sum(len(text) for _, _, text in messages)
    return {
        "messages": message_table(odom.stamp_ns, flags, labels),
        "events": event_table(odom.stamp_ns, window_spans(windows, topic), labels, flags),
        "kept_messages": sum(len(w.messages) for w in windows),
        "total_messages": len(messages),
        "kept_bytes": sum(len(t) for w in windows for _, t in w.messages),
        "total_bytes": total_bytes,
        "scores": scores,
        "stamps": odom.stamp_ns,
        "windows": windows,
    }
