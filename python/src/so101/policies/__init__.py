"""Policy models of the stack's own, each a LeRobot policy type (PreTrainedConfig,
PreTrainedPolicy and processors by LeRobot's naming convention), registered when imported:
  pose_act/  `pose_act`: ACT on the joints and the cube's pose, the pose estimated from the
             cameras by a CNN trained beside it (plugin lerobot_policy_so101_pose_act)
Nothing is imported here."""
