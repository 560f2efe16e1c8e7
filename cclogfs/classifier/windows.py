"""Logging windows around anomalies: pure logic, no I/O.

The trigger topic (odometry) decides. A ring keeps the last `before` messages (or
`before_s` seconds); an anomalous message opens a window with that context, and the
window stays open until `after` messages (or `after_s` seconds) have passed since the last
anomalous one. In seconds mode an anomaly may say how far back its evidence reaches
(`lookback_ns`): the window starts `before_s` ahead of that, and a later anomaly of the
open window whose evidence reaches further back than the window's start extends it back
(what the start left out is kept for that, within `lookback_max_s`). The window is then
held until `before` more messages have passed: if an anomaly comes first, its context would overlap (or touch) the window, so the two merge
and no message is logged twice. Other topics are logged over the window's time span
[first, last trigger-topic stamp], whatever order they arrive in. Latched topics (e.g.
/tf_static) are kept and added to every window so each window can be read alone: the newest
MAX_LATCHED distinct texts per topic, the count of older ones dropped in "latched_dropped".
A window longer than `max_part` messages of a topic is emitted in parts that share its
window_id.

Memory stays bounded however the stamps behave: in seconds mode the ring holds at most
`max_ring` messages (a held window closes when it fills), each pending queue at most
`max_pending`, and a trigger stamp more than CLOCK_RESET_NS behind the previous one (a clock
reset) is a gap: the open window closes and nothing queued before it joins a later window.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field
from operator import le, lt

from ..errors import InvalidInputError

__all__ = ["PendingWindow", "WindowBuilder"]

MAX_TRIGGERS_IN_META = 100
MAX_LATCHED = 64  # distinct texts kept per latched topic
CLOCK_RESET_NS = 1_000_000_000  # small backward jitter is not a reset


@dataclass
class PendingWindow:
    """A window to store: messages of one topic, in arrival order, with the window's
    metadata. What a window policy emits (WindowBuilder here, the pipeline's KeepAll) and
    the pipeline hands to the store, which keeps it as a record."""

    topic: str
    messages: list[tuple[int, str]]
    meta: dict = field(default_factory=dict)

    @property
    def start_ns(self) -> int:
        return self.messages[0][0]

    @property
    def end_ns(self) -> int:
        return self.messages[-1][0]


@dataclass
class _Open:
    window_id: str
    start_ns: int
    last_ns: int
    parts: dict[str, list[tuple[int, str]]] = field(default_factory=dict)
    part_no: dict[str, int] = field(default_factory=dict)
    triggers: list[int] = field(default_factory=list)
    n_triggers: int = 0
    peak_score: float = -math.inf
    peak_ns: int = 0
    left: int = 0  # trigger-topic messages still to log after the last anomaly
    until_ns: int = 0  # or: log up to this stamp
    closing: bool = False


class WindowBuilder:
    """Feed (topic, stamp_ns, text) in arrival order; get PendingWindows as they close."""

    def __init__(
        self,
        *,
        trigger_topic: str = "/odom",
        topics: set[str] | list[str] | None = None,
        latched: tuple[str, ...] = ("/tf_static",),
        before: int = 100,
        after: int = 100,
        before_s: float | None = None,
        after_s: float | None = None,
        max_part: int = 10_000,
        max_pending: int = 100_000,
        max_ring: int = 100_000,
        lookback_max_s: float = 0.0,
        merge_s: float = 0.0,
        hold_score: float | None = None,
        model_id: str = "",
    ):
        if before < 0 or after < 0 or max_part < 1 or max_ring < 1:
            raise InvalidInputError(
                "Window sizes need before >= 0, after >= 0, max_part >= 1, max_ring >= 1."
            )
        self.trigger_topic = trigger_topic
        self.topics = None if topics is None else set(topics) | {trigger_topic}
        self.latched_topics = set(latched)
        self.before, self.after = before, after
        self.before_ns = None if before_s is None else int(before_s * 1e9)
        self.after_ns = None if after_s is None else int(after_s * 1e9)
        # Seconds mode: an anomaly may say how far back its evidence reaches (`lookback_ns`
        # in push); the ring then keeps that much more context, up to lookback_max_s.
        self.lookback_max_ns = int(lookback_max_s * 1e9) if before_s is not None else 0
        # Seconds mode: an anomaly whose context comes within merge_s of a closed window
        # joins it (the gap is logged): one event flagged twice (a collision's stop and
        # restart seconds later) stays one window, with short context around each.
        self.merge_ns = int(merge_s * 1e9) if before_s is not None else 0
        # Hysteresis (seconds mode): while a window is open, a message scoring above
        # hold_score (below 0: not anomalous, but close) keeps it open like an anomaly.
        self.hold_score = hold_score if after_s is not None else None
        self.max_part = max_part
        self.max_pending = max_pending
        self.max_ring = max_ring
        self.model_id = model_id
        self.ring: deque[tuple[int, str]] = deque()  # trigger-topic context, not yet logged
        self.pending: dict[str, deque[tuple[int, str]]] = {}  # other topics, not yet logged
        self.latched: dict[str, dict[str, int]] = {}  # topic -> text -> stamp, oldest first
        self.latched_dropped: dict[str, int] = {}
        self.last_trigger_ns: int | None = None
        # False once a trigger stamp went back: the ring may then be out of order, and
        # `push_run` checks it before taking a stretch at once.
        self.ring_in_order = True
        self.window: _Open | None = None
        # Seconds mode with lookback: what the open window's start left out, within the
        # longest lookback, so that a later anomaly whose evidence reaches further back
        # (a slow feature after a quick one) extends the window back (`_reach_back`).
        self.back: deque[tuple[int, str]] = deque()
        self.back_other: dict[str, list[tuple[int, str]]] = {}
        self.windows_emitted = 0

    # -- input ------------------------------------------------------------------------

    def push(
        self, topic: str, stamp_ns: int, text: str, *, anomalous: bool = False,
        score: float = math.nan, lookback_ns: int = 0,
    ) -> list[PendingWindow]:  # fmt: skip
        """One message; `anomalous`/`score`/`lookback_ns` matter only on the trigger topic.
        `lookback_ns`: how long before this message the anomaly's evidence starts (the
        window then starts `before` earlier than that, within lookback_max_s)."""
        if topic in self.latched_topics:
            kept = self.latched.setdefault(topic, {})
            if text not in kept:
                if len(kept) >= MAX_LATCHED:  # the newest state matters most: drop the oldest
                    del kept[next(iter(kept))]
                    self.latched_dropped[topic] = self.latched_dropped.get(topic, 0) + 1
                kept[text] = stamp_ns
            return []
        if self.topics is not None and topic not in self.topics:
            return []
        if topic != self.trigger_topic:
            return self._push_other(topic, stamp_ns, text)
        out: list[PendingWindow] = []
        last, self.last_trigger_ns = self.last_trigger_ns, stamp_ns
        if last is not None and stamp_ns < last:
            self.ring_in_order = False
            if stamp_ns < last - CLOCK_RESET_NS:
                self._reset(out)
        w = self.window
        reach = min(max(lookback_ns, 0), self.lookback_max_ns)
        if w is None:
            self.ring.append((stamp_ns, text))
            self._trim_ring(stamp_ns)
            if anomalous:
                self._start(stamp_ns, reach, score, out)
        elif not w.closing:
            self._add(self.trigger_topic, [(stamp_ns, text)], out)
            w.last_ns = stamp_ns
            self._take_pending(stamp_ns, out)
            if anomalous:
                if self.back and self.back[-1][0] >= stamp_ns - reach - self.before_ns:  # inline: most do not
                    self._reach_back(stamp_ns - reach, out)
                self._trigger(stamp_ns, score)
            else:
                if self.hold_score is not None and score > self.hold_score:
                    w.until_ns = max(w.until_ns, stamp_ns + self.after_ns)
                w.left -= 1
                if (w.left <= 0) if self.after_ns is None else (stamp_ns >= w.until_ns):
                    w.closing = True
        else:
            self.ring.append((stamp_ns, text))
            if anomalous and self.lookback_max_ns and stamp_ns - reach - self.before_ns - self.merge_ns > w.last_ns:
                self._close(out)  # its context does not reach the held window: a new one
                self._start(stamp_ns, reach, score, out)
            elif anomalous:  # its context reaches back into the held window: merge
                w.closing = False
                self._add(self.trigger_topic, list(self.ring), out)
                self.ring.clear()
                w.last_ns = stamp_ns
                self._take_pending(stamp_ns, out)
                self._reach_back(stamp_ns - reach, out)
                self._trigger(stamp_ns, score)
            elif (
                len(self.ring) > self.before
                if self.before_ns is None
                else stamp_ns - w.last_ns > self.before_ns + self.merge_ns + self.lookback_max_ns
                or len(self.ring) > self.max_ring
            ):
                self._close(out)
                self._trim_ring(stamp_ns)
        return out

    def push_run(self, stamps: list[int], texts: list[str], anomalous: list[bool], scores: list[float],
                 lookbacks: list[int]) -> list[PendingWindow]:  # fmt: skip
        """`push` of consecutive trigger-topic messages, in order, with their `anomalous`,
        `score` and `lookback_ns`: the same windows in the same order.

        Most messages only join the ring: no window is open, or the open one is held
        (closing), the message is not anomalous and its stamp does not go back. Such a
        stretch is taken at once, one extend of the ring and at most one trim instead of one
        per message (issue 14); every other message goes through `push`."""
        n = len(stamps)
        if not n:
            return []
        if self.trigger_topic in self.latched_topics:  # `push` keeps them apart from the ring
            return [w for k in range(n) for w in self.push(self.trigger_topic, stamps[k], texts[k])]
        out: list[PendingWindow] = []
        if not self.ring_in_order:  # once a run: the stamp that went back may have left the ring
            ring_stamps = [m[0] for m in self.ring]
            self.ring_in_order = all(map(le, ring_stamps, ring_stamps[1:]))
        i = 0
        for stop in [*self._stops(stamps, anomalous), n]:
            while i < stop:  # messages that are neither anomalous nor going back
                j = self._take_quiet(stamps, texts, i, stop)
                if j == i:  # a window open (or the ring out of order): one message
                    out += self.push(self.trigger_topic, stamps[i], texts[i], score=scores[i])
                    j = i + 1
                i = j
            if stop < n:
                out += self.push(self.trigger_topic, stamps[stop], texts[stop], anomalous=anomalous[stop],
                                 score=scores[stop], lookback_ns=lookbacks[stop])  # fmt: skip
                i = stop + 1
        return out

    def _stops(self, stamps: list[int], anomalous: list[bool]) -> list[int]:
        """The indices `push_run` hands to `push` whatever the window's state: the
        anomalous messages and those whose stamp is before the previous trigger message's."""
        stops = [k for k, a in enumerate(anomalous) if a] if True in anomalous else []
        last = self.last_trigger_ns
        back = list(map(lt, stamps, [stamps[0] if last is None else last, *stamps[:-1]]))
        if True in back:
            stops = sorted({*stops, *(k for k, b in enumerate(back) if b)})
        return stops

    def _take_quiet(self, stamps: list[int], texts: list[str], i: int, stop: int) -> int:
        """Messages i, i+1, ... (up to `stop`, none anomalous, stamps in order) into the
        ring at once while that is all `push` would do with them: the index of the first
        one not taken (i when none can be)."""
        w, ring = self.window, self.ring
        if w is None:
            if not self.ring_in_order:  # one trim equals the trims one by one only in order
                return i
            ring.extend(zip(stamps[i:stop], texts[i:stop]))
            self.last_trigger_ns = stamps[stop - 1]
            self._trim_ring(stamps[stop - 1])
            return stop
        if not w.closing or self.before_ns is None:
            return i
        # Held: the message that takes the ring past the merge reach, or past max_ring,
        # closes the window (`push` takes it); the ones before only join the ring.
        reach = w.last_ns + self.before_ns + self.merge_ns + self.lookback_max_ns
        j = min(bisect.bisect_right(stamps, reach, i, stop), i + self.max_ring - len(ring))
        if j > i:
            ring.extend(zip(stamps[i:j], texts[i:j]))
            self.last_trigger_ns = stamps[j - 1]
        return max(j, i)

    def cut(self) -> list[PendingWindow]:
        """The open window's messages so far, as non-final parts, so that a hard kill
        loses only what came after (the pipeline calls this every few seconds). Each
        topic's newest message stays, so the window's final part is never empty."""
        out: list[PendingWindow] = []
        w = self.window
        if w is not None:
            for topic, part in w.parts.items():
                if len(part) > 1:
                    out.append(self._emit(topic, final=False, n=len(part) - 1))
        return out

    def flush(self) -> list[PendingWindow]:
        """End of input: emit the open window, if any."""
        out: list[PendingWindow] = []
        if self.window is not None:
            self._close(out)
        return out

    # -- internals --------------------------------------------------------------------

    def _push_other(self, topic: str, stamp_ns: int, text: str) -> list[PendingWindow]:
        w = self.window
        out: list[PendingWindow] = []
        if w is not None and not w.closing and w.start_ns <= stamp_ns <= w.last_ns:
            self._add(topic, [(stamp_ns, text)], out)
            return out
        q = self.pending.setdefault(topic, deque())
        if q and stamp_ns < q[-1][0]:  # keep the queue sorted, arrival order among equal stamps
            q.insert(bisect.bisect_right(q, stamp_ns, key=lambda m: m[0]), (stamp_ns, text))
        else:
            q.append((stamp_ns, text))
        if len(q) > self.max_pending:
            q.popleft()
        if w is None:
            self._trim_pending(topic)
        return out

    def _start(self, stamp_ns: int, reach: int, score: float, out: list[PendingWindow]) -> None:
        """Open a window for an anomaly whose evidence starts `reach` ns before it: in
        seconds mode the ring keeps `before` ahead of the evidence, no more."""
        self.back.clear()
        self.back_other.clear()
        if self.before_ns is not None:
            while self.ring and self.ring[0][0] < stamp_ns - reach - self.before_ns:
                m = self.ring.popleft()
                if self.lookback_max_ns:
                    self.back.append(m)
        self._open(stamp_ns, score, out)

    def _reach_back(self, from_ns: int, out: list[PendingWindow]) -> None:
        """An anomaly in the open window whose evidence starts at `from_ns`: the window
        starts `before` ahead of that, taking back what its start had left out."""
        if not self.back or self.back[-1][0] < from_ns - self.before_ns:  # none needed
            return
        lo = from_ns - self.before_ns
        take = []
        while self.back and self.back[-1][0] >= lo:
            take.append(self.back.pop())
        take.reverse()
        w = self.window
        w.start_ns = min(w.start_ns, take[0][0])
        self._add(self.trigger_topic, take, out)
        for topic, kept in self.back_other.items():
            k = bisect.bisect_left(kept, w.start_ns, key=lambda m: m[0])
            if k < len(kept):
                self._add(topic, kept[k:], out)
                del kept[k:]

    def _trim_ring(self, now_ns: int) -> None:
        """Keep the newest message and the `before` messages (or seconds, plus the
        longest lookback) before it."""
        ring = self.ring
        if self.before_ns is None:
            while len(ring) > self.before + 1:
                ring.popleft()
        else:
            # The bound once, not per message dropped: subtracting stamps (ints of 3 digits)
            # cost ~0.2 us a message of smart logging (issue 14).
            oldest = now_ns - self.before_ns - self.lookback_max_ns
            while ring and ring[0][0] < oldest:
                ring.popleft()
            while len(ring) > self.max_ring:
                ring.popleft()
        for topic in self.pending:
            self._trim_pending(topic)

    def _reset(self, out: list[PendingWindow]) -> None:
        """Clock reset: close the open window; nothing before the gap joins a later one."""
        if self.window is not None:
            self._close(out)
        self.ring.clear()
        self.pending.clear()

    def _trim_pending(self, topic: str) -> None:
        """Drop other-topic messages older than any window could start (queues are sorted)."""
        if not self.ring:
            return
        q, oldest = self.pending[topic], self.ring[0][0]
        while q and q[0][0] < oldest:
            q.popleft()

    def _open(self, stamp_ns: int, score: float, out: list[PendingWindow]) -> None:
        start = self.ring[0][0]
        self.window = _Open(window_id=f"w{start}", start_ns=start, last_ns=stamp_ns)
        # The flag first: the context may fill a part at once (9 s at 2 kHz), whose meta
        # must name it (a peak score of -inf is no JSON: the store refused the part).
        self._trigger(stamp_ns, score)
        self._add(self.trigger_topic, list(self.ring), out)
        self.ring.clear()
        oldest = self.back[0][0] if self.back else start
        for topic, q in self.pending.items():
            while q and q[0][0] < start:
                m = q.popleft()
                if m[0] >= oldest:
                    self.back_other.setdefault(topic, []).append(m)
        self._take_pending(stamp_ns, out)

    def _trigger(self, stamp_ns: int, score: float) -> None:
        w = self.window
        w.n_triggers += 1
        if len(w.triggers) < MAX_TRIGGERS_IN_META:
            w.triggers.append(stamp_ns)
        if score > w.peak_score or w.n_triggers == 1:
            w.peak_score, w.peak_ns = score, stamp_ns
        w.left = self.after
        if self.after_ns is not None:
            w.until_ns = stamp_ns + self.after_ns
        if (self.after if self.after_ns is None else self.after_ns) == 0:
            w.closing = True  # nothing to log after the anomaly

    def _take_pending(self, upto_ns: int, out: list[PendingWindow]) -> None:
        for topic, q in self.pending.items():
            batch = []
            while q and q[0][0] <= upto_ns:
                batch.append(q.popleft())
            if batch:
                self._add(topic, batch, out)

    def _add(self, topic: str, msgs: list[tuple[int, str]], out: list[PendingWindow]) -> None:
        # A part goes out only when a message beyond it exists, so the final part is never empty.
        part = self.window.parts.setdefault(topic, [])
        part.extend(msgs)
        while len(part) > self.max_part:
            out.append(self._emit(topic, final=False))
            part = self.window.parts[topic]

    def _meta(self, final: bool) -> dict:
        w = self.window
        return {
            "window_id": w.window_id, "start_ns": w.start_ns,
            "end_ns": w.last_ns if final else None, "final": final,
            "trigger_topic": self.trigger_topic, "triggers": list(w.triggers),
            "n_triggers": w.n_triggers,
            "peak_score": None if math.isnan(w.peak_score) else w.peak_score,
            "peak_ns": w.peak_ns, "model_id": self.model_id,
        }  # fmt: skip

    def _emit(self, topic: str, *, final: bool, n: int | None = None) -> PendingWindow:
        w = self.window
        n = self.max_part if n is None else min(n, self.max_part)
        msgs = sorted(w.parts[topic][:n], key=lambda m: m[0])
        w.parts[topic] = w.parts[topic][n:]
        part = w.part_no.get(topic, 0)
        w.part_no[topic] = part + 1
        return PendingWindow(topic, msgs, self._meta(final) | {"part": part})

    def _close(self, out: list[PendingWindow]) -> None:
        w = self.window
        self._take_pending(w.last_ns, out)
        for topic in list(w.parts):
            if w.parts[topic]:
                out.append(self._emit(topic, final=True))
        for topic, kept in self.latched.items():
            msgs = sorted(((s, t) for t, s in kept.items()), key=lambda m: m[0])
            dropped = self.latched_dropped.get(topic, 0)
            meta = {"part": 0, "latched": True, "latched_dropped": dropped}
            out.append(PendingWindow(topic, msgs, self._meta(True) | meta))
        self.window = None
        self.back.clear()
        self.back_other.clear()
        self.windows_emitted += 1
