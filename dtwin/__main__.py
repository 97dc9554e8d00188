"""``python -m dtwin``: the command line of :mod:`dtwin.cli`."""

import sys

from dtwin.cli import main

if __name__ == "__main__":
    sys.exit(main())
