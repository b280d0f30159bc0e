"""Cameras that agree: the simulation's cameras placed where a user's real ones stand.

board      the printed ChArUco board and where it lies relative to the arm
placement  a camera's pose from one picture of the board; the placements file the sim loads
sim_board  the board laid in the sim scene (the sim as a "real" camera, for tests and benchmarks)
cli        so101-camera-align
"""
