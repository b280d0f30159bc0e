"""Policies on the stack and their evaluation (so101-run-policy).

Layout (each module imports only those before it, and so101's shared facts, so101.stack and
so101.envs):
  stats.py       a success rate with its 95 % interval
  episodes.py    seeded evaluation episodes on a Gymnasium env of the stack, and their report
  expert.py      the scripted cube_to_bin expert in-process, as a policy over the envs' observations
  policy.py      a LeRobot policy behind the stack's units (radians in, radians out)
  run_policy.py  so101-run-policy: a LeRobot policy driving the arm live, or evaluated in lockstep
"""
