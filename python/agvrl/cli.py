"""The ``agvrl`` command line from the wheel: the Rust CLI, run in this process."""

import sys

from agvrl import _core


def main() -> None:
    sys.exit(_core.cli(["agvrl", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
