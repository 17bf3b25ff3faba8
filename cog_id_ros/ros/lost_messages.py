"""Messages a publisher sent that never reached a subscription, counted from the gaps in its
publication sequence numbers (rclpy's message info, ``publication_sequence_number``).

A subscription's queue overflows when the node cannot keep up (a flood, a stalled
process): DDS drops the oldest messages unseen. Each publisher numbers what it sends, so a
gap between two numbers received is what was lost. rclpy does not say which publisher a
message came from, so the numbers of several publishers cannot be told apart: gaps are
counted only while a single publisher feeds the topic (the caller's ``publishers()``).
One counter per subscription; the nodes count setpoints, measured states and efforts so.
"""
from typing import Callable


class LostMessages:
    """Counts gaps in the sequence numbers of one subscription's single publisher."""

    def __init__(self, publishers: Callable[[], int]) -> None:
        self.publishers = publishers
        self.total = 0
        self._last: int | None = None

    def count(self, info: dict | None) -> int:
        """The messages lost just before the one with message info ``info`` (0 when none,
        or when that cannot be told: no number, several publishers, a new publisher whose
        numbers start over); added to ``total``."""
        sequence = None if info is None else info.get('publication_sequence_number')
        last, self._last = self._last, sequence
        if sequence is None or last is None or sequence <= last + 1:
            return 0
        if self.publishers() != 1:
            return 0
        lost = sequence - last - 1
        self.total += lost
        return lost
