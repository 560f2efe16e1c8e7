"""Bugs the tests plant on purpose, to prove that they would catch them (issue 11).

Empty in use: nothing outside the tests adds to it. Each name switches off one safeguard:

- "torn-tail": recovery ignores the synced point, so damage below it is cut as a torn tail;
- "seal-no-fsync": a writer seals (or appends after) what a killed writer left without
  first making it durable;
- "trust-index": a read trusts the index entry, not checking the record header against it.
"""

BUGS: set[str] = set()
