"""Episode bags to LeRobot datasets, and their check (so101-bag-to-lerobot, so101-dataset-check).

Layout (each module imports only those before it, and the shared facts of so101):
  commands.py   the targets the robot obeyed: command messages by the nodes' rules (pure)
  resample.py   streams recorded at their own rates onto the dataset's frame grid (pure)
  bags.py       recorder_node's episode bags read: streams, camera frames read twice, never all at once
  check.py      so101-dataset-check: a converted dataset as LeRobot will read it
  convert.py    so101-bag-to-lerobot: bags -> a LeRobot dataset (codebase v3.0), then the check
"""
