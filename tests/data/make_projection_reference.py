"""Regenerate ``projection_reference.json`` with OpenCV, independently of datagen.

Run from the repository root: ``python tests/data/make_projection_reference.py``.
The intrinsics follow the paper's Table 1 literally; the projections come from
``cv2.projectPoints`` with zero distortion. datagen's own camera code is not used.
"""

import json
import math
from pathlib import Path

import cv2
import numpy as np

OUT = Path(__file__).with_name("projection_reference.json")


def main() -> None:
    rng = np.random.default_rng(20241121)
    cases = []
    for hfov_deg in (15.0, 25.0, 55.0, 75.0):
        for width, height in ((2048, 1080), (640, 338)):
            cx, cy = width / 2.0, height / 2.0
            f = cx / math.tan(math.radians(hfov_deg) / 2.0)
            K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
            rvec = rng.normal(size=3)
            tvec = np.array([rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(20, 120)])
            points = rng.uniform(-8.0, 8.0, size=(12, 3))
            uv, _ = cv2.projectPoints(points, rvec, tvec, K, np.zeros(5))
            rotation, _ = cv2.Rodrigues(rvec)
            cases.append(
                {
                    "hfov_deg": hfov_deg,
                    "width": width,
                    "height": height,
                    "K": K.tolist(),
                    "rvec": rvec.tolist(),
                    "cam_from_model_rotation": rotation.tolist(),
                    "cam_from_model_translation": tvec.tolist(),
                    "points_model": points.tolist(),
                    "uv_px": uv.reshape(-1, 2).tolist(),
                }
            )
    OUT.write_text(
        json.dumps({"generator": f"cv2.projectPoints, OpenCV {cv2.__version__}", "cases": cases}, indent=1)
        + "\n"
    )


if __name__ == "__main__":
    main()
