"""Retention's carry: windows of named streams that outlive the segment retention drops.

A store's bookkeeping (`cclog record`'s runs on /cclog/runs: what was recorded, from which
source) is tiny and is the store's history; a budget that drops the oldest segment must not
drop it with the data, or the store forgets what it recorded and takes the same source
again. So before the drop's commit, each window of those streams in the segment is put
again, into the active segment (same stream, stamps, texts, meta and codec; a new seq, as
seqs are never reused), and synced; only then is the segment dropped (FORMAT.md,
"Compaction and retention").

A crash between the sync and the commit leaves the window twice (the old segment is still
there): the copy names the seq it was first put under (meta key `carried`), and a window
whose copy is in the store already is not carried again, so repeated crashes add no more.
Readers never see the two: `once` hides a copy whose original (or an earlier copy of it)
is in the same answer, as `Store.query` does unless the carry itself asks for both.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any

from ..errors import CclogError
from .format import AGED_META_KEY, SEGMENT_HEADER_SIZE

if TYPE_CHECKING:
    from .window import Window

CARRIED_META_KEY = "carried"
# Room a carry leaves free beside its own records: the manifest's temporary copy (twice, as
# the reserve counts it) and a margin for the records' headers.
_MARGIN = 64 << 10


def origin(meta: dict[str, Any], seq: int) -> int:
    """The seq a window was first put under: a carried copy names it, else its own."""
    mark = meta.get(CARRIED_META_KEY)
    return mark["seq"] if isinstance(mark, dict) and isinstance(mark.get("seq"), int) else seq


def once(windows: Iterable[Window]) -> Iterator[Window]:
    """`windows` (in (start_ns, seq) order, as a query merges them) less each carried copy
    whose origin is in them already: the copy a crash between a carry's sync and its drop's
    commit left beside the original. A copy has its original's stream, stamps and count, so
    it follows it among the windows of the same start; only windows sharing all four are
    read (their meta) to be told apart, and an unreadable one is kept for its reader to name."""
    start, seen = None, {}  # the windows of this start given so far, by (stream, end, count)
    for w in windows:
        if w.start_ns != start:
            start, seen = w.start_ns, {}
        key = (w.name, w.end_ns, w.count)
        earlier = seen.get(key)
        if earlier is None:
            seen[key] = [w]
            yield w
            continue
        origins = {_origin_of(e) for e in earlier}
        if _origin_of(w) not in origins - {None}:
            earlier.append(w)
            yield w


def _origin_of(w: Window) -> int | None:
    """The seq `w` was first put under, None when its record cannot be read here."""
    try:
        return origin(w.meta, w.seq)
    except CclogError:
        return None


def carry_forward(store: Any, info: dict[str, Any], names: Iterable[str], manifest_bytes: int) -> set[str]:
    """Put the windows of streams `names` of the segment `info` (a manifest entry, about to
    be dropped) again and sync them. Returns the streams every window of which lives on;
    a stream whose windows could not be read or found no room is dropped with the segment
    (the manifest's `dropped` then counts it, as before carrying)."""
    first, end = info["first_seq"], info["end_seq"]
    kept, put = set(), False
    for name in names:
        if name not in info["streams"]:
            continue
        windows = list(store.query(name, skip_damaged=True, copies=True))  # a copy a crash left counts
        here = [w for w in windows if first <= w.seq < end]
        have = {origin(w.meta, w.seq) for w in windows if not first <= w.seq < end}
        todo = [w for w in here if origin(w.meta, w.seq) not in have]
        need = sum(w.stored_bytes + SEGMENT_HEADER_SIZE for w in todo) + 2 * manifest_bytes + _MARGIN
        if todo and store.free_bytes() < need:
            continue  # a full disk: the drop must still free it
        try:
            copies = [(w.messages(), w.meta, w.codec_config, w.seq) for w in todo]
            copies = [(list(m), dict(meta), config, seq) for m, meta, config, seq in copies]
        except CclogError:  # damaged, or a codec this version does not know
            continue  # unreadable: it goes with the segment, counted as dropped
        for messages, meta, config, seq in copies:
            aged = meta.pop(AGED_META_KEY, None)  # put_window refuses the key: it comes with the flag
            mark = meta.get(CARRIED_META_KEY) if origin(meta, seq) != seq else {"seq": seq}
            meta[CARRIED_META_KEY] = mark if aged is None else dict(mark, aged=aged)
            store.put_window(name, messages, meta, codec=config)
            put = True
        kept.add(name)
    if put:
        store.sync()  # durable before the commit that drops the originals
    return kept
