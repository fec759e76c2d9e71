"""``python -m simbench`` runs the command line, as the ``simbench`` script does."""

import sys

from simbench.cli import main

if __name__ == "__main__":
    sys.exit(main())
