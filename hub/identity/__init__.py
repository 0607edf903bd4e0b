"""Who is which camera track: the streaming engine, its settings, records, cues, rules and assignment; the paper's
permutation search in `paper/`."""
