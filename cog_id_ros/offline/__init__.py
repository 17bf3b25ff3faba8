"""cog_id_ros.offline: the offline face (no ROS): the CSV tool ``cog_id_torques``, the
mechanism report ``cog_id_inspect``, and their parts.

  cli.py             the tool: a CSV trajectory in, torques, summary and plot out
  trajectory_io.py   reading and writing trajectory CSV files
  derivatives.py     estimating missing velocities and accelerations (shared with the node)
  plotting.py        the torque plot
  inspect.py         the report: tree, loops, DOF, the assembled pose beside the given one
  mechanism_plot.py  the mechanism drawn at a pose (and snapshots along a trajectory)
"""
