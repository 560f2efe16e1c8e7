"""Bugs the tests plant on purpose, to prove that they would catch them (issues 11, 16).

Empty in use: nothing outside the tests adds to it. Each name switches off one safeguard
(tests/store/test_planted.py turns each on and shows a check of the suite failing):

- "torn-tail": recovery ignores the synced point, so damage below it is cut as a torn tail;
- "seal-no-fsync": a writer seals (or appends after) what a killed writer left without
  first making it durable, and `Store.seal()` seals the active segment without its fsync;
- "trust-index": a read trusts the index entry, not checking the record header against it;
- "skip-bad-record": a scan that meets a bad record skips to the next intact one and reads
  on, saying nothing (a hole instead of the end of the log);
- "no-dir-fsync": a new segment's directory entry is not fsynced;
- "rename-before-sync": a file replaced atomically (MANIFEST, an index) is renamed into
  place before its data is fsynced;
- "early-delete": compaction and retention delete their input files before the manifest
  that stops naming them is durable;
- "trust-length": a record's lengths are used before they are checked against the limits
  and the file's size;
- "trust-zstd-size": a zstd payload is decompressed into the size its frame declares;
- "follow-symlink": store files are opened without O_NOFOLLOW.
"""

BUGS: set[str] = set()
