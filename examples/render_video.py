"""Render an episode to an animated GIF (``render_mode="rgb_array"``).

Gymnasium's ``RecordVideo`` wrapper works too when moviepy is installed; this
example needs only Pillow, a dependency of the package.

    python examples/render_video.py [--steps 1500] [--out docking.gif]
"""

import argparse

import gymnasium as gym
from PIL import Image

from controllers import AdaptiveLQG

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=1500, help="env steps (0.1 s each)")
parser.add_argument("--every", type=int, default=10, help="one frame per this many steps")
parser.add_argument("--out", default="docking.gif")
args = parser.parse_args()

env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2", task="slew", render_mode="rgb_array")
ctrl = AdaptiveLQG(env.unwrapped)
obs, info = env.reset(seed=0)
ctrl.reset(seed=0)
frames = []
for k in range(args.steps):
    obs, reward, terminated, truncated, info = env.step(ctrl.act(obs, info))
    if k % args.every == 0:
        frames.append(Image.fromarray(env.render()))
    if terminated or truncated:
        break
frames[0].save(args.out, save_all=True, append_images=frames[1:], duration=100, loop=0)
print(f"wrote {args.out}: {len(frames)} frames, {info['time']:.0f} s of flight")
