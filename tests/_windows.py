"""Helpers for export tests: real stores filled from the shared data, and a tiny fake."""

from __future__ import annotations

from dataclasses import dataclass, field

import cclogfs
from cclogfs.ingest import open_source


def read_topics(path, topics):
    """{topic: [(stamp_ns, text)]} of a source file."""
    out: dict[str, list[tuple[int, str]]] = {t: [] for t in topics}
    with open_source(path, topics) as src:
        for m in src:
            out[m.topic].append((m.stamp_ns, m.text))
    return out


def fill_store(store_path, messages_by_topic, window=100, msgtypes=None):
    """A store holding every message, in windows of `window` messages per topic."""
    with cclogfs.open_store(store_path, create=True) as store:
        for topic, msgs in messages_by_topic.items():
            for i in range(0, len(msgs), window):
                meta = {"score": i / 7}
                if msgtypes:
                    meta["msgtype"] = msgtypes[topic]
                store.put_window(topic, msgs[i : i + window], meta=meta)
    return store_path


@dataclass
class FakeWindow:
    name: str
    seq: int
    msgs: list[tuple[int, str]]
    meta: dict = field(default_factory=dict)

    @property
    def start_ns(self):
        return self.msgs[0][0]

    @property
    def end_ns(self):
        return self.msgs[-1][0]

    def messages(self):
        return iter(self.msgs)
