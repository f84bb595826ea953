"""``python -m refimpl``: the ``refimpl`` command line (refimpl/cli.py, spec/cli.md)."""
import sys

from refimpl.cli import main

if __name__ == "__main__":
    sys.exit(main())
