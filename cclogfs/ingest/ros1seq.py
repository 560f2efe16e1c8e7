"""Loss on live ROS 1 topics, told from `header.seq`: what `cclog record ros1://` reports.

A ROS 1 publisher numbers the messages of a type that starts with `Header header`: rospy
sets `header.seq` to 1, 2, 3... per publisher, and `rosbag play` republishes the numbers
the bag holds. So, per topic and per publisher (the connection header's `callerid`), a
message whose seq is more than one past the previous one means that many were dropped on
the way (a publisher's or subscriber's bounded queue). The seq is the first 4 bytes of the
serialized message (uint32, little-endian), so no second decoding is needed.

What cannot be told, and is said instead of counted as 0:
- types without a header (tf2_msgs/TFMessage: its transforms carry headers, but a
  broadcaster does not number them, and one message holds transforms of many frames);
- a publisher whose seq does not go up by whole steps (all 0, as a ROS 2 bridge or a bag
  converted from ROS 2 sends; or going back, as when two recorded publishers are played
  as one, or a node restarts under the same name): its gaps are not counted;
- messages lost before the first or after the last one received (no seq to compare).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

_SEQ = struct.Struct("<I")


def starts_with_header(msgdef: str) -> bool:
    """True when a ROS 1 message definition's first field is `Header header`."""
    for line in msgdef.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            kind, _, name = line.partition(" ")
            return kind in ("Header", "std_msgs/Header") and name.strip() == "header"
    return False


@dataclass
class PublisherSeq:
    """The seq numbers of one publisher on one topic."""

    received: int = 0
    first: int = 0
    last: int = 0
    lost: int = 0
    unnumbered: int = 0  # times seq did not go up (repeat or back): gaps cannot be told

    def add(self, seq: int, latched: bool) -> None:
        if self.received and seq > self.last:
            self.lost += seq - self.last - 1
        elif self.received and not (latched and seq == self.last):  # a latched message comes again on reconnecting
            self.unnumbered += 1
        if not self.received:
            self.first = seq
        self.received += 1
        self.last = seq

    @property
    def checked(self) -> bool:
        return self.unnumbered == 0


@dataclass
class TopicSeq:
    """Per topic: its publishers' seq numbers, or why they cannot be checked."""

    received: int = 0
    unchecked: str | None = None  # why loss cannot be told on this topic
    publishers: dict[str, PublisherSeq] = field(default_factory=dict)

    @property
    def lost(self) -> int:
        return sum(p.lost for p in self.publishers.values() if p.checked)

    def why_unchecked(self) -> str | None:
        if self.unchecked:
            return self.unchecked
        bad = [c for c, p in self.publishers.items() if not p.checked]
        if bad:
            return f"seq does not go up one by one from {', '.join(sorted(bad))}"
        return None


class SeqCheck:
    """Counts the messages lost on each topic, from the seq of the ones received."""

    def __init__(self) -> None:
        self.topics: dict[str, TopicSeq] = {}
        self._has_header: dict[str, bool] = {}  # md5sum -> the type starts with a Header
        self.not_stored = 0  # received, but after the recording stopped taking messages

    def add(self, topic: str, raw: bytes, header: dict[str, str]) -> None:
        t = self.topics.get(topic)
        if t is None:
            t = self.topics[topic] = TopicSeq()
        t.received += 1
        md5 = header.get("md5sum", "")
        has = self._has_header.get(md5)
        if has is None:
            has = self._has_header[md5] = starts_with_header(header.get("message_definition", ""))
        if not has or len(raw) < 4:
            t.unchecked = f"{header.get('type', '?')} has no header.seq"
            return
        pub = t.publishers.get(header.get("callerid", ""))
        if pub is None:
            pub = t.publishers[header.get("callerid", "")] = PublisherSeq()
        pub.add(_SEQ.unpack_from(raw)[0], header.get("latching") == "1")

    @property
    def lost(self) -> int:
        """Messages known lost: seq gaps on the checked topics, and those not stored."""
        return sum(t.lost for t in self.topics.values()) + self.not_stored

    def lines(self) -> list[str]:
        """The report, one line per topic, then what could not be checked."""
        out = []
        for topic, t in sorted(self.topics.items()):
            why = t.why_unchecked()
            lost = f"{t.lost:,} lost" if why is None else f"not checked ({why})"
            if why is not None and t.lost:
                lost += f"; {t.lost:,} lost from the publishers that number theirs"
            out.append(f"  {topic}: {t.received:,} received, {lost}")
        if self.not_stored:
            out.append(f"  {self.not_stored:,} received after the recording stopped taking messages, not stored")
        return out
