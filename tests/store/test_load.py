"""Readers under load (issue 16): library readers, a refreshing reader, `fsck --deep` and
`cclog cat` in a loop while a writer process records, seals, ages and drops segments.
Every error a reader reports here is false (the store holds no damage): there must be none.
`python -m bench load --seconds 600` is the longer soak of the same code."""

from bench.load import run


def test_readers_in_a_loop_while_a_writer_records_compacts_and_ages_report_no_false_error(tmp_path):
    tally = run(12, cat_every=6, fsck_every=3, workdir=str(tmp_path))
    print(f"puts {tally.puts}, windows read {tally.reads}, opens {tally.opens}, fsck {tally.fscks}, "
          f"cat {tally.cats}, errors {len(tally.errors)}")  # fmt: skip
    assert tally.errors == []
    assert tally.reads > 100 and tally.opens > 4 and tally.fscks >= 1 and tally.cats >= 1
