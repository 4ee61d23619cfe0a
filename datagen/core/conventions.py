"""Every frame, axis and pixel convention datagen uses, written down once.

Nothing else in the package may restate these facts; import them from here.

Body frames (paper, Fig. 7 and Fig. 12)
    x forward, y left, z up, right-handed.

    =========  =====================================================
    object     origin
    =========  =====================================================
    receiver   the refueling probe tip (receiver and probe are one body)
    drogue     the drogue (basket) centre
    tanker     the *average* drogue centre: a fixed offset behind and
               below the tanker's hose port, not a point on the airframe
    =========  =====================================================

World frame
    An inertial frame with the same axis sense as the body frames: z up,
    x along the tanker's initial heading, y to its left. The approach model's
    drogue-centred local frame (paper Fig. 7) is a translation of it.
    z is the altitude above the sea at the camera's nadir: the sea is the
    sphere of radius :data:`EARTH_RADIUS_M` whose top is the world's z = 0
    directly below the camera (a local-level frame; the aircraft fly in it
    as on a flat earth, the earth's surface and the horizon are round).

Camera frame (OpenCV)
    x right, y down, z forward (along the optical axis). A point is in front of
    the camera iff its z exceeds :data:`NEAR_PLANE_M`.

Mitsuba camera frame
    Mitsuba's sensors look along local +z with local +y up and local +x *left*
    (``mi.ScalarTransform4f.look_at`` builds the columns left, up, forward).
    :data:`CVCAM_FROM_MICAM` converts between the two; it is its own inverse.

Pixels (continuous)
    The image spans ``[0, W] x [0, H]``; pixel ``(i, j)`` (column i, row j)
    covers ``[i, i+1) x [j, j+1)``, so its centre is ``(i + 0.5, j + 0.5)``.
    ``K`` has ``cx = W / 2`` and ``cy = H / 2`` exactly (Table 1: 1024.0, 540.0
    for 2048x1080). YOLO values are these coordinates divided by W and H.
    Mitsuba's film uses the same continuous convention: a film position sample
    ``s`` in ``[0, 1]^2`` lands at ``uv_px = s * (W, H)``. OpenCV's drawing
    functions put integer coordinates at pixel *centres*: a mark at continuous
    ``(u, v)`` is drawn at :func:`drawing_px` ``(u, v) = (u - 0.5, v - 0.5)``.

Time within a frame
    A frame's time (its poses, its labels without a rolling shutter) is the middle of its
    exposure. A rolling shutter reads the rows out from the top down over ``readout_s``:
    the image's continuous row ``v`` is exposed centred at the frame's time plus
    :func:`row_time_s` ``(v, H, readout_s) = (v / H - 1/2) readout_s``; the middle of the
    image (``v = H / 2``) at the frame's time. A global shutter's ``readout_s`` is 0.

Objects and mounts
    :data:`OBJECT_NAMES` are the rigid bodies of a refueling scene, in the order
    their object ids are assigned (:func:`object_id`: 1-based; 0 is background);
    :data:`RIGID_OBJECTS` are those with a mesh and a feature file (the hose is
    made per frame), which are the objects whose features can be labeled.
    :data:`CAMERA_MOUNTS` are the paper's camera positions (their geometry is
    :data:`datagen.assets.rig.MOUNTS`).

Transforms
    A 4x4 homogeneous matrix that maps coordinates in frame ``a`` to frame ``b``
    is named ``b_from_a``; they compose right to left:
    ``cam_from_receiver = cam_from_world @ world_from_receiver``.
    Point arrays are named by their frame (``points_model``, ``points_cam``,
    ``uv_px``). Units are metres and radians in code, degrees in configs.

Randomness
    One root seed per config. Frame ``i`` draws everything that is its own
    (sky, sun, materials) from :func:`frame_rng` ``(seed, i)``. Draws
    shared by the consecutive frames of one approach chain ``a`` (initial pose,
    turbulence, tanker flight, mount perturbation) come from
    :func:`approach_rng` ``(seed, a)``, a separate stream (spawn key
    ``(a, APPROACH_STREAM)``) that can never collide with a frame's (with
    approach model 2 the drogue's gusts come from :func:`gust_rng` ``(seed,
    a)``, spawn key ``(a, GUST_STREAM)``). Random
    surface features (paper model I) come from :func:`random_features_rng`
    ``(seed, object)``, spawn key ``(object id - 1, RANDOM_FEATURES_STREAM)``.
    The train/val split of a frame comes from :func:`split_uniform` ``(seed,
    unit)``, spawn key ``(unit, SPLIT_STREAM)``, where the unit is the frame
    index (or the approach chain index with ``dataset.split_by: approach``): a
    stream of its own, so that changing ``val_fraction`` moves frames between
    splits without changing any frame's sky, materials or pose. Mitsuba's
    sampler seed of frame ``i`` is :func:`render_seed` ``(seed, i)``, the first
    word of the frame's own seed sequence; ``datagen evaluate``'s pixel noise
    comes from :func:`evaluation_rng` ``(seed, i, run)``. The world's draws
    (sun, clouds, sea, liveries, sensor) come from :func:`world_rng` ``(seed,
    index, dimension)``, spawn key ``(index, WORLD_STREAM, dimension)``; a
    procedural texture or noise field is made from a seed drawn there and
    recorded in the manifest, through :func:`texture_rng` ``(texture_seed)``.
    No module uses a global RNG.
"""

from __future__ import annotations

from typing import Final

import numpy as np

__all__ = [
    "BODY_FORWARD",
    "BODY_LEFT",
    "BODY_UP",
    "CAMERA_MOUNTS",
    "CVCAM_FROM_MICAM",
    "CV_DOWN",
    "CV_FORWARD",
    "CV_RIGHT",
    "EARTH_RADIUS_M",
    "GRAVITY_MPS2",
    "GUST_STREAM",
    "MICAM_FROM_CVCAM",
    "NEAR_PLANE_M",
    "OBJECT_NAMES",
    "OTHER_AIRCRAFT_ID",
    "PIXEL_CONVENTION",
    "RIGID_OBJECTS",
    "SEALANT_PART",
    "TARGET_STREAM",
    "WORLD_DIMENSIONS",
    "WORLD_STREAM",
    "approach_rng",
    "drawing_px",
    "evaluation_rng",
    "frame_rng",
    "frame_seed_sequence",
    "gust_rng",
    "index_px",
    "object_id",
    "pixel_centre",
    "pixel_centres",
    "random_features_rng",
    "render_seed",
    "split_uniform",
    "target_render_seed",
    "texture_part_rng",
    "texture_rng",
    "world_rng",
]

# --- the earth ------------------------------------------------------------------
#: The earth's mean radius, metres (IUGG): the sea's sphere (see World frame).
EARTH_RADIUS_M: Final[float] = 6_371_008.8

# --- body frames -------------------------------------------------------------
BODY_FORWARD: Final = np.array([1.0, 0.0, 0.0])
BODY_LEFT: Final = np.array([0.0, 1.0, 0.0])
BODY_UP: Final = np.array([0.0, 0.0, 1.0])
#: Standard gravity, m/s^2, along the world's -z (the tanker's turns, the sea's waves).
GRAVITY_MPS2: Final = 9.80665

#: The rigid bodies of a refueling scene, in the order their object ids are
#: assigned (id = index + 1; id 0 is background).
OBJECT_NAMES: Final[tuple[str, ...]] = ("tanker", "receiver", "drogue", "hose")
#: The objects with a mesh and a feature file (the hose is made per frame): the ones
#: whose features can be labeled.
RIGID_OBJECTS: Final[tuple[str, ...]] = OBJECT_NAMES[:3]
#: The paper's camera mounts (3.1): receiver right wing pod, receiver cockpit, tanker hose pod.
CAMERA_MOUNTS: Final[tuple[str, ...]] = ("wingcam", "dashcam", "podcam")


def object_id(name: str) -> int:
    """The ``object_id`` of an object in the EXR and the geometry pass: 1-based position in
    :data:`OBJECT_NAMES` (0 is the background: the sea or nothing; :data:`OTHER_AIRCRAFT_ID`
    another aircraft, never labeled)."""
    return OBJECT_NAMES.index(name) + 1


#: The ``object_id`` of another aircraft in view (:mod:`datagen.scene.traffic`): after every
#: object's, so that no labeled object's mask or motion takes its pixels.
OTHER_AIRCRAFT_ID: Final[int] = len(OBJECT_NAMES) + 1

# --- camera frames -----------------------------------------------------------
CV_RIGHT: Final = np.array([1.0, 0.0, 0.0])
CV_DOWN: Final = np.array([0.0, 1.0, 0.0])
CV_FORWARD: Final = np.array([0.0, 0.0, 1.0])

#: Points with camera-frame z at or below this (metres) are "at or behind the
#: camera plane": they are never projected into a label.
NEAR_PLANE_M: Final[float] = 1e-6

#: Maps Mitsuba camera-local coordinates (x left, y up, z forward) to OpenCV
#: camera coordinates (x right, y down, z forward). Self-inverse.
CVCAM_FROM_MICAM: Final = np.diag([-1.0, -1.0, 1.0, 1.0])
MICAM_FROM_CVCAM: Final = CVCAM_FROM_MICAM

for _a in (BODY_FORWARD, BODY_LEFT, BODY_UP, CV_RIGHT, CV_DOWN, CV_FORWARD, CVCAM_FROM_MICAM):
    _a.setflags(write=False)

# --- pixels ------------------------------------------------------------------
#: Recorded in every dataset so that readers know how to interpret pixel values.
PIXEL_CONVENTION: Final[str] = "continuous"


def index_px(uv_px):
    """Continuous pixel coordinates ``uv_px`` (``(..., 2)``, or any array of u or v values)
    in the pixel-index convention, where integer coordinates are pixel centres: half a
    pixel up and left. OpenCV's drawing grid, COCO keypoints and the camera matrices of the
    BOP format use it.

    >>> index_px([0.5, 2047.5]).tolist()  # the first and last pixel centres of a 2048-pixel row
    [0.0, 2047.0]
    """
    return np.asarray(uv_px, dtype=np.float64) - 0.5


def drawing_px(uv_px):
    """Where OpenCV draws a mark at continuous pixel coordinates ``uv_px`` (``(..., 2)``)."""
    return index_px(uv_px)


def pixel_centre(index):
    """The continuous coordinate of the centre of pixel ``index`` (any array of column or
    row indices, its dtype kept): ``index + 0.5``. The image's centre ``W / 2`` is the
    corner shared by its middle pixels.

    >>> pixel_centre(0), pixel_centre(np.arange(1023, 1025)).tolist()
    (0.5, [1023.5, 1024.5])
    """
    return index + 0.5


def pixel_centres(width: int, height: int, stride: int = 1):
    """``(u, v)`` grids ``(h, w)`` of the continuous coordinates of every pixel centre
    (``stride`` 1) or of the centre of every ``stride`` x ``stride`` block."""
    w, h = -(-width // stride), -(-height // stride)
    # A block's centre is the centre of its middle pixel: index i * stride + (stride - 1) / 2.
    return np.meshgrid(pixel_centre(np.arange(w) * stride + (stride - 1) / 2),
                       pixel_centre(np.arange(h) * stride + (stride - 1) / 2))


# --- randomness --------------------------------------------------------------
#: Luminance of linear RGB (Rec. 709 primaries, the renderer's ``*_rgb`` variants): its weights.
REC709_LUMA: Final = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def luminance(rgb):
    """Rec. 709 luminance of linear RGB ``(..., 3)``, float32."""
    return np.asarray(rgb, dtype=np.float32) @ REC709_LUMA


def row_time_s(v_px, height: int, readout_s):
    """When a rolling shutter exposed the image's continuous row ``v_px`` (any array),
    seconds after the frame's time (see Time within a frame); ``readout_s`` broadcasts.

    >>> row_time_s(np.array([0.0, 540.0, 1080.0]), 1080, 0.02).tolist()
    [-0.01, 0.0, 0.01]
    """
    return (np.asarray(v_px) / height - 0.5) * readout_s


def frame_seed_sequence(seed: int, frame_index: int) -> np.random.SeedSequence:
    """The seed sequence of frame ``frame_index`` under root seed ``seed``."""
    return np.random.SeedSequence(seed, spawn_key=(frame_index,))


def frame_rng(seed: int, frame_index: int) -> np.random.Generator:
    """The RNG every draw for frame ``frame_index`` comes from.

    A pure function of ``(seed, frame_index)``: a frame can be regenerated
    alone, on any worker, in any order.
    """
    return np.random.default_rng(frame_seed_sequence(seed, frame_index))


def render_seed(seed: int, frame_index: int) -> int:
    """Mitsuba's sampler seed for frame ``frame_index``: the first word of its seed sequence."""
    return int(frame_seed_sequence(seed, frame_index).generate_state(1, dtype=np.uint32)[0])


#: Spawn key of the target pass's sampler seed under a frame's render seed.
TARGET_STREAM: Final[int] = 7


def target_render_seed(seed: int) -> int:
    """Mitsuba's sampler seed for a frame's target pass (:mod:`datagen.render.target`), whose
    render seed is ``seed``: the first word of the seed sequence keyed by it and
    :data:`TARGET_STREAM`, so that the pass's samples are not the frame's."""
    return int(np.random.SeedSequence(seed, spawn_key=(TARGET_STREAM,)).generate_state(1, dtype=np.uint32)[0])


#: Second spawn-key element of the approach streams (frame streams have one-element keys).
APPROACH_STREAM: Final[int] = 1


def approach_rng(seed: int, approach_index: int) -> np.random.Generator:
    """The RNG of approach chain ``approach_index``: every draw its frames share."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(approach_index, APPROACH_STREAM)))


#: Second spawn-key element of the drogue-gust streams (approach model 2).
GUST_STREAM: Final[int] = 6


def gust_rng(seed: int, approach_index: int) -> np.random.Generator:
    """The RNG of approach chain ``approach_index``'s drogue gusts (approach model 2; model 1
    draws them from :func:`approach_rng`)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(approach_index, GUST_STREAM)))


#: Second spawn-key element of the random-feature streams (paper model I).
RANDOM_FEATURES_STREAM: Final[int] = 2


def random_features_rng(seed: int, object_name: str) -> np.random.Generator:
    """The RNG that places random surface features (paper model I) on one object."""
    key = (OBJECT_NAMES.index(object_name), RANDOM_FEATURES_STREAM)
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


#: Second spawn-key element of the train/val split streams.
SPLIT_STREAM: Final[int] = 3


def split_uniform(seed: int, unit: int) -> float:
    """A uniform number in [0, 1) that decides the split of split unit ``unit``
    (a frame, or an approach chain): the unit goes to ``val`` when it is below
    ``val_fraction``. 32 bits of the unit's own seed sequence (cheap: no generator)."""
    state = np.random.SeedSequence(seed, spawn_key=(unit, SPLIT_STREAM)).generate_state(1, dtype=np.uint32)
    return float(state[0]) / 2.0**32


#: Second spawn-key element of the evaluation's pixel-noise streams.
EVALUATION_STREAM: Final[int] = 4


def evaluation_rng(seed: int, frame_index: int, run: int) -> np.random.Generator:
    """The RNG of the pixel noise ``datagen evaluate`` adds to frame ``frame_index`` in
    its ``run``-th noise setting (spawn key ``(frame, EVALUATION_STREAM, run)``)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(frame_index, EVALUATION_STREAM, run)))


#: Second spawn-key element of the world streams (clouds, sea state, liveries, sensor, backlit sun).
WORLD_STREAM: Final[int] = 5
#: The world's randomization dimensions, each with its own stream (third spawn-key element: the
#: index here), so that switching one on or off changes no draw of another, nor of the look.
#: The sun and the sensor are drawn per frame; clouds, sea, liveries, the atmosphere, the
#: ground, the camera's vibration, the drogue's canopy, the camera's window and other traffic
#: per approach chain.
WORLD_DIMENSIONS: Final[tuple[str, ...]] = ("sun", "clouds", "sea", "livery", "sensor", "atmosphere", "ground",
                                            "vibration", "drogue", "window", "traffic")


def world_rng(seed: int, index: int, dimension: str) -> np.random.Generator:
    """The RNG of one world dimension: of frame ``index`` (sun, sensor) or of approach chain
    ``index`` (clouds, sea, livery); spawn key ``(index, WORLD_STREAM, WORLD_DIMENSIONS.index(dimension))``
    (the dimensions keep the two kinds of index apart)."""
    key = (index, WORLD_STREAM, WORLD_DIMENSIONS.index(dimension))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def texture_rng(texture_seed: int) -> np.random.Generator:
    """The RNG that makes a procedural texture or noise field (a cloud layer, the waves, a
    livery, a frame's sensor noise) from its seed, itself drawn from a :func:`world_rng`
    stream and recorded in the manifest (so that the texture can be remade from the row)."""
    return np.random.default_rng(texture_seed)


#: The part number of a livery's seam sealant, drawn after the livery (:func:`texture_part_rng`).
SEALANT_PART: Final[int] = 1


def texture_part_rng(texture_seed: int, part: int) -> np.random.Generator:
    """The RNG of a part of a procedural texture drawn after the texture itself (a livery's
    seam sealant: :data:`SEALANT_PART`), apart from :func:`texture_rng`'s stream: adding a part
    shifts none of the texture's draws, nor any draw after them."""
    return np.random.default_rng((texture_seed, part))  # entropy (seed, part): never texture_rng's
