"""The running stack from Python: its nodes started and stopped, and the rclpy tools beside them
(so101-launch, so101-replay, so101-description).

Layout (each module imports only those before it, the shared facts of so101 and so101.dataset):
  process.py         child processes started and stopped the way the nodes expect (SIGINT first)
  isolation.py       is this process inside a private network namespace? (scripts/isolated)
  rclpy_wait.py      waiting on the ROS graph from the rclpy tools
  description.py     so101-description: the arm's ROS package for RViz and MoveIt
  launch_plan.py     so101-launch's plan: which processes a profile starts, with their command lines (pure)
  record_session.py  timed recording sessions, as lerobot-record runs them
  launch.py          so101-launch: the plan run, stopped cleanly
  replay.py          so101-replay: one episode's recorded actions sent to the arm
"""
