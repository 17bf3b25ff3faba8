"""The serialized (CDR) form of std_msgs/Float64MultiArray (and rosgraph_msgs/Clock),
built with ``struct``.

rclpy's ``Publisher.publish`` also takes a message already serialized (``bytes``) and
publishes it as it is. For the node's ``effort_command`` that skips rclpy's conversion of
the Python message to its C struct and the rmw's serialisation of that struct: the bytes
are built here in one ``struct`` call (under a microsecond for a handful of efforts).
Subscribers receive an ordinary Float64MultiArray; nothing tells them how it was built.

The encoding (plain CDR, little-endian, as rmw_fastrtps serialises it;
test/ros/test_cdr.py checks it byte for byte against ``rclpy.serialization``):

====== ===================================================================================
bytes  field
====== ===================================================================================
0-3    encapsulation: ``00 01`` (CDR, little-endian), options ``00 00``
4-7    ``layout.dim``: sequence<MultiArrayDimension>, uint32 count, here 0
8-11   ``layout.data_offset``: uint32, here 0
12-15  ``data``: sequence<float64>, uint32 count n
16-19  padding: the doubles are 8-aligned, counted from byte 4 (after the encapsulation)
20-    the n doubles, IEEE 754 little-endian
====== ===================================================================================

So the message is ``20 + 8 n`` bytes (also for n = 0: rmw_fastrtps's serialized size
counts the padding even without a double after it). Fast CDR leaves the padding bytes
unwritten (whatever its buffer held); here they are zeros. Any layout with dimensions is
out of scope: the node's commands never have one.
"""
import functools
import struct
from typing import Callable, Sequence

#: encapsulation header of plain CDR, little-endian
CDR_LE = b'\x00\x01\x00\x00'

#: bytes before the first double: encapsulation, no dims, data_offset 0, count, padding
PREFIX_SIZE = 20


def float64_multiarray(data: Sequence[float]) -> bytes:
    """The serialized Float64MultiArray with ``data`` (floats; no layout dimensions)."""
    return float64_multiarray_packer(len(data))(*data)


def float64_multiarray_packer(n: int) -> Callable[..., bytes]:
    """``pack(*values) -> bytes``: the serialized Float64MultiArray of exactly ``n`` floats
    (one C call, for a hot path that always sends ``n``; ``struct.error`` for another n)."""
    return functools.partial(struct.Struct(f'<4sIII4x{n}d').pack, CDR_LE, 0, 0, n)


#: rosgraph_msgs/Clock: the encapsulation, then ``clock`` (int32 sec, uint32 nanosec)
_CLOCK = struct.Struct('<4siI')


def clock(stamp_ns: int) -> bytes:
    """The serialized rosgraph_msgs/Clock of ``stamp_ns`` (>= 0): 12 bytes, one struct
    call (cog_sim_node publishes one after every step)."""
    return _CLOCK.pack(CDR_LE, *divmod(stamp_ns, 1_000_000_000))
