"""Experiment drivers behind scripts/ and `graphloc reproduce`: each module holds the trials,
summaries and plots of one benchmark or seed reproduction, so the script in scripts/ and the
CLI verb are thin callers of the same code (works from an installed package, not only a
source checkout)."""
