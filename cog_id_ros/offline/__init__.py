"""cog_id_ros.offline: the offline face (no ROS): the CSV tool ``cog_id_torques`` and its parts.

  cli.py             the tool: a CSV trajectory in, torques, summary and plot out
  trajectory_io.py   reading and writing trajectory CSV files
  derivatives.py     estimating missing velocities and accelerations (shared with the node)
  plotting.py        the torque plot
"""
