"""Receiver: an F/A-18-class fighter with a refueling probe on the right of the nose.

About 17 m long and 12 m across the wingtip missiles. Receiver body frame: x
forward, y left, z up, origin at the probe tip; the centreline lies
:data:`datagen.assets.rig.RECEIVER_CENTRELINE_Y_M` to the left of the tip. The right
wing carries the wingcam pod whose nose sits just behind the wingcam mount of
:data:`datagen.assets.rig.MOUNTS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datagen.assets.models import FeatureAnchor, Model
from datagen.assets.models.loft import (
    Panel,
    Parts,
    box,
    decal,
    ellipsoid,
    loft,
    mirror_y,
    superellipse_ring,
    tube,
    wing,
)
from datagen.assets.rig import MOUNTS, RECEIVER_CENTRELINE_Y_M

__all__ = ["build_receiver"]

Y0 = RECEIVER_CENTRELINE_Y_M
Z0 = -0.55  # fuselage reference line
X_NOSE = -0.9  # radome tip: the probe reaches 0.9 m past it

# (distance aft of the nose, half width, half height, centre offset in z, superellipse exponent)
_STATIONS = (
    (0.0, 0.0, 0.0, -0.05, 2.0),
    (0.3, 0.16, 0.17, -0.04, 2.0),
    (0.9, 0.33, 0.35, -0.02, 2.1),
    (1.8, 0.48, 0.50, 0.00, 2.2),
    (3.0, 0.58, 0.62, 0.02, 2.3),
    (4.2, 0.63, 0.68, 0.04, 2.5),
    (5.5, 0.72, 0.72, 0.02, 2.8),
    (7.0, 0.95, 0.74, 0.00, 3.0),
    (9.0, 1.15, 0.74, 0.00, 3.2),
    (11.5, 1.20, 0.72, 0.00, 3.2),
    (13.2, 1.15, 0.68, 0.02, 3.0),
    (15.0, 1.00, 0.62, 0.02, 2.8),
    (16.4, 0.92, 0.55, 0.00, 2.6),
)
_RADOME_END = 3  # stations [0, 3] are the radome


def _rings(stations, n: int = 48) -> list[np.ndarray]:
    return [superellipse_ring(X_NOSE - s, Y0, Z0 + dz, hw, hh, n, e) for s, hw, hh, dz, e in stations]


def _fuselage(parts: Parts) -> None:
    parts.add("radome", loft(_rings(_STATIONS[: _RADOME_END + 1])))
    parts.add("paint", loft(_rings(_STATIONS[_RADOME_END:])))


def _probe_path(tip: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points from the probe tip back to its base and the radius at each: a
    pointed nozzle, a wider coupling ring, then the mast."""
    axis = (base - tip) / np.linalg.norm(base - tip)
    length = float(np.linalg.norm(base - tip))
    profile = [(0.0, 0.0), (0.015, 0.022), (0.05, 0.045), (0.10, 0.060), (0.13, 0.066), (0.34, 0.066),
               (0.37, 0.050), (length * 0.5, 0.050), (length - 0.15, 0.055), (length, 0.055)]
    s = np.array([p[0] for p in profile])
    return tip + np.outer(s, axis), np.array([p[1] for p in profile])


#: The probe: its tip at the origin, its base on the upper right of the forward fuselage.
PROBE_TIP = np.zeros(3)
PROBE_BASE = np.array([-3.75, 0.13, -0.16])
#: The canopy: an ellipsoid's centre and radii.
CANOPY_CENTRE = np.array([X_NOSE - 4.4, Y0, Z0 + 0.45])
CANOPY_RADII = np.array([1.9, 0.48, 0.50])
#: The intakes: the x of their faces, their y off the centreline, z, width and height.
INTAKE_FRONT, INTAKE_Y, INTAKE_Z, INTAKE_W, INTAKE_H = -8.0, 1.02, Z0 - 0.32, 0.55, 0.72
#: The wingtip missiles' y off the centreline.
MISSILE_Y = 5.92
#: The x of the fuselage's tail (the nozzles' station).
X_TAIL = X_NOSE - _STATIONS[-1][0]


@dataclass(frozen=True)
class _Surfaces:
    """The right-hand flying surfaces (the left ones are their mirror images)."""

    lex: Panel
    wing: Panel
    stab: Panel
    tail: Panel


def build_receiver() -> Model:
    """The receiver's meshes, part by part, and its feature anchors."""
    parts = Parts()
    _fuselage(parts)
    fuselage = parts.build()["paint"]
    probe = _probe(parts)
    _canopy(parts)
    _intakes(parts)
    surfaces = _flying_surfaces(parts)
    _wingtip_missiles(parts)
    pod_nose = _wing_pods(parts, surfaces.wing)
    _tail_details(parts)
    _markings(parts, fuselage, surfaces)
    return Model("receiver", parts.build(), tuple(_anchors(probe, surfaces, pod_nose)), small_radius_m=0.06)


def _probe(parts: Parts) -> np.ndarray:
    """The probe and its fairing; returns the probe's centreline, tip first."""
    path, radius = _probe_path(PROBE_TIP, PROBE_BASE)
    parts.add("probe", tube(path, radius, n=20))
    parts.add("paint", ellipsoid(PROBE_BASE + np.array([-0.15, 0.02, -0.02]), (0.45, 0.10, 0.09), subdivisions=2))
    return path


def _canopy(parts: Parts) -> None:
    """The canopy glass and its bow frame."""
    parts.add("glass", ellipsoid(CANOPY_CENTRE, CANOPY_RADII, subdivisions=4))
    parts.add("paint", box(CANOPY_CENTRE + np.array([-0.2, 0.0, 0.0]), (0.08, 0.98, 1.02)))  # canopy bow frame


def _intakes(parts: Parts) -> None:
    """The intakes under the leading-edge extensions, with dark inlet faces."""
    for side in (-1, 1):
        yc = Y0 + side * INTAKE_Y
        parts.add("paint", box((INTAKE_FRONT - 1.75, yc, INTAKE_Z), (3.5, INTAKE_W, INTAKE_H)))
        parts.add("engine_inlets", box((INTAKE_FRONT + 0.005, yc, INTAKE_Z), (0.02, INTAKE_W - 0.1, INTAKE_H - 0.1)))


def _flying_surfaces(parts: Parts) -> _Surfaces:
    """Leading-edge extensions, wings, stabilators and canted twin tails, both sides."""
    surfaces = _Surfaces(
        lex=Panel((-4.6, Y0 - 0.55, Z0 + 0.2), 6.0, (-9.0, Y0 - 1.55, Z0 + 0.1), 1.9, thickness=0.03),
        wing=Panel((-9.2, Y0 - 1.1, Z0), 4.4, (-11.9, Y0 - 5.75, Z0 - 0.07), 1.65, thickness=(0.05, 0.04)),
        stab=Panel((-15.0, Y0 - 1.0, Z0 - 0.05), 2.7, (-16.7, Y0 - 3.35, Z0 - 0.05), 1.1, thickness=0.045),
        tail=Panel((-12.6, Y0 - 0.85, Z0 + 0.6), 3.3, (-15.4, Y0 - 1.85, Z0 + 3.45), 1.45, thickness=0.05,
                   vertical=True),
    )
    for panel in (surfaces.lex, surfaces.wing, surfaces.stab, surfaces.tail):
        parts.add_mirrored("paint", Y0, panel.mesh())
    return surfaces


def _wingtip_missiles(parts: Parts) -> None:
    """The wingtip launch rails and their missiles."""
    for side in (-1, 1):
        y = Y0 + side * MISSILE_Y
        parts.add("paint", box((-12.65, Y0 + side * 5.82, Z0 - 0.07), (2.3, 0.1, 0.08)))
        body = np.array([[-11.0, y, Z0 - 0.07], [-11.06, y, Z0 - 0.07], [-11.3, y, Z0 - 0.07],
                         [-13.85, y, Z0 - 0.07], [-13.9, y, Z0 - 0.07]])
        parts.add("stores", tube(body, [0.0, 0.03, 0.064, 0.064, 0.05], n=16))
        for angle in (np.pi / 4, 3 * np.pi / 4):
            rot = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
            parts.add("stores", box((-13.6, y, Z0 - 0.07), (0.35, 0.36, 0.01), rot))


def _wing_pods(parts: Parts, wing_r: Panel) -> float:
    """The wing pods on their pylons; the right one carries the wingcam just ahead of its
    nose. Returns the pods' nose x."""
    cam = np.array(MOUNTS["wingcam"].position_m)
    pod_nose = cam[0] - 0.05
    pod = np.array([[pod_nose - d, cam[1], cam[2]] for d in (0.0, 0.04, 0.2, 0.5, 2.7, 3.1, 3.2)])
    pod_r = tube(pod, [0.0, 0.07, 0.14, 0.17, 0.17, 0.09, 0.05], n=24)
    wing_f = (Y0 - cam[1] - 1.1) / (5.75 - 1.1)
    wing_bottom = wing_r.le(wing_f)[2] - 0.05
    pylon_r = wing(
        (wing_r.le(wing_f)[0] - 0.1, cam[1], cam[2] + 0.1), 1.5,
        (wing_r.le(wing_f)[0] - 0.1, cam[1], wing_bottom + 0.05), 1.5, thickness=0.07, vertical=True,
    )
    parts.add("pod", pod_r, mirror_y(pod_r, Y0))
    parts.add_mirrored("paint", Y0, pylon_r)
    return pod_nose


def _tail_details(parts: Parts) -> None:
    """The engine nozzles with dark exhausts, the gun port and the dorsal antenna."""
    for side in (-1, 1):
        c = (Y0 + side * 0.48, Z0 - 0.02)
        nozzle = np.array([[X_TAIL + 0.1, *c], [X_TAIL - 0.5, *c], [X_TAIL - 0.8, *c]])
        parts.add("metal", tube(nozzle, [0.42, 0.42, 0.37], n=32))
        parts.add("engine_exhausts", tube(np.array([[X_TAIL - 0.79, *c], [X_TAIL - 0.81, *c]]), 0.33, n=32))
    parts.add("metal", box((X_NOSE - 1.45, Y0, Z0 + 0.45), (0.12, 0.10, 0.10)))
    parts.add("paint", Panel((-8.4, Y0, Z0 + 0.7), 0.5, (-8.6, Y0, Z0 + 0.95), 0.25,
                             thickness=0.08, vertical=True).mesh(16))


def _markings(parts: Parts, fuselage, surfaces: _Surfaces) -> None:
    """National insignia on the wings and fuselage, a squadron band on the tails."""
    for side in (-1, 1):
        w = surfaces.wing if side < 0 else surfaces.wing.mirrored(Y0)
        parts.add("markings", decal(w.mesh(), w.at(0.72, 0.45) + np.array([0, 0, 0.3]), (0.8, 0.8), round_=True))
        parts.add("markings", decal(fuselage, (X_NOSE - 8.0, Y0 + side * 1.3, Z0 + 0.3), (1.2, 0.35)))
        t = surfaces.tail if side < 0 else surfaces.tail.mirrored(Y0)
        parts.add("markings", decal(t.mesh(), t.at(0.7, 0.45) + np.array([0, side * 0.5, 0]), (1.2, 0.3)))


def _anchors(path: np.ndarray, surfaces: _Surfaces, pod_nose: float) -> list[FeatureAnchor]:
    """The receiver's 40 feature anchors: the probe, nose and canopy, then both sides."""
    cam = np.array(MOUNTS["wingcam"].position_m)
    c = CANOPY_CENTRE
    anchors = [
        FeatureAnchor.at("probe_tip", PROBE_TIP),
        FeatureAnchor.at("probe_nozzle", path[5] + np.array([0.0, 0.0, 0.066])),
        FeatureAnchor.at("probe_mid", path[7] + np.array([0.0, 0.0, 0.05])),
        FeatureAnchor.at("probe_base", PROBE_BASE + np.array([0.1, -0.08, 0.0]), "medium"),
        FeatureAnchor.at("radome_tip", (X_NOSE, Y0, Z0 - 0.05)),
        FeatureAnchor.at("radome_seam_right", (X_NOSE - 1.8, Y0 - 0.48, Z0)),
        FeatureAnchor.at("gun_port", (X_NOSE - 1.45, Y0, Z0 + 0.5)),
        # Canopy points where the glass stands clear of the fuselage (its ends are buried).
        FeatureAnchor.at("windscreen_front", c + np.array([1.3, 0.0, 0.37])),
        FeatureAnchor.at("canopy_top", c + np.array([0.0, 0.0, CANOPY_RADII[2]])),
        FeatureAnchor.at("canopy_aft", c + np.array([-1.45, 0.0, 0.33])),
        FeatureAnchor.at("canopy_bow_right", c + np.array([-0.2, -0.5, 0.25])),
        FeatureAnchor.at("canopy_bow_left", c + np.array([-0.2, 0.5, 0.25])),
    ]
    for side, label in ((-1, "right"), (1, "left")):
        y_out = Y0 + side * (INTAKE_Y + INTAKE_W / 2)
        anchors += [
            FeatureAnchor.at(f"intake_{label}_lower", (INTAKE_FRONT, y_out, INTAKE_Z - INTAKE_H / 2)),
            FeatureAnchor.at(f"intake_{label}_upper", (INTAKE_FRONT, y_out, INTAKE_Z + INTAKE_H / 2)),
        ]
    wing_r = surfaces.wing
    anchors += FeatureAnchor.on_both_sides({
        "lex_{side}_edge": surfaces.lex.le(0.55),
        "wing_{side}_le_inboard": wing_r.le(0.2),
        "wing_{side}_tip_le": wing_r.le(1.0),
        "wing_{side}_tip_te": wing_r.te(1.0),
        "wing_{side}_te_inboard": wing_r.te(0.25),
        "missile_{side}_nose": (-11.0, Y0 - MISSILE_Y, Z0 - 0.07),
        "pod_{side}_nose": (pod_nose - 0.04, cam[1], cam[2] + 0.07),
        "tail_{side}_tip_le": surfaces.tail.le(1.0),
        "tail_{side}_tip_te": surfaces.tail.te(1.0),
        "stab_{side}_tip_le": surfaces.stab.le(1.0),
        "nozzle_{side}": (X_TAIL - 0.8, Y0 - 0.48, Z0 + 0.3),
        "insignia_{side}_wing": wing_r.at(0.72, 0.45) + np.array([0, 0, 0.3]),
    }, Y0, sizes={"insignia_{side}_wing": "medium"})
    return anchors
