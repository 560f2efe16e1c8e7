"""Issue 16, crash states inside a split put: a window over the record limit is stored as
parts (flag PART), each but the last saying "this window continues in the next record".
Every workload of a step and a split put, of a split put and a step (steps as in
test_crash_states), and of two split puts,
without and with group commits by size, crashed at every operation boundary in every
failure mode: each image holds a prefix of the puts, never a prefix of a split put's parts,
and every put an fsync made durable (bench/crash.py says what is checked). The old writer
ran a group commit between the parts, so a synced point fell inside a window and images
kept a prefix of its parts; no flag told a reader or fsck that the window went on."""

from bench.crash import STEPS, ace_workloads, check_workloads

from test_crash_states import report

# Distinct states the test must check: 90% of what the last run checked (bench/crash.py is
# seeded; nothing here runs in the background).
SPLIT_MIN = 14400


def test_every_workload_of_a_step_and_a_split_put():
    workloads = [("split",), ("split", "split")]
    workloads += [w for step in STEPS for w in ((step, "split"), ("split", step))]
    tally = check_workloads(workloads, seed=11, group_bytes=(None, 700))
    report(tally, f"{len(workloads)} workloads of a step and a split put")
    assert tally.states >= SPLIT_MIN


def test_the_workloads_without_a_split_are_those_of_test_crash_states():
    # The split step is apart from the ACE steps, so their counts (ACE_MIN) stay as they were.
    assert "split" not in STEPS and all("split" not in w for w in ace_workloads(3))
