"""so101-learn: the learning recipes, one command each (demonstrations, LeRobot's ACT and
Diffusion on the state, behaviour cloning with `imitation`, SAC with Stable-Baselines3, evaluation).
See so101.learn.cli and docs/learning.md."""
