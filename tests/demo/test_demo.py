"""The demo end to end with a short configuration; its printed figures match the store."""

import json
import lzma

import cclogfs
from cclogfs.classifier import event_table
from cclogfs.cli import main
from cclogfs.demo import DemoConfig, run_demo
from cclogfs.ingest import open_source


def test_demo_figures_match_the_store(tmp_path, capsys):
    cfg = DemoConfig(out=tmp_path / "demo", train_minutes=1.0, test_minutes=1.0, rate_hz=30.0, anomalies=2)
    res = run_demo(cfg)
    out = capsys.readouterr().out
    assert "True Positives" in out and "events recalled" in out and "cclog info" in out

    with open_source(res.paths["bag"]) as source:
        messages = [(m.topic, m.stamp_ns, m.text) for m in source]
    json_all = "\n".join(t for _, _, t in messages).encode()
    sizes = dict(res.storage)
    assert sizes["raw JSON (every message)"] == len(json_all)
    assert sizes["LZMA-6 of all the JSON (the paper's best)"] == len(lzma.compress(json_all, preset=6))

    with cclogfs.open_store(res.paths["store_all"], readonly=True) as store:  # every message is there
        stored = sorted((w.name, t, m) for w in store.query() for t, m in w.messages())
        assert stored == sorted(messages)
        assert sizes["cclogfs, every message kept"] == sum(
            p.stat().st_size for p in res.paths["store_all"].iterdir() if p.name != "LOCK")

    with cclogfs.open_store(res.paths["store"], readonly=True) as store:
        odom = list(store.query("/odom"))
        joined = {}  # parts of one long window share its window_id
        for w in odom:
            a, b = joined.get(w.meta["window_id"], (w.start_ns, w.end_ns))
            joined[w.meta["window_id"]] = (min(a, w.start_ns), max(b, w.end_ns))
        stamps = sorted(s for t, s, _ in messages if t == "/odom")
        labels = json.loads(res.paths["labels"].read_text())
        assert res.events == event_table(stamps, sorted(joined.values()), labels)
        kept = sum(w.count for w in odom)
        assert abs(res.events["kept_fraction"] - kept / len(stamps)) < 1e-9
        assert sizes["cclogfs, smart logging"] == sum(
            p.stat().st_size for p in res.paths["store"].iterdir() if p.name != "LOCK")
    aged = sizes["cclogfs, smart logging, aged to 1e-3 (cclog compact)"]
    assert aged == sum(p.stat().st_size for p in res.paths["store_aged"].iterdir() if p.name != "LOCK")
    assert aged < sizes["cclogfs, smart logging"]
    with cclogfs.open_store(res.paths["store_aged"], readonly=True) as store:
        assert all(w.aged is not None for w in store.query("/odom"))
    assert res.paths["trajectory"].stat().st_size > 10_000 and res.paths["scores"].stat().st_size > 10_000

    # A second run over the same directory works, and the store passes fsck.
    run_demo(cfg)
    assert main(["fsck", str(res.paths["store"]), "--deep"]) == 0
