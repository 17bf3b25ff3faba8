"""cog_id_ros.ros.cdr: the struct-built Float64MultiArray is rclpy's serialisation, byte for byte.

The one exception are the four padding bytes before the first double, which Fast CDR
leaves unwritten (they hold whatever its buffer held) and cdr.py writes as zeros.
"""
import math
import struct

import pytest

pytest.importorskip('rclpy')
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from cog_id_ros.ros import cdr  # noqa: E402

PADDING = slice(16, 20)
ODD = [0.0, -0.0, 1.0, -1.5, math.inf, -math.inf, math.pi, -math.e, 5e-324, -5e-324,
       2.2250738585072014e-308, 1.7976931348623157e308, -1.7976931348623157e308, 1e-300,
       123456789.123456789, 0.1, -1e16, 2.0 ** 53 + 2, 7.0, -3.25]


def bits(values):
    """The IEEE bits of each value: tells -0.0 from 0.0, compares infinities exactly."""
    return [struct.pack('<d', float(v)) for v in values]


def without_padding(raw):
    return raw[:PADDING.start] + raw[PADDING.stop:]


@pytest.mark.parametrize('n', range(21))
def test_same_bytes_as_rclpy(n):
    for data in (ODD[:n], ODD[::-1][:n], [float(k) for k in range(n)]):
        ours = cdr.float64_multiarray(data)
        theirs = serialize_message(Float64MultiArray(data=data))
        assert len(ours) == len(theirs) == cdr.PREFIX_SIZE + 8 * n
        assert without_padding(ours) == without_padding(theirs)
        assert ours[PADDING] == bytes(4)
        assert ours[:4] == cdr.CDR_LE


@pytest.mark.parametrize('n', range(21))
def test_rclpy_reads_the_same_numbers_back(n):
    data = ODD[:n]
    msg = deserialize_message(cdr.float64_multiarray(data), Float64MultiArray)
    assert bits(msg.data) == bits(data)
    assert list(msg.layout.dim) == [] and msg.layout.data_offset == 0


def test_packer_for_a_fixed_length():
    pack = cdr.float64_multiarray_packer(6)
    data = ODD[:6]
    assert pack(*data) == cdr.float64_multiarray(data)
    with pytest.raises(struct.error):
        pack(*ODD[:5])


def test_accepts_tuples_numpy_and_ints():
    np = pytest.importorskip('numpy')
    data = [1.0, -0.0, math.inf]
    expected = cdr.float64_multiarray(data)
    assert cdr.float64_multiarray(tuple(data)) == expected
    assert cdr.float64_multiarray(np.array(data)) == expected
    assert cdr.float64_multiarray([1, -0.0, math.inf]) == expected


@pytest.mark.parametrize('stamp_ns', [0, 1, 999_999_999, 1_000_000_000, 1_500_000_000,
                                      (2 ** 31 - 1) * 1_000_000_000 + 999_999_999])
def test_clock_same_bytes_as_rclpy(stamp_ns):
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(stamp_ns, 1_000_000_000)
    assert cdr.clock(stamp_ns) == serialize_message(msg)
    back = deserialize_message(cdr.clock(stamp_ns), Clock)
    assert back.clock.sec * 1_000_000_000 + back.clock.nanosec == stamp_ns
