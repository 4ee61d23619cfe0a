"""Make receiver.glb: a small jet built from trimesh primitives, as a receiver.

The receiver's body frame (datagen's conventions): x forward, y left, z up, metres,
origin at the refueling probe's tip. Each part is a named mesh of the GLB, and its
name gives its material: ``canopy_glass`` is glass, ``probe`` metal,
``engine_inlets`` and ``engine_exhausts`` dark; the rest, ``paint``, wears the livery.

Run from the repository root: ``.venv/bin/python examples/own-aircraft/make_mesh.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent
#: The fuselage's axis: left of the probe and below it.
AXIS_Y, AXIS_Z = 0.5, -0.3


def along_x(mesh: trimesh.Trimesh, x0: float, y: float, z: float) -> trimesh.Trimesh:
    """A mesh made along +z (trimesh's cylinders and cones, base at z = 0 or centred) turned
    to run along +x, then moved to start at (x0, y, z)."""
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0.0, 1.0, 0.0]))
    mesh.apply_translation([x0 - mesh.bounds[0, 0], y, z])
    return mesh


def cylinder_x(x0: float, x1: float, radius: float, y: float, z: float, sections: int = 24) -> trimesh.Trimesh:
    return along_x(trimesh.creation.cylinder(radius=radius, height=x1 - x0, sections=sections), x0, y, z)


def box(center, extents) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(center))


def parts() -> dict[str, list[trimesh.Trimesh]]:
    nose = along_x(trimesh.creation.cone(radius=0.7, height=1.5, sections=24), -2.5, AXIS_Y, AXIS_Z)
    canopy = trimesh.creation.icosphere(subdivisions=2)
    canopy.apply_scale([1.4, 0.45, 0.45])
    canopy.apply_translation([-4.0, AXIS_Y, 0.3])
    return {
        "paint": [
            cylinder_x(-10.0, -2.5, 0.7, AXIS_Y, AXIS_Z),  # fuselage
            nose,
            box([-6.5, AXIS_Y, -0.4], [2.4, 9.0, 0.16]),  # wings: tips at y = 5.0 and -4.0
            box([-9.6, AXIS_Y, -0.2], [1.2, 3.6, 0.12]),  # tailplane: tips at y = 2.3 and -1.3
            box([-9.5, AXIS_Y, 0.9], [1.4, 0.12, 1.6]),  # fin: top at z = 1.7
        ],
        "canopy_glass": [canopy],
        "probe": [cylinder_x(-3.5, 0.0, 0.05, 0.0, 0.0, sections=12)],  # its tip is the origin
        "engine_inlets": [cylinder_x(-5.6, -4.4, 0.3, y, -0.55) for y in (AXIS_Y + 0.95, AXIS_Y - 0.95)],
        "engine_exhausts": [cylinder_x(-10.4, -10.0, 0.45, AXIS_Y, AXIS_Z)],
    }


def main() -> None:
    scene = trimesh.Scene()
    for name, meshes in parts().items():
        scene.add_geometry(trimesh.util.concatenate(meshes), geom_name=name, node_name=name)
    path = HERE / "receiver.glb"
    path.write_bytes(scene.export(file_type="glb"))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
