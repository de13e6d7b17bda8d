"""`fusion` / `python -m fusion`: the command line lives in fusion.cli."""

from __future__ import annotations

import sys

from fusion.cli import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
