"""Issue 16, "Fuzzing": the committed corpus of every parser (tests/fuzz/corpus/TARGET/,
grown by `python -m bench fuzz --update-corpus`, each crash found added once fixed) and
each target's built seeds, replayed with checksums switched off: every input must end
in a return or one of the project's errors, never another exception."""

from pathlib import Path

import pytest

from bench._fuzz_targets import TARGETS, run_one, seeds

CORPUS = Path(__file__).parent / "corpus"


def _inputs(target):
    files = sorted((CORPUS / target).glob("*")) if (CORPUS / target).is_dir() else []
    return [f.read_bytes() for f in files] + seeds(target)


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_the_corpus_replays_without_a_crash(target):
    inputs = _inputs(target)
    assert inputs
    for data in inputs:
        run_one(target, data)


def test_every_target_has_a_committed_corpus():
    missing = [t for t in TARGETS if not any((CORPUS / t).glob("*"))]
    assert not missing, f"no corpus for {missing}: run `python -m bench fuzz --update-corpus`"
