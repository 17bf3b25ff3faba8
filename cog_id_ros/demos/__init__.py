"""cog_id_ros.demos: the paper's example, end to end.

  paper_four_bar.py  the paper's target motion (defined once), its exact torque, config/
  fig4.py            Fig. 4 produced by two cog_id_node processes over ROS 2 (``./dev run``)
  table.py           the same torques from the Python API alone (``./dev table``, cog_id_demo)
"""
