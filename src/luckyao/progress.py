"""Progress of long loops in the job logs: done/total, rate and ETA."""

import logging
import time

log = logging.getLogger("luckyao.progress")


class Progress:
    """Logs ``what done/total (percent), rate/s, ETA`` at most every ``every_s`` seconds
    (and always at the end)."""

    def __init__(self, what: str, total: int, every_s: float = 10.0):
        self.what, self.total, self.every_s = what, total, every_s
        self.start = self.last = time.monotonic()

    def update(self, done: int) -> None:
        now = time.monotonic()
        if now - self.last < self.every_s and done < self.total:
            return
        self.last = now
        rate = done / max(now - self.start, 1e-9)
        eta = (self.total - done) / rate if rate > 0 else float("inf")
        log.info("%s %d/%d (%.1f%%), %.1f/s, ETA %.0f s", self.what, done, self.total,
                 100 * done / max(self.total, 1), rate, eta)
