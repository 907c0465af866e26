#!/usr/bin/env python3
"""The benchmarks: ``python -m parmps bench`` (parmps/validation/bench.py), from a checkout.

    scripts/bench.py [--particles N ...] [--ranks R ...] [--steps S] [--warmup W]
    scripts/bench.py --time-to-solution [--spacing L0 ...] [--ranks R ...] [--end-time T]
"""

import sys

from parmps.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench"] + sys.argv[1:]))
