"""Issue 11, what must hold, in small: bit flips and zeroed sectors in every file kind of a
clean and a crash-cut store (bench/bitflip.py runs 20,000 of the same trials)."""

import random

import pytest

from bench.bitflip import KINDS, build, trial


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    root = tmp_path_factory.mktemp("bitflip")
    return [build(root, crashed=False), build(root, crashed=True)], root


@pytest.mark.parametrize("kind", KINDS)
def test_every_flip_is_flagged_and_no_intact_record_is_lost(bases, kind):
    (clean, crashed), root = bases
    rng = random.Random(KINDS.index(kind))
    done = 0
    for i in range(60):
        r = trial((clean, crashed)[i % 2], rng, root / f"w-{kind}", kind, "sector" if i % 6 == 5 else "bit")
        if r is None:
            continue
        done += 1
        assert r.flagged, (i, r)
        assert r.changed == 0, (i, r)
        assert r.lost == [], (i, r)
        assert not r.refused or kind == "MANIFEST", (i, r)  # a damaged MANIFEST waits for --repair
    assert done >= 50


# -- issue 16: every bit of a small store, and 100,000 random damages of a larger one, at
# the parsers (bench/bitflip_fast.py: about 2,000 damages a second on this machine; the
# 100,000 are split in four so that the two test workers share them).

from bench import bitflip_fast as fast  # noqa: E402


@pytest.fixture(scope="module")
def oracles(tmp_path_factory):
    root = tmp_path_factory.mktemp("bitflip_fast")
    return fast.build(root, 12, 4), fast.build(root, 400, 64)


def test_every_bit_of_a_small_store_changes_no_message(oracles):
    totals = fast.every_bit(oracles[0])
    assert totals["flips"] > 40_000 and totals["changed"] == 0, totals


@pytest.mark.parametrize("seed", range(4))
def test_random_flips_bursts_and_sectors_change_no_message(oracles, seed):
    totals = fast.random_damage(oracles[1], 25_000, random.Random(seed))
    assert totals["changed"] == 0, totals
    assert all(totals[m] >= 8_000 for m in fast.MODES), totals
    assert all(totals[k] >= 1_000 for k in ("MANIFEST", "index", "segment", "LOCK", "side file")), totals


def test_the_oracle_sees_changes_when_checksums_are_off(oracles):
    # The measure above can fail: with the checksums off, flips do change messages.
    from bench._fuzz_targets import checksums_off

    with checksums_off():
        totals = fast.random_damage(oracles[1], 600, random.Random(9))
    assert totals["changed"] > 0, totals
