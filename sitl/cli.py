"""``sitl`` command line (the networked SITL arrives with its own issue)."""

import sys


def main(argv=None) -> int:
    print("sitl: the networked MAVLink SITL is not built yet; use `gcs sim` for in-process simulation", file=sys.stderr)
    return 2
