"""Test helper: an env that keeps every action it was sent (test_perturbation, test_dagger)."""

from __future__ import annotations

import numpy as np


class Sent:
    """The env, keeping every action it was sent."""

    def __init__(self, env):
        self.env, self.actions = env, []

    def step(self, action):
        self.actions.append(np.asarray(action, dtype=np.float64))
        return self.env.step(action)
