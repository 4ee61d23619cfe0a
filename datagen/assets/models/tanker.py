"""Tanker: a KC-46 / KC-135-class twin-engine tanker with a centreline drogue unit.

About 50 m long and 48 m in span. Tanker body frame: x forward, y left, z up,
origin at the *average* drogue centre, so the aircraft sits ahead of and above
the origin. The centreline drogue unit's fairing hangs under the aft fuselage
with its hose exit port at :data:`datagen.assets.rig.HOSE_PORT_TANKER_M`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datagen.assets.models import FeatureAnchor, Model
from datagen.assets.models.loft import (
    Panel,
    Parts,
    decal,
    ellipsoid,
    loft,
    superellipse_ring,
    tube,
)
from datagen.assets.rig import HOSE_PORT_TANKER_M

__all__ = ["build_tanker"]

X_NOSE = 65.5

# (distance aft of the nose, half width, half height, centre height z)
_STATIONS = (
    (0.0, 0.0, 0.0, 8.0),
    (0.6, 0.75, 0.70, 8.10),
    (1.6, 1.25, 1.25, 8.25),
    (3.0, 1.65, 1.70, 8.40),
    (5.0, 1.88, 1.92, 8.50),
    (34.0, 1.88, 1.92, 8.50),
    (38.0, 1.78, 1.75, 8.70),
    (42.0, 1.45, 1.30, 9.10),
    (46.0, 0.95, 0.80, 9.60),
    (48.8, 0.40, 0.35, 9.95),
    (49.6, 0.25, 0.22, 10.00),
)
_RADOME_END = 2


def _rings(stations, n: int = 64) -> list[np.ndarray]:
    return [superellipse_ring(X_NOSE - s, 0.0, zc, hw, hh, n) for s, hw, hh, zc in stations]


def _along_x(x, y, z) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return np.column_stack([x, np.broadcast_to(y, x.shape), np.broadcast_to(z, x.shape)])


#: The engines' y off the centreline and their axis height.
ENGINE_Y, ENGINE_Z = 7.8, 5.9
#: The wing refueling pods' x stations, nose to tail.
WARP_X = (36.2, 36.0, 35.4, 32.6, 31.8, 31.6)
#: Where the flap-track fairings sit along the wing's span.
FLAP_TRACKS = (0.2, 0.45, 0.85)
#: The x of the fuselage's tail.
X_TAIL = X_NOSE - _STATIONS[-1][0]
PORT = np.asarray(HOSE_PORT_TANKER_M, dtype=np.float64)


@dataclass(frozen=True)
class _Surfaces:
    """The right wing and stabilizer (the left ones are their mirror images) and the fin."""

    wing: Panel
    stab: Panel
    fin: Panel


def build_tanker() -> Model:
    """The tanker's meshes, part by part, and its feature anchors."""
    parts = Parts()
    parts.add("radome", loft(_rings(_STATIONS[: _RADOME_END + 1])))
    parts.add("paint", loft(_rings(_STATIONS[_RADOME_END:])))
    fuselage = parts.build()["paint"]
    parts.add("paint", ellipsoid((40.0, 0.0, 7.1), (7.5, 1.95, 0.9)))  # wing-body fairing
    surfaces = _flying_surfaces(parts)
    pylon = _engines(parts, surfaces.wing)
    pod_z = _wing_pods(parts, surfaces.wing)
    _drogue_unit(parts)
    belly = _belly_details(parts, fuselage)
    insignia = _markings(parts, fuselage, surfaces)
    return Model("tanker", parts.build(), tuple(_anchors(surfaces, pylon, pod_z, belly, insignia)),
                 small_radius_m=0.25)


def _flying_surfaces(parts: Parts) -> _Surfaces:
    """The wings, stabilizers and fin."""
    surfaces = _Surfaces(
        wing=Panel((44.0, -1.6, 7.0), 8.5, (30.5, -24.0, 9.3), 2.0, thickness=(0.13, 0.10)),
        stab=Panel((24.0, -1.0, 9.4), 5.5, (17.6, -9.3, 10.1), 1.9, thickness=0.10),
        fin=Panel((26.5, 0.0, 10.0), 7.5, (19.5, 0.0, 16.6), 2.9, thickness=0.11, vertical=True),
    )
    parts.add_mirrored("paint", 0.0, surfaces.wing.mesh(48), surfaces.stab.mesh())
    parts.add("paint", surfaces.fin.mesh())
    return surfaces


def _engines(parts: Parts, wing_r: Panel) -> Panel:
    """The engines under the wings: nacelle, dark inlet face with spinner, exhaust plug.
    Returns the right pylon."""
    wing_le = wing_r.le((ENGINE_Y - 1.6) / 22.4)
    nacelle = tube(_along_x([47.6, 47.45, 46.8, 44.0, 42.2, 41.8], -ENGINE_Y, ENGINE_Z),
                   [1.25, 1.38, 1.45, 1.42, 1.15, 1.05], n=48)
    pylon = Panel((45.0, -ENGINE_Y, ENGINE_Z + 1.2), 4.5, (wing_le[0] + 0.4, -ENGINE_Y, wing_le[2] - 0.1),
                  3.8, thickness=0.1, vertical=True)
    parts.add_mirrored("paint", 0.0, nacelle, pylon.mesh())
    parts.add_mirrored("engine_inlets", 0.0, tube(_along_x([47.61, 47.63], -ENGINE_Y, ENGINE_Z), 1.15, n=48))
    parts.add_mirrored("metal", 0.0,
                       tube(_along_x([48.3, 48.0, 47.62], -ENGINE_Y, ENGINE_Z), [0.0, 0.3, 0.42], n=24),
                       tube(_along_x([41.82, 41.0, 40.4], -ENGINE_Y, ENGINE_Z), [0.62, 0.45, 0.0], n=24))
    parts.add_mirrored("engine_exhausts", 0.0, tube(_along_x([41.81, 41.79], -ENGINE_Y, ENGINE_Z), 1.0, n=48))
    return pylon


def _wing_pods(parts: Parts, wing_r: Panel) -> float:
    """The wing refueling pods (not used for the hose here) and the flap-track fairings.
    Returns the pods' axis height."""
    f_pod = (17.0 - 1.6) / 22.4
    pod_z = wing_r.le(f_pod)[2] - 0.85
    warp = tube(_along_x(list(WARP_X), -17.0, pod_z), [0.0, 0.18, 0.4, 0.4, 0.22, 0.12], n=24)
    warp_pylon = Panel((35.0, -17.0, pod_z + 0.3), 2.6, (wing_r.le(f_pod)[0] - 0.2, -17.0, pod_z + 0.8),
                       2.6, thickness=0.08, vertical=True)
    parts.add_mirrored("pod", 0.0, warp)
    parts.add_mirrored("paint", 0.0, warp_pylon.mesh())
    for f in FLAP_TRACKS:
        te, z = wing_r.te(f), wing_r.le(f)[2] - 0.1
        fairing = tube(_along_x([te[0] + 1.6, te[0] + 1.2, te[0] - 0.3, te[0] - 1.3], te[1], z),
                       [0.0, 0.22, 0.25, 0.0], n=16)
        parts.add_mirrored("paint", 0.0, fairing)
    return pod_z


def _drogue_unit(parts: Parts) -> None:
    """The centreline drogue unit's fairing with the hose exit port on its aft face."""
    cdu_x = np.array([30.5, 29.0, 26.0, 23.0, PORT[0]])
    cdu_path = np.column_stack([cdu_x, np.zeros(5), [7.7, 7.3, 6.95, 6.7, 6.55]])
    parts.add("paint", tube(cdu_path, [0.2, 0.6, 0.8, 0.8, 0.75], n=32))
    parts.add("metal", tube(_along_x([PORT[0] + 0.05, PORT[0] - 0.05], 0.0, PORT[2]), 0.11, n=24))
    parts.add("engine_exhausts", tube(_along_x([PORT[0] - 0.051, PORT[0] - 0.055], 0.0, PORT[2]), 0.075, n=24))


def _belly_details(parts: Parts, fuselage) -> dict[float, np.ndarray]:
    """The tail cone's APU exhaust, the belly antennas and the pilot director lights.
    Returns the belly points under the antennas, by x."""
    parts.add("metal", tube(_along_x([X_TAIL + 0.05, X_TAIL - 0.25], 0.0, 10.0), 0.17, n=24))
    belly = {x: superellipse_ring(x, 0.0, 8.5, 1.88, 1.92, 1, angles=[-np.pi / 2])[0] for x in (48.0, 34.0)}
    for x, p in belly.items():
        parts.add("paint", Panel((x, 0.0, p[2] + 0.05), 0.8, (x - 0.4, 0.0, p[2] - 0.4), 0.35,
                                 thickness=0.08, vertical=True).mesh(16))
    parts.add("metal", decal(fuselage, (54.0, 0.0, 6.0), (3.0, 0.6)))
    return belly


def _markings(parts: Parts, fuselage, surfaces: _Surfaces) -> np.ndarray:
    """Cockpit windows, fuselage bands, the fin flash and the underwing insignia. Returns the
    right insignia's centre."""
    for y, z, x in ((0.42, 9.55, X_NOSE - 2.4), (1.2, 9.35, X_NOSE - 2.8)):
        for side in (-1, 1):
            parts.add("glass", decal(fuselage, (x, side * y, z + 0.3), (0.75, 0.5), along=(0.0, 1.0, 0.0)))
    for side in (-1, 1):
        parts.add("markings", decal(fuselage, (50.0, side * 2.2, 8.7), (5.0, 0.55)))
        parts.add("markings", decal(surfaces.fin.mesh(), (21.8, side * 0.5, 14.0), (2.2, 0.9)))
    insignia = surfaces.wing.at(0.62, 0.5) - np.array([0.0, 0.0, 0.6])
    parts.add_mirrored("markings", 0.0, decal(surfaces.wing.mesh(48), insignia, (1.8, 1.8), round_=True))
    return insignia


def _anchors(surfaces: _Surfaces, pylon: Panel, pod_z: float, belly: dict[float, np.ndarray],
             insignia: np.ndarray) -> list[FeatureAnchor]:
    """The tanker's 40 feature anchors: the centreline, then both sides."""
    fin, stab_r, wing_r = surfaces.fin, surfaces.stab, surfaces.wing
    anchors = [
        FeatureAnchor.at("hose_port", PORT + np.array([-0.06, 0.0, -0.11]), "medium"),
        FeatureAnchor.at("drogue_unit_belly", (26.0, 0.0, 6.0), "medium"),
        FeatureAnchor.at("tail_cone", (X_TAIL - 0.25, 0.0, 10.0)),
        FeatureAnchor.at("fin_tip_le", fin.le(1.0)),
        FeatureAnchor.at("fin_tip_te", fin.te(1.0)),
        FeatureAnchor.at("fin_root_te", fin.te(0.08)),
        FeatureAnchor.at("belly_antenna_aft", belly[34.0] - np.array([0.4, 0.0, 0.4])),
        FeatureAnchor.at("belly_antenna_fwd", belly[48.0] - np.array([0.4, 0.0, 0.4])),
        FeatureAnchor.at("director_lights", (54.0, 0.0, 6.0), "medium"),
        FeatureAnchor.at("radome_tip", (X_NOSE, 0.0, 8.0)),
    ]
    anchors += FeatureAnchor.on_both_sides({
        "stab_{side}_tip_le": stab_r.le(1.0),
        "stab_{side}_tip_te": stab_r.te(1.0),
        "stab_{side}_root_te": stab_r.te(0.12),
        "wing_{side}_tip_le": wing_r.le(1.0),
        "wing_{side}_tip_te": wing_r.te(1.0),
        "wing_{side}_root_te": wing_r.te(0.08),
        "wing_{side}_mid_te": wing_r.te(0.6),
        "engine_{side}_exhaust_plug": (40.4, -ENGINE_Y, ENGINE_Z),
        "engine_{side}_inlet_lip": (47.6, -ENGINE_Y, ENGINE_Z - 1.25),
        "pylon_{side}_aft": pylon.te(0.0),
        "flap_track_{side}_inboard": (wing_r.te(0.2)[0] - 1.3, wing_r.te(0.2)[1], wing_r.le(0.2)[2] - 0.1),
        "flap_track_{side}_outboard": (wing_r.te(0.85)[0] - 1.3, wing_r.te(0.85)[1], wing_r.le(0.85)[2] - 0.1),
        "wing_pod_{side}_nose": (WARP_X[0], -17.0, pod_z),
        "wing_pod_{side}_tail": (WARP_X[-1], -17.0, pod_z),
        "insignia_{side}_wing": insignia,
    }, sizes={"engine_{side}_exhaust_plug": "medium", "wing_pod_{side}_tail": "medium",
              "insignia_{side}_wing": "medium"})
    return anchors
