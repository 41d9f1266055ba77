"""Publish a bag's messages as ROS 2 topics over Cyclone DDS (no ROS installation): the topics
its topics file maps (docs/rosbag.md), at their recorded rate or faster. A log directory
(manifest.json) instead goes out line by line as graphloc_msgs/msg/LogRow on
/graphloc/log/ROBOT/TABLE (what `graphloc live --ros2 --manifest` reads: docs/live.md).

    python scripts/publish_bag_ros2.py tests/data/real_bag/husky_outdoor_120s.bag \
        --topics topics.yaml --rate 4
    python scripts/publish_bag_ros2.py BAG --topics topics.yaml --fast
    python scripts/publish_bag_ros2.py LOG_DIR --rate 1

The domain is ROS_DOMAIN_ID; CYCLONEDDS_URI picks the interfaces (docs/live.md). The script
waits (--wait s) until a subscriber matched each topic, then publishes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/

from benchmarks.live_publish import Publisher, bag_messages, log_messages  # noqa: E402
from graphloc.datasets.rosbag_topics import read_topics  # noqa: E402
from graphloc.manifest import MANIFEST  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("source", type=Path, help="a ROS bag, or a log directory")
    p.add_argument("--topics", type=Path, help="graphloc import's topics file (a bag)")
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=float, default=1.0, help="times the recorded pace")
    pace.add_argument("--fast", action="store_true", help="as fast as the messages go")
    p.add_argument("--wait", type=float, default=30.0, help="s to wait for subscribers")
    args = p.parse_args(argv)
    try:
        if (args.source / MANIFEST).is_file():
            if args.topics is not None:
                raise ValueError(f"--topics: {args.source} is a log directory, not a bag")
            messages = log_messages(args.source)
        else:
            if args.topics is None:
                raise ValueError(f"{args.source}: a bag needs --topics FILE")
            messages = bag_messages(args.source, set(read_topics(args.topics).topics))
    except (ValueError, FileNotFoundError) as exc:
        print(f"publish_bag_ros2: error: {exc}", file=sys.stderr)
        return 2
    if not messages:
        print(f"publish_bag_ros2: error: {args.source}: no message to publish", file=sys.stderr)
        return 2
    pub = Publisher(messages)
    alone = pub.wait_for_subscribers(args.wait)
    if alone:
        print(f"publish_bag_ros2: no subscriber after {args.wait:g} s on {sorted(alone)}")
    n = pub.run(None if args.fast else args.rate)
    pub.drain()
    print(f"published {n} messages on {len(pub.writers)} topics", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
