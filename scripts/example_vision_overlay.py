"""Example (issue 3): one PNG with the vision front-ends' detections and candidate poses.

Thin wrapper: the code is benchmarks.example_vision_overlay (its options: `--help`)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.example_vision_overlay import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
