"""``python -m agvrl ...`` is the ``agvrl`` command line."""

from agvrl.cli import main

main()
