"""Example (issue 3): one PNG with the vision front-ends' detections and candidate poses.

Thin wrapper: the code is graphloc.experiments.example_vision_overlay (its options: `--help`)."""

import sys

from graphloc.experiments.example_vision_overlay import main

if __name__ == "__main__":
    sys.exit(main())
