"""Issue 16, "Fuzzing", with Hypothesis: random bytes, and valid inputs (each target's
seeds) mutated by flips, overwrites, insertions and cuts, for every parser, checksums
switched off. A crash is any exception but the project's errors."""

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bench._fuzz_targets import TARGETS, run_one, seeds

# Targets that write files (a segment, a model, a bag) are slower: fewer examples.
_SLOW = {"segment_scan", "model_files", "rosbag1"}


@st.composite
def mutated(draw, target):
    data = bytearray(draw(st.sampled_from(seeds(target))))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "overwrite", "insert", "cut", "int"]))
        pos = draw(st.integers(0, len(data)))
        if op == "flip" and pos < len(data):
            data[pos] ^= 1 << draw(st.integers(0, 7))
        elif op == "overwrite":
            chunk = draw(st.binary(min_size=1, max_size=8))
            data[pos : pos + len(chunk)] = chunk
        elif op == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        elif op == "cut":
            del data[pos : pos + draw(st.integers(1, 16))]
        elif op == "int" and pos + 8 <= len(data):
            value = draw(st.sampled_from([0, 1, 255, 1 << 31, 1 << 32, (1 << 63) - 1, (1 << 64) - 1]))
            data[pos : pos + 8] = value.to_bytes(8, "little")
    return bytes(data)


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_no_input_crashes_a_parser(target):
    @settings(max_examples=60 if target in _SLOW else 300, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))  # fmt: skip
    @given(st.one_of(st.binary(max_size=512), mutated(target)))
    def check(data):
        run_one(target, data)

    check()
