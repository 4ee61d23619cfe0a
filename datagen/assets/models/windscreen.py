"""A cockpit camera's windscreen frame: the arch a camera behind the windscreen sees at the
edges of its view (the canopy bow and its two posts), in the receiver's body frame.

It is built around the mount's nominal camera (:meth:`datagen.assets.rig.Mount.body_from_cam`),
half a metre ahead of the lens: the posts rise from beyond the view's sides, below its middle,
to beyond its top corners, crossing the upper corners, and the bow joins them just above the
view's top (a turn of the camera brings it in). The camera's mount jitter and vibration move the
camera, not the frame. The renderer draws it for a camera that looks through a windscreen
(:attr:`datagen.assets.rig.Mount.window`); it occludes like anything else.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

import numpy as np

from datagen.assets.loader import concatenated
from datagen.assets.models.loft import tube

if TYPE_CHECKING:
    import trimesh

    from datagen.assets.rig import Mount

__all__ = ["FRAME_RADIUS_M", "windscreen_frame"]

#: The frame's tubes' radius, metres.
FRAME_RADIUS_M: Final = 0.012
#: The posts and the bow in the nominal camera's frame (OpenCV: x right, y down, z forward),
#: metres: a post's foot and head (the other post is its mirror), and the bow's middle.
POST_FOOT: Final = (-0.45, 0.12, 0.45)
POST_HEAD: Final = (-0.29, -0.23, 0.5)
BOW_MIDDLE: Final = (0.0, -0.215, 0.52)


def windscreen_frame(mount: Mount) -> trimesh.Trimesh:
    """The frame's mesh in ``mount``'s body frame."""
    def mirrored(p):
        return (-p[0], p[1], p[2])

    paths = ([POST_FOOT, POST_HEAD], [mirrored(POST_FOOT), mirrored(POST_HEAD)],
             [POST_HEAD, BOW_MIDDLE, mirrored(POST_HEAD)])
    body_from_cam = mount.body_from_cam()
    parts = []
    for path in paths:
        cam = np.asarray(path, dtype=np.float64)
        parts.append(tube(cam @ body_from_cam[:3, :3].T + body_from_cam[:3, 3], FRAME_RADIUS_M, n=12))
    return concatenated(parts)
