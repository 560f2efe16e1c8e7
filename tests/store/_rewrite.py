"""Helpers shared by the compaction tests: a random rewrite callback and a store's state."""

import json
import random

from cclogfs.store.format import RecordFlag
from cclogfs.store import Replacement

CHOICES = ("keep", "same", "downsample", "aged")


def random_rewrite(seed, decided=None):
    """A rewrite callback choosing per window, from `seed`: keep it, replace it unchanged,
    downsample it, or age it (fewer messages, new texts, AGED flag, another codec).
    `decided` (a dict) receives seq -> (messages, meta, flags) of every replacement."""
    rng = random.Random(seed)

    def fn(window):
        choice = rng.choice(CHOICES)
        if choice == "keep":
            return None
        messages = list(window.messages())
        meta = window.meta
        flags = window.flags
        codec = None
        if choice == "downsample":
            messages = messages[:: rng.randint(2, 3)]
        elif choice == "aged":
            messages = [(t, json.dumps({"aged_of": len(text), "k": i})) for i, (t, text) in enumerate(messages[::2])]
            meta = dict(meta, aged={"float_abs": 0.01, "downsampled": 2})
            flags = int(RecordFlag.AGED)
            codec = rng.choice(["zstd", "none", "columnar"])
        if decided is not None:
            decided[window.seq] = (messages, meta, flags)
        return Replacement(messages, meta, codec=codec, flags=flags)

    return fn


def state(store):
    """Everything a store's records hold, in seq order, for exact comparisons."""
    return [
        (w.seq, w.name, w.start_ns, w.end_ns, w.meta, w.flags, list(w.messages()))
        for w in sorted(store.query(), key=lambda w: w.seq)
    ]


def leftovers(path, manifest):
    """Segment/index/temp files in `path` the manifest does not account for."""
    from cclogfs.store.format import parse_seq_name

    named = {(s["first_seq"], s.get("gen", 0)) for s in manifest["segments"]}
    end = manifest["segments"][-1]["end_seq"] if manifest["segments"] else manifest.get("first_seq", 0)
    out = []
    for name in sorted(p.name for p in path.iterdir()):
        parsed = parse_seq_name(name)
        if name.endswith(".tmp"):
            out.append(name)
        elif parsed and (parsed[0], parsed[2]) not in named and (parsed[2] > 0 or parsed[0] < end):
            out.append(name)
    return out
