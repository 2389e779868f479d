"""Progress of long loops in the job logs: done/total, rate and ETA."""

import logging
import time

log = logging.getLogger("luckyao.progress")


class Progress:
    """Logs ``what done/total (percent), rate/s, ETA`` at most every ``every_s`` seconds
    (and always at the end). The rate and the ETA count from the first update: the work
    before it (the first chunk, which compiles the numba kernels) does not stretch them."""

    def __init__(self, what: str, total: int, every_s: float = 10.0):
        self.what, self.total, self.every_s = what, total, every_s
        self.start = self.last = time.monotonic()
        self.baseline = None  # (time, done) of the first update

    def update(self, done: int) -> None:
        now = time.monotonic()
        if self.baseline is None and done < self.total:
            self.baseline = (now, done)
            log.info(
                "%s %d/%d (%.1f%%), first chunk in %.1f s (ETA from the next)",
                self.what,
                done,
                self.total,
                100 * done / max(self.total, 1),
                now - self.start,
            )
            self.last = now
            return
        if now - self.last < self.every_s and done < self.total:
            return
        self.last = now
        since, done_then = self.baseline or (self.start, 0)
        rate = (done - done_then) / max(now - since, 1e-9)
        eta = (self.total - done) / rate if rate > 0 else float("inf")
        log.info(
            "%s %d/%d (%.1f%%), %.1f/s, ETA %.0f s",
            self.what,
            done,
            self.total,
            100 * done / max(self.total, 1),
            rate,
            eta,
        )
