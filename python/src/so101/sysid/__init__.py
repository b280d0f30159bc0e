"""so101-sysid: identify the STS3215 model of your own arm from its logs.

- `record` (record.py) drives the arm through the driver, one joint at a time, through steps,
  holds under gravity and a chirp (excitation.py), and records one bag per joint;
- `fit` (fit.py) fits the servo model's free parameters per joint so that its replay of the
  recorded goals matches the recorded positions, and writes the parameter file that
  so101_sim_node --servo-params, the Gym envs (servo_params=), LeRobot's so101_sim env type and
  so101_servo_emulator --servo-params load;
- `compare` (compare.py) replays any recorded episode's commands in the simulation and reports the
  tracking gap per joint (RMS and max, rad) and at the gripper (mm), with the preset and the fit.

docs/sim_to_real.md walks through it.
"""
