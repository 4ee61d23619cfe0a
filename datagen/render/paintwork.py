"""The aircraft's paintwork on the Mitsuba side: the liveries of :mod:`datagen.assets.liveries`
evaluated in the render kernel on the receiver's and the tanker's painted parts (base
colour, roughness and, under a ``normalmap``, the skin's normal), the markings' roundels
and numbers on their decals, and the navigation and anti-collision lights.

Each object's painted parts share one BSDF (and its decals another), so the kernel holds
each object's paint once however many parts wear it. A livery is drawn once per approach
(:meth:`Paintwork.apply` keeps it while the look's livery draws do not change); what
changes per frame (the object's pose, the camera, a light's state) reaches the kernel as
opaque values or parameter updates: no new kernel.

The lights are point sources added to the linear image after the render and the denoiser
(:meth:`Paintwork.light_spots`, drawn by the renderer where a ray from the camera reaches
them): a lens :data:`LIGHT_RADIUS_M` across-radius standing :data:`LIGHT_STANDOFF_M` off the
skin, never a pixel of geometry, so that they change no label, mask or visibility. In
daylight they light nothing around them; what a camera sees of one is its radiance over the
solid angle it subtends, spread over the lens's point spread, then blurred, exposed and
glared with the rest of the image by the camera model. Their radiance follows the frame's
daylight (``aircraft_light_scale`` times the luminance of the sky's and the sun's horizontal
irradiance over pi, the radiance of a white diffuser lit by it; beacons 3 times that); the
beacons flash; they are not dimmed by the air (at most a few hundred metres away, they
would lose a few per cent). Another aircraft in view (:mod:`datagen.scene.traffic`) is an
instance of the same shapes: it wears the same paint, evaluated in its own body frame (the
textures tell its hits by the instance a ray met; a scalar variant paints it in the target's),
and carries no lights.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.liveries import (
    LIGHTS,
    Livery,
    Markings,
    PaintPoint,
    decal_uv,
    exhaust_sites,
    light_sites,
    structure_uv,
)
from datagen.core.conventions import luminance, texture_rng
from datagen.core.transforms import vec3

if TYPE_CHECKING:
    from datagen.config.schema import LiveryConfig
    from datagen.scene.look import FrameLook

__all__ = ["BEACON_GAIN", "BEACON_HZ", "BEACON_ON", "LIGHT_RADIUS_M", "LIGHT_STANDOFF_M", "LIVERY_OBJECTS", "Airframe",
           "Paintwork", "add_light_spots"]

#: The objects that wear a livery (on their painted parts) and carry lights.
LIVERY_OBJECTS: Final = ("receiver", "tanker")
#: Anti-collision beacons flash at this rate (Hz), lit this share of each period.
BEACON_HZ: Final = 1.0
BEACON_ON: Final = 0.2
#: A light's lens: its radius and how far it stands off the skin's outermost point (metres).
LIGHT_RADIUS_M: Final = 0.04
LIGHT_STANDOFF_M: Final = 0.05
#: A beacon's radiance over a steady light's.
BEACON_GAIN: Final = 3.0


@dataclass(frozen=True)
class Airframe:
    """What a livery needs to know of an aircraft's mesh (body frame, metres)."""

    length_m: float
    span_m: float
    centre: tuple[float, float, float]  # the painted skin's bounding-box centre
    nose_x_m: float
    exhausts: tuple[tuple[float, float, float, float], ...]
    lights: dict[str, NDArray[np.float64]]  # light name -> its lens's centre

    @classmethod
    def of(cls, mesh) -> Airframe:
        from datagen.assets.models import material_class

        painted = [np.asarray(p.vertices) for n, p in mesh.parts.items() if material_class(n) == "paint"]
        skin = np.concatenate(painted) if painted else np.concatenate([np.asarray(p.vertices)
                                                                       for p in mesh.parts.values()])
        lo, hi = skin.min(axis=0), skin.max(axis=0)
        centre = (lo + hi) / 2.0
        exhausts: tuple = ()
        for name, part in mesh.parts.items():
            if "exhaust" in name.lower():
                exhausts += exhaust_sites(part.vertices, part.faces)
        outward = {"port": (0, 1.0), "starboard": (1, -1.0), "tail": (0, -1.0), "beacon_top": (2, 1.0),
                   "beacon_bottom": (2, -1.0)}
        lights = {}
        for name, site in light_sites(skin, float(centre[1])).items():
            axis, sign = outward[name]
            lights[name] = site + np.eye(3)[axis] * sign * LIGHT_STANDOFF_M
        return cls(float(hi[0] - lo[0]), float(hi[1] - lo[1]), vec3(centre), float(hi[0]),
                   exhausts, lights)


class Paintwork:
    """The liveries, markings and lights of a config's scene (nothing of them where
    ``randomization.livery`` is off)."""

    def __init__(self, livery: LiveryConfig, pixel_rad: float) -> None:
        lv = livery
        self.enabled = lv.enabled
        self.markings = lv.enabled and lv.markings
        self.lights = lv.enabled and lv.lights
        self.detail = lv.surface_detail
        self.panel_lines = lv.panel_lines
        self.pixel_rad = pixel_rad
        self._airframes: dict[str, Airframe] = {}
        self._textures: dict[str, dict] = {}  # object -> {"albedo", "roughness", "normal", "markings"}
        self._bsdfs: dict[tuple[str, str], object] = {}
        self._key: tuple | None = None
        self._drawn: dict[str, tuple[Livery, Markings]] = {}
        self._phase = 0.0

    # -- construction --------------------------------------------------------------------
    def wears(self, obj: str, material_class: str) -> str | None:
        """What ``obj``'s part of ``material_class`` wears: "livery", "markings" or None."""
        if not self.enabled or obj not in LIVERY_OBJECTS:
            return None
        if material_class == "paint":
            return "livery"
        if material_class == "markings" and self.markings:
            return "markings"
        return None

    def airframe(self, obj: str, mesh) -> Airframe:
        if obj not in self._airframes:
            self._airframes[obj] = Airframe.of(mesh)
        return self._airframes[obj]

    def part(self, obj: str, mesh, wear: str, tm) -> tuple[NDArray, NDArray, NDArray]:
        """Unwelded vertices, faces and texture coordinates of a part wearing ``wear``."""
        if wear == "livery":
            return structure_uv(tm.vertices, tm.faces)
        return decal_uv(tm.vertices, tm.faces, np.asarray(self.airframe(obj, mesh).centre))

    def bsdf(self, obj: str, wear: str, principled: dict):
        """The one BSDF every part of ``obj`` wearing ``wear`` shares."""
        import mitsuba as mi

        from datagen.render.procedural import body_texture_class

        if (obj, wear) in self._bsdfs:
            return self._bsdfs[(obj, wear)]
        texture = body_texture_class(mi.variant())
        textures = self._textures.setdefault(obj, {})
        if wear == "markings":
            textures["markings"] = texture(pixel_rad=self.pixel_rad, colour=True)
            textures["markings"].shade = _grey
            description: dict = dict(principled, base_color=textures["markings"])
        else:
            textures["albedo"] = texture(pixel_rad=self.pixel_rad, colour=True)
            textures["roughness"] = texture(pixel_rad=self.pixel_rad)
            textures["albedo"].shade, textures["roughness"].shade = _grey, _half
            description = dict(principled, base_color=textures["albedo"], roughness=textures["roughness"])
            if self.detail:
                textures["normal"] = texture(pixel_rad=self.pixel_rad, colour=True)
                textures["normal"].shade = _flat
                description = {"type": "normalmap", "normalmap": textures["normal"], "bsdf": description}
        self._bsdfs[(obj, wear)] = mi.load_dict(description)
        return self._bsdfs[(obj, wear)]

    def material_prefix(self, bsdf_key: str, wear: str) -> str:
        """Where a shared BSDF's principled parameters are, given its first part's BSDF key."""
        return f"{bsdf_key}.nested_bsdf" if wear == "livery" and self.detail else bsdf_key

    # -- per frame -----------------------------------------------------------------------
    def drawn(self, look: FrameLook) -> dict[str, tuple[Livery, Markings]]:
        """Each object's livery and markings this approach (empty when liveries are off)."""
        if not self.enabled or look.livery_seed is None:
            return {}
        key = (look.livery_seed, look.receiver_livery, look.tanker_livery, look.livery_weathering)
        if key != self._key:
            rng = texture_rng(look.livery_seed)
            self._drawn = {}
            for obj in LIVERY_OBJECTS:
                frame = self._airframes.get(obj)
                scheme = getattr(look, f"{obj}_livery")
                if frame is None:
                    continue
                livery = Livery.drawn(rng, scheme, float(look.livery_weathering or 0.0), length_m=frame.length_m,
                                      span_m=frame.span_m, centre_y_m=frame.centre[1], nose_x_m=frame.nose_x_m,
                                      exhausts=frame.exhausts, panel_lines=self.panel_lines)
                self._drawn[obj] = (livery, Markings.drawn(rng, scheme in ("grey_camouflage", "two_tone")))
            self._phase = float(rng.uniform())
            self._key = key
        return self._drawn

    def bind_twins(self, registry_ids: dict[str, int]) -> None:
        """Name each object's twin, another instance of its shapes (:mod:`datagen.scene.traffic`),
        by its Mitsuba registry id: the textures paint its hits in its own body frame."""
        for obj, textures in self._textures.items():
            for texture in textures.values():
                texture.twin = registry_ids.get(obj)

    def textures(self) -> tuple:
        """Every procedural texture of the paintwork (each object's albedo, roughness, normal, markings)."""
        return tuple(t for textures in self._textures.values() for t in textures.values())

    def apply(self, look: FrameLook, render_from_body: dict[str, NDArray], camera_render,
              render_from_twin: dict[str, NDArray] | None = None) -> None:
        """Pose the frame's paint (``render_from_body``: each object's 4x4, and its twin's in
        ``render_from_twin`` where it has one; the camera at ``camera_render``)."""
        drawn = self.drawn(look)
        for obj, (livery, markings) in drawn.items():
            textures = self._textures.get(obj, {})
            body_from_render = np.linalg.inv(render_from_body[obj])
            twin = (render_from_twin or {}).get(obj)
            twin_from_render = None if twin is None else np.linalg.inv(twin)
            for texture in textures.values():
                texture.body_from_render = body_from_render
                if twin_from_render is not None:
                    texture.twin_body_from_render = twin_from_render
                texture.camera = tuple(float(c) for c in camera_render)
            base = look.materials[obj]["metal" if livery.scheme == "bare_metal" else "paint"].roughness
            if "albedo" in textures:
                textures["albedo"].shade = livery.albedo
                textures["roughness"].set_value("base", base)
                textures["roughness"].shade = functools.partial(_roughness, livery, textures["roughness"].frame_values)
            if "normal" in textures:
                textures["normal"].shade = functools.partial(_normal, livery)
            if "markings" in textures:
                half = 0.25  # the decals' typical half-size (metres): a footprint in their units
                textures["markings"].shade = functools.partial(_markings, markings, livery, half)

    def light_spots(self, look: FrameLook, world_from_body: dict[str, NDArray], time_s: float,
                    irradiance) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """The frame's lit lights: ``(position in the world (3,), radiance RGB (3,))`` each
        (none where lights are off, or this approach flies without them)."""
        if not self.lights or not look.aircraft_lights or irradiance is None:
            return []
        daylight = float(luminance(np.asarray(irradiance[0]) + np.asarray(irradiance[1]))) / np.pi
        scale = float(look.aircraft_light_scale or 0.0) * daylight
        flash = (time_s * BEACON_HZ + self._phase) % 1.0 < BEACON_ON
        spots = []
        for obj, frame in self._airframes.items():
            for name, colour, flashing in LIGHTS:
                if flashing and not flash:
                    continue
                site = world_from_body[obj] @ np.append(frame.lights[name], 1.0)
                spots.append((site[:3], np.asarray(colour) * scale * (BEACON_GAIN if flashing else 1.0)))
        return spots


def add_light_spots(rgb: NDArray[np.float32], pixels: NDArray[np.float64], distance_m: NDArray[np.float64],
                    radiance: NDArray[np.float64], fx: float) -> None:
    """Add point lights to a linear image in place: each at continuous pixel ``pixels[i]``,
    ``distance_m[i]`` away, a lens :data:`LIGHT_RADIUS_M` in radius of ``radiance[i]``: its
    radiance times the solid angle it subtends over a pixel's (``pi r^2 fx^2 / d^2`` pixels'
    worth), spread by a Gaussian as wide as the lens's image or half a pixel, whichever is wider."""
    h, w = rgb.shape[:2]
    for (u, v), d, radiance_i in zip(pixels, distance_m, radiance, strict=True):
        r_px = LIGHT_RADIUS_M * fx / d
        sigma = max(0.5, r_px)
        reach = int(np.ceil(3.0 * sigma))
        x0, y0 = int(np.floor(u)) - reach, int(np.floor(v)) - reach
        xs, ys = np.arange(x0, x0 + 2 * reach + 2), np.arange(y0, y0 + 2 * reach + 2)
        keep_x, keep_y = (xs >= 0) & (xs < w), (ys >= 0) & (ys < h)
        if not keep_x.any() or not keep_y.any():
            continue
        gx = np.exp(-0.5 * ((xs + 0.5 - u) / sigma) ** 2)
        gy = np.exp(-0.5 * ((ys + 0.5 - v) / sigma) ** 2)
        weights = np.outer(gy, gx)
        weights /= weights.sum()
        power = np.pi * r_px * r_px  # pixels' worth of the lens's radiance
        patch = weights[np.ix_(keep_y, keep_x)][..., None] * (power * np.asarray(radiance_i))[None, None, :]
        rgb[ys[keep_y][0]:ys[keep_y][-1] + 1, xs[keep_x][0]:xs[keep_x][-1] + 1] += patch.astype(np.float32)


def _grey(p: PaintPoint, ops):
    return tuple(p.x * ops.f32(0.0) + ops.f32(0.5) for _ in range(3))


def _half(p: PaintPoint, ops):
    return p.x * ops.f32(0.0) + ops.f32(0.5)


def _flat(p: PaintPoint, ops):
    zero = p.x * ops.f32(0.0)
    return zero + ops.f32(0.5), zero + ops.f32(0.5), zero + ops.f32(1.0)


def _roughness(livery: Livery, values: dict, p: PaintPoint, ops):
    """The livery's roughness over the frame's drawn roughness of its paint (``values["base"]``)."""
    return livery.roughness(values["base"], p, ops)


def _normal(livery: Livery, p: PaintPoint, ops):
    """The livery's normal encoded as a normal map's colour (n / 2 + 1/2)."""
    half = ops.f32(0.5)
    return tuple(c * half + half for c in livery.normal(p, ops))


def _markings(markings: Markings, livery: Livery, half_m: float, p: PaintPoint, ops):
    return markings.colour(p.s, p.t, p.footprint * ops.f32(1.0 / half_m), livery.paint(p, ops), ops)
