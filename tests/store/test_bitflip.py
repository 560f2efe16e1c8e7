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
