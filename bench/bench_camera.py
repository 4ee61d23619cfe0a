"""The camera as flown, per mount, without rendering: the image motion over each frame's
exposure of the drogue's centre and of the image's corners (the camera's own turn), with the
camera's vibration on and off; and the share of frames with another aircraft in view, wet
windows and dark drogue canopies.

    python bench/bench_camera.py [--frames 2000] [--seed 11]

Image motion is the displacement over the frame's drawn exposure (``sensor_exposure_time_s``)
of where a point projects, from the frame's pose and the pose ``MOTION_DT_S`` earlier (the
motion blur's own finite difference): for the drogue, its true centre; for the corners, points
at infinity (the sky, which only the camera's turn moves). Prints a markdown table per scene:
percentiles 50/90/99 of each, px.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def motions(scene: str, frames: int, seed: int, vibration: bool) -> dict[str, np.ndarray]:
    from datagen.config import load_config, override_config
    from datagen.config.schema import world_off
    from datagen.core.camera import Intrinsics, project_points
    from datagen.core.transforms import invert_rigid
    from datagen.scene.approach import FrameStates
    from datagen.scene.look import frame_look

    config = override_config(load_config(scene), {"dataset.seed": seed, "dataset.frames": frames,
                                                 **({} if vibration else world_off("vibration"))})
    c = config.camera
    k = Intrinsics.from_hfov_deg(c.width, c.height, c.hfov_deg)
    corners = np.array([[-k.cx / k.fx, -k.cy / k.fy, 1.0], [(c.width - k.cx) / k.fx, (c.height - k.cy) / k.fy, 1.0]])
    states = FrameStates(config)
    drogue, corner, traffic, wet, dark = [], [], [], [], []
    from datagen.assets.drogues import CANOPIES, DARK_FABRICS

    for i in range(frames):
        state = states(i)
        look = frame_look(config, state)
        earlier = state.earlier
        scale = look.sensor_exposure_time_s / (state.time_s - earlier.time_s)
        now, before = (project_points((invert_rigid(s.world_from_cam) @ s.world_from_drogue)[None, :3, 3], k)[0]
                       for s in (state, earlier))  # the drogue's centre, where it is at each time
        drogue.append(np.linalg.norm(now - before) * scale)
        turn = earlier.cam_from_world[:3, :3] @ state.world_from_cam[:3, :3]  # directions: now -> earlier camera
        moved = project_points(corners @ turn.T, k) - project_points(corners, k)
        corner.append(float(np.linalg.norm(moved, axis=1).max()) * scale)
        traffic.append(look.other_aircraft not in (None, "none"))
        wet.append(bool(look.window_droplets))
        dark.append(look.drogue_canopy is not None and CANOPIES[look.drogue_canopy].fabric in DARK_FABRICS)
    return {"drogue": np.array(drogue), "corner": np.array(corner), "traffic": np.array(traffic),
            "wet": np.array(wet), "dark": np.array(dark)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["wingcam55", "podcam15", "podcam25", "dashcam75"])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    print("| scene | vibration | drogue motion px p50/p90/p99 | turn at a corner px p50/p90/p99 | other aircraft "
          "| wet window | dark canopy |")
    print("|---|---|---|---|---|---|---|")
    for scene in args.scenes:
        for on in (False, True):
            m = motions(scene, args.frames, args.seed, on)

            def pct(a):
                return "/".join(f"{v:.2f}" for v in np.percentile(a, [50, 90, 99]))

            print(f"| {scene} | {'on' if on else 'off'} | {pct(m['drogue'])} | {pct(m['corner'])} | "
                  f"{m['traffic'].mean():.0%} | {m['wet'].mean():.0%} | {m['dark'].mean():.0%} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
