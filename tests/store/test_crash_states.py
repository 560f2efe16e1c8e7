"""Issue 16, crash states: every workload of up to 3 steps (as CrashMonkey's ACE), then
random longer ones and the background threads, crashed at every operation boundary in
every failure mode, per file and with directory operations reordered, with recovery and
repair crashed again (bench/crash.py says what is checked; `python3 dev.py bench crash`
runs millions).

Each test counts the distinct crash states it checked and asserts its share of the
suite's minimum; the shares add up to at least 100,000 (checked below)."""

import random

import pytest

from bench.crash import STEPS, Tally, ace_workloads, check_workloads, explore, run_background, run_steps

# Distinct states each test must check: 90% of what the last run checked (bench/crash.py
# is seeded; only the background threads' timing varies).
ACE_MIN = {"start+put": 13800, "big": 19000, "sync": 10300, "reopen": 10200, "kill": 10700, "seal": 27000,
           "age": 10500, "drop": 10000, "failsync": 16500}  # fmt: skip
LONG_MIN = 8000  # per test of random longer workloads
LONG_TESTS = 2
BACKGROUND_MIN = 3000


def test_the_minimum_is_100000_crash_states():
    assert set(ACE_MIN) == {"start+put", *STEPS[1:]}
    assert sum(ACE_MIN.values()) + LONG_MIN * LONG_TESTS + BACKGROUND_MIN >= 100_000


def report(tally: Tally, what: str) -> None:
    print(f"{what}: {tally.states} distinct crash states ({tally.images} images, {tally.nested} in a "
          f"crashed recovery or repair), {len(tally.violations)} violations")  # fmt: skip
    assert [v for v in tally.violations if v][:5] == [] and not tally.violations


@pytest.mark.parametrize("first", ACE_MIN)
def test_every_workload_of_up_to_3_steps(first):
    firsts = ("", "put") if first == "start+put" else (first,)
    workloads = [w for w in ace_workloads(3) if (w[0] if w else "") in firsts]
    tally = check_workloads(workloads, seed=STEPS.index(firsts[-1]), group_bytes=(None, 700))
    report(tally, f"workloads of up to 3 steps starting with {first}")
    assert tally.states >= ACE_MIN[first]


@pytest.mark.parametrize("seed", range(LONG_TESTS))
def test_random_longer_workloads(seed):
    rng = random.Random(seed)
    tally = Tally()
    while tally.states < LONG_MIN:
        steps = [rng.choice(STEPS) for _ in range(rng.randint(4, 16))]
        explore(run_steps(steps, rng.choice((None, 700, 2500))), tally, rng, ",".join(steps), nested_every=8)
    report(tally, f"random workloads of 4 to 16 steps (seed {seed})")


def test_the_group_commit_and_upkeep_threads():
    rng = random.Random(7)
    tally = Tally()
    runs = 0
    while tally.states < BACKGROUND_MIN:
        explore(run_background(rng.randrange(2**32)), tally, rng, f"background {runs}", nested_every=8)
        runs += 1
    report(tally, f"group-commit and upkeep threads ({runs} runs)")
