"""cog_id_ros.offline: the offline face (no ROS): the CSV tool ``cog_id_torques``, the
mechanism report ``cog_id_inspect``, the simulator ``cog_id_simulate``, and their parts.

cog_id_torques:
  cli.py             the tool: its options and its run, step by step (a CSV trajectory in,
                     torques, summary and plot out)
  skipped_rows.py    rows left unsolved before solving: jumps, pieces too short to estimate
  solving.py         the samples solved in chunks; a refused row named, or skipped
  floating_base.py   a floating-base robot: --contacts, whole_body_torques per chunk, the
                     wrench columns
  base_samples.py    its base columns read and checked, absent rates estimated
  summary.py         peak, RMS and power per joint, as a table or JSON
  outputs.py         the output paths checked first, the files written together at the end
  progress.py        the progress bar (cog_id_simulate's too)
  plotting.py        the torque plot (and cog_id_simulate's motion plot)

cog_id_inspect:
  inspect.py           the tool: its options and its run
  inspect_structure.py the report's header, spanning tree, loops and actuation
  inspect_pose.py      the joint table (given beside assembled pose) and the closure there
  inspect_motion.py    --trajectory solved along the branch, with snapshots
  mechanism_plot.py    the mechanism drawn at a pose (and snapshots along a trajectory)

cog_id_simulate:
  simulate.py        the tool: its options and its run (cog_id_ros.Simulation stepped, the
                     motion CSV, plot and summary out)
  simulate_inputs.py the efforts CSV read, the effort each step holds (hold or line between
                     rows), the initial state, the reference motion

shared (the tools, and some with the node):
  console.py         exit statuses, one-line errors, the parser, loading, main's frame
  stop_signals.py    SIGINT, SIGTERM, SIGHUP: a run stops, no temporary file is left
  trajectory_io.py   reading trajectory CSV files, writing and reading efforts CSV files
  samples.py         q, qd, qdd of the active joints, absent columns estimated
  derivatives.py     estimating missing velocities and accelerations (shared with the node)
  jumps.py           jumps between samples and wrapped angles; the default step limit
                     (shared with the node's max_setpoint_step)
  atomic_files.py    output files written whole or not at all
"""
