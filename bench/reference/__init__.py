"""Frozen reference implementations the performance figures compare against in the same run
(the hand-written CDR codec, the numpy NDT before issue 16, the kNN merge before issue 33's
rewrite). Not used by the pipeline."""
