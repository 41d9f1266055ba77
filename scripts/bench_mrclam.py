"""MRCLAM benchmark: dead reckoning vs batch (LM) vs online (iSAM2) smoothing on a whole MRCLAM
dataset, with and without landmarks, plus cooperative SLAM (graphloc.experiments.bench_mrclam;
`--help` lists the options)."""

import sys

from graphloc.experiments.bench_mrclam import main

if __name__ == "__main__":
    sys.exit(main())
