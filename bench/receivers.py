"""Receiving in a bench's driver without an rclpy executor (bench_node_latency.py,
bench_control_latency.py, bench_control_soak.py).

A driver that timestamps the answers of the nodes it measures must not add an rclpy
executor of its own to what it measures: an executor rebuilds its wait set and wraps
each message in a task before the callback runs (tens to hundreds of us on the 2-core
reference VM, and a tail of milliseconds when it falls behind). Every topic a driver
receives is served here by a thread of its own that waits on that subscription alone
(:class:`cog_id_ros.ros.setpoint_loop.SetpointLoop`, the node's own control-rate loop):
:func:`listen` for any topic, :class:`Diagnostics` for ``/diagnostics``.
"""
import time


def listen(node, msg_type, topic, callback, qos, **kwargs):
    """A started thread that calls ``callback(msg)`` for every message on ``topic`` (keywords
    go to the subscription, e.g. ``raw=True``); ``stop()`` it before the node is destroyed."""
    from cog_id_ros.ros.setpoint_loop import SetpointLoop
    loop = SetpointLoop(node, msg_type, topic, callback, qos, **kwargs)
    loop.start()
    return loop


def namespace_of(status_name):
    """'/ns' of a status named '/ns/<node>: ...' (None for a node outside a namespace)."""
    return '/' + status_name.split('/')[1] if status_name.count('/') > 1 else None


class Diagnostics:
    """Every DiagnosticStatus the nodes publish on /diagnostics, as received: ``reports``,
    (time.perf_counter() of arrival, namespace, {key: value}) in order of arrival."""

    def __init__(self, node):
        from diagnostic_msgs.msg import DiagnosticArray
        self.reports = []
        self.loop = listen(node, DiagnosticArray, '/diagnostics', self._on_diagnostics, 100)

    def _on_diagnostics(self, msg):
        now = time.perf_counter()
        for status in msg.status:
            ns = namespace_of(status.name)
            if ns is not None:
                self.reports.append((now, ns, {kv.key: kv.value for kv in status.values}))

    def latest(self, ns, after=-float('inf')):
        """The latest report of ``ns`` received after ``after`` (perf_counter), or None."""
        for t, name, values in reversed(self.reports):
            if t <= after:
                return None
            if name == ns:
                return values
        return None

    def first_after(self, ns, after):
        """The first report of ``ns`` received after ``after`` (perf_counter), or None."""
        for t, name, values in self.reports:
            if t > after and name == ns:
                return values
        return None

    def wait(self, namespaces, after, timeout):
        """{ns: the first report after ``after``} of each of ``namespaces``, waiting up to
        ``timeout`` s for them (a namespace without one maps to {})."""
        end = time.perf_counter() + timeout
        while True:
            found = {ns: self.first_after(ns, after) for ns in namespaces}
            if all(v is not None for v in found.values()) or time.perf_counter() > end:
                return {ns: v or {} for ns, v in found.items()}
            time.sleep(0.05)

    def close(self):
        self.loop.stop()
