"""The progress bar of the offline tools (``cog_id_torques``, ``cog_id_simulate``): one line
on stderr, redrawn in place, for long inputs on a terminal."""

import math
import os
import time as _time

PROGRESS_MIN_SAMPLES = 10_000   # the bar appears for inputs over this many samples


class ProgressBar:
    """A one-line progress bar redrawn in place with carriage returns."""

    def __init__(self, total, stream, enabled, label='solving', unit='samples'):
        self.total = total
        self.unit = unit
        self.stream = stream
        self.enabled = enabled
        self.label = label
        self.start = _time.perf_counter()
        self.drawn = False
        self.last_length = 0

    @staticmethod
    def wanted(total, stream, disabled=False):
        if disabled or total <= PROGRESS_MIN_SAMPLES:
            return False
        try:
            return bool(stream.isatty())
        except (AttributeError, ValueError, OSError):
            return False

    def _width(self):
        try:
            columns = os.get_terminal_size(self.stream.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 0
        return columns if columns > 0 else 80

    def update(self, done):
        if not self.enabled:
            return
        elapsed = _time.perf_counter() - self.start
        frac = done / self.total if self.total else 1.0
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else float('nan')
        tail = (f' {frac:4.0%} {done:,}/{self.total:,} {self.unit}  {rate:,.0f}/s'
                + (f'  {eta:.0f} s left' if done < self.total and math.isfinite(eta)
                   else f'  {elapsed:.1f} s'))
        room = max(10, min(40, self._width() - len(self.label) - len(tail) - 5))
        fill = int(round(frac * room))
        line = f'{self.label} [{"#" * fill}{"." * (room - fill)}]{tail}'
        self.stream.write('\r' + line.ljust(self.last_length))
        self.last_length = len(line)
        self.stream.flush()
        self.drawn = True

    def close(self):
        if self.enabled and self.drawn:
            self.stream.write('\n')
            self.stream.flush()
