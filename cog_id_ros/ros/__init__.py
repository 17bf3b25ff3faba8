"""cog_id_ros.ros: the ROS 2 face (needs rclpy): the nodes ``cog_id_node`` and
``cog_sim_node`` and their parts.

  node.py              the node's wiring: topics, timers, the callback that serves a setpoint
  main.py              ``cog_id_node``'s main (stop signals while it imports, usage, start-up)
  config.py            NodeConfig: what the node reads at start-up, frozen (node and worker)
  parameters.py        the node's parameters: type, default, bounds, description (one table)
  topics.py            the node's topics: type, direction, QoS, meaning (one table)
  setpoint_stream.py   a setpoint message -> the checked, estimated setpoint (or a rejection)
  setpoint_filter.py   the causal velocity and acceleration estimator of the setpoint stream
  modes.py             control modes: setpoint -> efforts (FeedForward: inverse dynamics)
  setpoint_loop.py     the thread that serves joint_setpoint outside the executor
  trajectory_worker.py trajectories solved in a process of their own
  diagnostics.py       the counts and /diagnostics status; guarded callbacks, throttled warnings
  conversions.py       ROS messages <-> arrays, rejection reasons, the one effort clip
  cdr.py               effort_command serialized by hand (one struct call)
  read_only_node.py    base of the nodes: parameters read once, then read-only
  startup.py           run a node: stop signals during start-up, spin, exit status
  command_line.py      --params-file checks and rcl's messages, naming the parameter
  stop_signals.py      SIGINT / SIGTERM during start-up
  sim_node.py          ``cog_sim_node``'s wiring: the mechanism simulated, efforts in, joint
                       states out (the physics: ``cog_id_ros.Simulation``)
  sim_main.py          ``cog_sim_node``'s main (main.py's, with its own usage)
  sim_parameters.py    its own parameters (one table; the shared ones are cog_id_node's entries)
  sim_topics.py        its topics and ~/reset (one table)
  sim_efforts.py       effort messages checked (or rejected by reason), then held
  sim_loop.py          the integration thread: paced steps, joint_states and /clock, reset
  sim_diagnostics.py   what it counts and its /diagnostics status
  player.py            ``cog_id_player``: a CSV trajectory published as setpoints
  recorder.py          the efforts recorded in a process of their own, and the account of a
                       run: every setpoint answered and recorded, or where it went
"""
