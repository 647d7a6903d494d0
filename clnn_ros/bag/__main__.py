"""python -m clnn_ros.bag repair BAG [--out DIR]: the bag tools' command line."""

from __future__ import annotations

import sys
from pathlib import Path

from ..cli import OneLineArgumentParser
from ..files import describe_write_error
from .reader import BagError
from .repair import repair, repaired_path


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.bag", name="bag",
                                   description="Tools for the project's bags.")
    commands = parser.add_subparsers(dest="command", required=True)
    repair_command = commands.add_parser(
        "repair", help="a finalized copy of a bag whose recorder was killed",
        description="Write a finalized, indexed copy (a new bag directory with metadata.yaml) of "
                    "a bag whose recorder was killed: every message of its complete chunks.")
    repair_command.add_argument("bag", type=Path, help="the bag directory, or its .mcap file")
    repair_command.add_argument("--out", type=Path,
                                help="the new bag directory (default: <bag>_repaired)")
    args = parser.parse_args(argv)
    out = args.out or repaired_path(args.bag)
    try:
        out, messages, complete = repair(args.bag, out)
    except BagError as error:
        print(f"bag: error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"bag: error: {describe_write_error(error, out)}: nothing kept there; give --out "
              f"DIR on a disk with room", file=sys.stderr)
        return 1
    print(f"bag: {messages} messages" + (f" ({args.bag} was complete)" if complete else
                                         " (every complete chunk)") + f" in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
