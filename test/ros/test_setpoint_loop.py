"""SetpointLoop: a subscription served by a thread of its own, over real DDS in one process.

Order and completeness of what it serves, its lock, errors in the callback, a clean stop,
and that no executor ever runs the subscription (even one spinning the same node).
"""
import threading
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from conftest import wait_until  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from cog_id_ros.ros.node import control_qos  # noqa: E402
from cog_id_ros.ros.setpoint_loop import SetpointLoop  # noqa: E402


@pytest.fixture
def pair(rclpy_context, request):
    """(publishing node, serving node, executor spinning the serving node in a thread)."""
    name = request.node.name.replace('[', '_').replace(']', '').replace('-', '_')
    sender = rclpy.create_node(f'sender_{name}', namespace='/loop_test', context=rclpy_context)
    server = rclpy.create_node(f'server_{name}', namespace='/loop_test', context=rclpy_context)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(server)
    thread = threading.Thread(target=executor.spin, daemon=True)
    yield sender, server, executor, thread
    executor.shutdown()
    sender.destroy_node()
    server.destroy_node()


def test_every_message_is_served_in_order_with_the_lock_held(pair):
    sender, server, executor, thread = pair
    lock = threading.Lock()
    served, lock_held = [], []

    def callback(msg):
        lock_held.append(lock.locked())
        served.append(int(msg.data[0]))

    loop = SetpointLoop(server, Float64MultiArray, 'in_order', callback, control_qos(), lock=lock)
    thread.start()                     # an executor spins the same node meanwhile
    loop.start()
    pub = sender.create_publisher(Float64MultiArray, 'in_order', control_qos())
    assert wait_until(lambda: pub.get_subscription_count() > 0)
    for k in range(300):               # faster than one at a time: some queue up
        pub.publish(Float64MultiArray(data=[float(k)]))
        if k % 50 == 0:
            time.sleep(0.01)
    try:
        assert wait_until(lambda: len(served) >= 300)
        assert served == list(range(300))
        assert all(lock_held)
    finally:
        loop.stop()
    assert not loop.running


def test_the_executor_never_runs_the_subscription(pair):
    """The subscription's callback is a sentinel that raises if anything but the loop
    calls it; an executor spinning the node while messages arrive must not."""
    sender, server, executor, thread = pair
    served = []
    loop = SetpointLoop(server, Float64MultiArray, 'not_executor', served.append, control_qos())
    thread.start()
    pub = sender.create_publisher(Float64MultiArray, 'not_executor', control_qos())
    assert wait_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(Float64MultiArray(data=[1.0]))
    time.sleep(0.5)                    # the loop is not started: nobody may take it
    assert served == [] and thread.is_alive()
    loop.start()
    try:
        assert wait_until(lambda: len(served) == 1)   # queued, served once the loop runs
        assert thread.is_alive()       # the executor did not fail on the sentinel callback
    finally:
        loop.stop()


def test_an_error_in_the_callback_is_reported_and_the_loop_goes_on(pair):
    sender, server, executor, thread = pair
    served, errors = [], []

    def callback(msg):
        if msg.data[0] < 0:
            raise ValueError('negative')
        served.append(msg.data[0])

    loop = SetpointLoop(server, Float64MultiArray, 'errors', callback, control_qos(),
                        on_error=errors.append)
    loop.start()
    pub = sender.create_publisher(Float64MultiArray, 'errors', control_qos())
    assert wait_until(lambda: pub.get_subscription_count() > 0)
    for value in (1.0, -1.0, 2.0):
        pub.publish(Float64MultiArray(data=[value]))
    try:
        assert wait_until(lambda: len(served) == 2)
        assert served == [1.0, 2.0]
        assert len(errors) == 1 and isinstance(errors[0], ValueError)
        assert loop.running
    finally:
        loop.stop()
    assert not loop.running
    loop.stop()                        # a second stop is harmless
