"""Wrappers for learning agents on the spacecraft environments.

:class:`ActionRepeat` lets an agent decide at a coarser period than the
plant's sample time (MuJoCo's ``frame_skip``, Atari's frame skipping). The
spacecraft's attitude moves on a scale of tens of seconds while the env
samples every 0.1 s, so an agent acting every sample has to assign credit
over hundreds of decisions; holding each action for 1 s brings that to tens.
Put it outermost (outside a features wrapper) so that whatever runs per
sample, such as an online identifier, still sees every sample.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["ActionRepeat"]


class ActionRepeat(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Apply each action for ``repeat`` consecutive env steps.

    The rewards of the repeated steps are summed (the return of an episode
    is unchanged); the observation, ``terminated``, ``truncated`` and
    ``info`` are those of the last step taken. The repetition stops early
    when the episode ends. ``info["repeated_steps"]`` is the number of env
    steps the action was held for.

    Parameters
    ----------
    env : gymnasium.Env
    repeat : int
        Env steps per action, >= 1 (10 holds an action for 1 s at the
        registered ``dt = 0.1 s``).
    """

    def __init__(self, env: gym.Env, repeat: int = 10) -> None:
        if isinstance(repeat, bool) or not isinstance(repeat, int | np.integer) or repeat < 1:
            raise ValueError(f"repeat must be an integer >= 1, got {repeat!r}")
        gym.utils.RecordConstructorArgs.__init__(self, repeat=repeat)
        gym.Wrapper.__init__(self, env)
        self.repeat = int(repeat)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        total, steps = 0.0, 0
        while True:
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            steps += 1
            if terminated or truncated or steps == self.repeat:
                break
        info["repeated_steps"] = steps
        return obs, total, terminated, truncated, info
