"""``python -m spherevm``: the same as the ``spherevm`` command."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
