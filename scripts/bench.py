#!/usr/bin/env python3
"""The benchmarks: ``python -m parmps bench`` (parmps/validation/bench.py), from a checkout.

    scripts/bench.py [--particles N ...] [--ranks R ...] [--steps S] [--warmup W]
    scripts/bench.py --time-to-solution [--spacing L0 ...] [--ranks R ...] [--end-time T]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from parmps.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["bench"] + sys.argv[1:]))
