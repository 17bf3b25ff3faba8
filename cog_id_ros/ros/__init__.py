"""cog_id_ros.ros: the ROS 2 face (needs rclpy): the node ``cog_id_node`` and its parts.

  node.py            the node: setpoints in, effort commands out, diagnostics
  parameters.py      the node's parameters: type, default, bounds, description (one table)
  topics.py          the node's topics: type, direction, QoS, meaning (one table)
  setpoint_loop.py   the thread that serves joint_setpoint outside the executor
  setpoint_filter.py the causal velocity and acceleration estimator of the setpoint stream
  conversions.py     ROS messages <-> arrays, rejection reasons, the trajectory process
  stop_signals.py    SIGINT / SIGTERM during start-up
  player.py          ``cog_id_player``: a CSV trajectory published as setpoints
  recorder.py        the efforts recorded in a process of their own, and the account of a
                     run: every setpoint answered and recorded, or where it went
"""
