"""`graphloc import BAG --topics topics.yaml --out RUN`: a ROS 1 / ROS 2 / MCAP bag -> a graphloc
log directory (docs/rosbag.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from graphloc.config import add_config_arguments, config_from_args
from graphloc.config_schema import config_dataclass, setting
from graphloc.exitcodes import OK
from graphloc.structured import dumps_json

HELP = "ROS 1 / ROS 2 / MCAP bag + topics file -> graphloc log directory (smooth / online input)"


@config_dataclass
class ImportOptions:
    """The options of `graphloc import` (command line and `--config FILE.toml`)."""

    topics: str | None = setting(
        None,
        description=(
            "topics file (YAML, docs/rosbag.md); unset: topics.yaml inside or beside the bag"
        ),
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", type=Path, help=".bag file, .mcap file or ROS 2 bag directory")
    parser.add_argument("--out", required=True, type=Path, help="log directory to write")
    parser.add_argument("--config", type=Path, help="TOML file with any of the options below")
    add_config_arguments(parser, ImportOptions)


def run(args: argparse.Namespace) -> int:
    from graphloc.datasets.rosbag import find_topics_file, import_bag

    opts = config_from_args(ImportOptions, args)
    topics = Path(opts.topics) if opts.topics is not None else find_topics_file(args.bag)
    if (args.out / "manifest.json").exists():
        raise ValueError(f"{args.out}: holds a log already (manifest.json); choose another --out")
    result = import_bag(args.bag, topics, args.out)
    print(
        dumps_json(
            {
                "log": str(result.root),
                "rows": result.rows,
                "skipped": result.skips.as_dict(),
                "notes": result.notes.as_dict(),
                "unmapped_topics": result.unmapped,
            },
            indent=1,
        )
    )
    return OK
