"""``python -m carapost.sample OUT_DIR [--markers N] [--frames N] [--seed N]``."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
