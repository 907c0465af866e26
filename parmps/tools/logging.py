"""Rank-aware logging: rank 0 logs at INFO, every other rank at WARNING."""

import logging
import sys

_FORMAT = "%(asctime)s %(name)s %(levelname)s%(rank)s: %(message)s"


class _RankFilter(logging.Filter):
    def __init__(self, rank, size):
        super().__init__()
        self.tag = f" [rank {rank}/{size}]" if size > 1 else ""

    def filter(self, record):
        record.rank = self.tag
        return True


def configure(comm, verbose=False):
    """Send the package's log records to stderr, INFO on rank 0 and WARNING elsewhere."""
    logger = logging.getLogger("parmps")
    for handler in list(logger.handlers):
        logger.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(_FORMAT, datefmt="%H:%M:%S"))
    handler.addFilter(_RankFilter(comm.rank, comm.size))
    logger.addHandler(handler)
    if comm.rank == 0:
        logger.setLevel(logging.DEBUG if verbose else logging.INFO)
    else:
        logger.setLevel(logging.WARNING)
    logger.propagate = False
    return logger
