"""``datagen assets``: build, show and preview the built-in meshes and feature sets, and
write a feature file for a user's own mesh."""


from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, cast

import typer

from datagen.cli.common import MAX_SPP, assets_app, output_path, path_value, user_errors
from datagen.config import load_config
from datagen.core.conventions import RIGID_OBJECTS
from datagen.core.errors import DatagenError
from datagen.core.features import FEATURE_VARIANTS, SIZE_SCALE

if TYPE_CHECKING:
    from datagen.assets.models import Size

#: Where ``datagen assets preview`` writes without ``--out``: a working folder in the current
#: one (never the repository's tracked ``assets/previews``).
PREVIEWS_FOLDER = "previews"


@assets_app.command("build")
@user_errors
def assets_build(
    out: Annotated[Path | None, typer.Option("--out", parser=path_value,
                                             help="Assets folder (default: the built-in one).")] = None,
) -> None:
    """Regenerate every built-in mesh and feature file, byte for byte."""
    from datagen.assets.generate import write_assets
    from datagen.assets.loader import BUILTIN_DIR

    for path, size in write_assets(output_path(out, "--out") if out else BUILTIN_DIR).items():
        typer.echo(f"wrote {path} ({size:,} bytes)")


def _object_name(name: str) -> str:
    if name not in RIGID_OBJECTS:
        raise DatagenError(f"unknown object {name!r} (choose from {', '.join(RIGID_OBJECTS)})")
    return name


#: The forms of ``datagen assets features``' feature flags.
POINT_FORM = "NAME=X,Y,Z[,SIZE]"
RING_FORM = "NAME=X,Y,Z,RADIUS,AXIS,COUNT[,SIZE]"
#: Smallest ring radius, metres: feature files hold micrometres.
MIN_RADIUS_M = 1e-3


def _split(flag: str, text: str, form: str, counts: tuple[int, int]) -> tuple[str, list[str]]:
    """``NAME=a,b,...`` as the name and its values, their count in ``counts``."""
    from datagen.core.features import MAX_NAME_CHARS, valid_name

    name, equals, rest = text.partition("=")
    name = name.strip()
    if not equals:
        raise DatagenError(f"{flag} {text!r}: expected {form}")
    if not valid_name(name):
        raise DatagenError(f"{flag} {text!r}: the name before '=' must be 1 to {MAX_NAME_CHARS} printable "
                           "characters")
    values = [v.strip() for v in rest.split(",")]
    if not counts[0] <= len(values) <= counts[1]:
        raise DatagenError(f"{flag} {text!r}: expected {form}, got {len(values)} value{'s' * (len(values) != 1)} "
                           "after '='")
    return name, values


def _number(flag: str, text: str, value: str) -> float:
    try:
        number = float(value)
    except ValueError:
        raise DatagenError(f"{flag} {text!r}: {value!r} is not a number") from None
    if not math.isfinite(number):
        raise DatagenError(f"{flag} {text!r}: {value!r} is not a finite number")
    return number


def _size(flag: str, text: str, values: list[str], at: int) -> Size:
    size = values[at] if len(values) > at else "medium"
    if size not in SIZE_SCALE:
        raise DatagenError(f"{flag} {text!r}: unknown size {size!r} (choose {', '.join(SIZE_SCALE)})")
    return cast("Size", size)


def _point(text: str):
    """A ``--point`` value as a feature anchor."""
    from datagen.assets.models import FeatureAnchor

    name, values = _split("--point", text, POINT_FORM, (3, 4))
    xyz = [_number("--point", text, v) for v in values[:3]]
    return FeatureAnchor.at(name, xyz, _size("--point", text, values, 3))


def _ring(text: str):
    """A ``--ring`` value as an internal ring feature."""
    from datagen.assets.generate import AXES, ring_feature
    from datagen.assets.loader import MAX_FEATURE_POINTS

    name, values = _split("--ring", text, RING_FORM, (6, 7))
    xyz = [_number("--ring", text, v) for v in values[:3]]
    radius = _number("--ring", text, values[3])
    if radius < MIN_RADIUS_M:
        raise DatagenError(f"--ring {text!r}: RADIUS must be at least {MIN_RADIUS_M:g} m, got {values[3]}")
    axis = values[4].lower()
    if axis not in AXES:
        raise DatagenError(f"--ring {text!r}: AXIS must be x, y or z (the body axis the ring's plane is normal to), "
                           f"got {values[4]!r}")
    if not values[5].isdigit() or not 3 <= int(values[5]) <= MAX_FEATURE_POINTS:
        raise DatagenError(f"--ring {text!r}: COUNT must be a whole number of points from 3 to {MAX_FEATURE_POINTS}, "
                           f"got {values[5]!r}")
    return ring_feature(name, xyz, radius, axis, int(values[5]), _size("--ring", text, values, 6))


@assets_app.command("features")
@user_errors
def assets_features(
    name: Annotated[str, typer.Argument(help=f"The object the file is for: {', '.join(RIGID_OBJECTS)}.",
                                        show_default=False)],
    out: Annotated[Path, typer.Option("--out", parser=path_value, help="Feature file to write (JSON); written "
                                      "whole or not at all.", show_default=False)],
    points: Annotated[list[str] | None, typer.Option(
        "--point", metavar=POINT_FORM, show_default=False,
        help="A feature at a point of the surface (repeatable): X,Y,Z in the body frame (metres), snapped to the "
        "--mesh surface, with a ring of 8 surface points around it of --small-radius times 1, 2 or 4 for SIZE "
        "small, medium (the default) or large.")] = None,
    rings: Annotated[list[str] | None, typer.Option(
        "--ring", metavar=RING_FORM, show_default=False,
        help="A ring feature (repeatable): COUNT points RADIUS metres around the centre X,Y,Z in the plane normal "
        "to AXIS (x, y or z), kept where given; its centre is not on the surface (an inlet's lip, a basket's "
        "rim). SIZE: small, medium (the default) or large.")] = None,
    mesh: Annotated[Path | None, typer.Option("--mesh", parser=path_value, help="The object's mesh (OBJ, PLY or "
                                              "GLB; body frame, metres): --point needs it.")] = None,
    small_radius: Annotated[float | None, typer.Option("--small-radius", help="Ring radius of a small --point "
                                                       "feature, metres (default: the built-in object's).",
                                                       show_default=False)] = None,
) -> None:
    """Write a feature file for a mesh from named surface points and rings.

    Class ids: the --point features in the order given, then the --ring features.

    Variants: baseline (each feature its own size); small, medium, large (every --point that size, same centres)."""
    from datagen.assets.loader import BUILTIN_DIR, MAX_FEATURES, builtin_paths, degenerate, load_mesh, read_feature_file

    name = _object_name(name)
    anchors = [_point(text) for text in points or []]
    internal = [_ring(text) for text in rings or []]
    flags: dict[str, str] = {}  # feature name -> the flag that gave it, as typed
    for flag, features, texts in (("--point", anchors, points or []), ("--ring", internal, rings or [])):
        for feature, text in zip(features, texts, strict=True):
            if feature.name in flags:
                raise DatagenError(f"{flag} {text!r}: the name {feature.name!r} is taken by {flags[feature.name]}")
            flags[feature.name] = f"{flag} {text!r}"
    if not flags:
        raise DatagenError(f"name at least one feature: --point {POINT_FORM} or --ring {RING_FORM}")
    if len(flags) > MAX_FEATURES:
        raise DatagenError(f"{len(flags)} features; a feature file may have at most {MAX_FEATURES}")
    if anchors and mesh is None:
        raise DatagenError("--point needs --mesh: a point's feature is made on the mesh's surface")
    if small_radius is not None and not (math.isfinite(small_radius) and small_radius >= MIN_RADIUS_M):
        raise DatagenError(f"--small-radius: {small_radius:g}: expected a length of at least {MIN_RADIUS_M:g} m")
    output_path(out, "--out")
    if Path(out).is_dir():
        raise DatagenError(f"--out: {out} is a folder; name the feature file to write")
    if Path(out).resolve().is_relative_to(BUILTIN_DIR.resolve()):
        raise DatagenError(f"--out: {out} is among the built-in assets (datagen assets build makes those); "
                           "write yours beside your mesh")
    if small_radius is None:
        path = builtin_paths(name)[1]
        shipped = read_feature_file(path)
        if not isinstance(shipped, dict) or not isinstance(shipped.get("small_radius_m"), (int, float)):
            raise DatagenError(f"{path}: small_radius_m: missing; datagen assets build writes it")
        small_radius = float(shipped["small_radius_m"])

    from datagen.assets.generate import features_text, named_model, stored_features, write_features
    from datagen.assets.table import describe_features

    loaded = load_mesh(mesh, name) if mesh is not None else None
    for line in loaded.warnings if loaded is not None else ():
        typer.echo(line, err=True)
    variants = stored_features(named_model(name, anchors, internal, small_radius, loaded))
    for variant, features in variants.items():
        for feature in features:
            why = degenerate(feature.points_m)
            if why and feature.internal:
                raise DatagenError(f"{flags[feature.name]}: its points are degenerate ({why}); give a larger RADIUS")
            if why:
                ring = f"{feature.size} ring ({small_radius * SIZE_SCALE[feature.size]:g} m"
                ring += ")" if variant == "baseline" else f", the {variant} variant's)"
                smaller = "give it a smaller size or " if variant == "baseline" else ""
                raise DatagenError(f"{flags[feature.name]}: its {ring} on the mesh surface is degenerate ({why}); "
                                   f"move the point, or {smaller}give a smaller --small-radius")
    for anchor, feature in zip(anchors, variants["baseline"], strict=False):
        gap = float(math.dist(anchor.anchor_m, feature.center_m))
        if gap > small_radius * SIZE_SCALE[feature.size]:
            centre = ", ".join(f"{v:.3f}" for v in feature.center_m)
            typer.echo(f"warning: {flags[feature.name]}: {gap:.3g} m from the mesh surface; its feature is at the "
                       f"nearest surface point ({centre}): is the point in the body frame, in metres?", err=True)
    path = write_features(out, features_text(name, small_radius, variants), name)
    counts = ", ".join(f"{n} {kind}{'s' * (n != 1)}" for n, kind in ((len(anchors), "point"), (len(internal), "ring")))
    typer.echo(f"wrote {path}: {len(flags)} feature{'s' * (len(flags) != 1)} of {name} ({counts}), "
               f"small radius {small_radius:g} m, variants {', '.join(variants)}")
    typer.echo(describe_features(variants["baseline"]))


@assets_app.command("show")
@user_errors
def assets_show(
    name: Annotated[str, typer.Argument(help=f"Object: {', '.join(RIGID_OBJECTS)}.", show_default=False)],
    variant: Annotated[str, typer.Option("--variant", help=f"{', '.join(FEATURE_VARIANTS[:-1])} or "
                                         f"{FEATURE_VARIANTS[-1]}.")] = "baseline",
    config: Annotated[Path | None, typer.Option("--config", parser=path_value,
                                                help="Use this config's mesh and feature files "
                                                "and its seed (default: the built-in assets).")] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Seed of random features without --config.")] = 0,
    count: Annotated[int, typer.Option("--count", min=3, max=1000, help="Random features without --config "
                                       "(as features.random_per_object).")] = 40,
) -> None:
    """Print the feature table of an object."""
    from datagen.assets.loader import builtin_paths
    from datagen.assets.table import describe_features, load_object_features, object_paths

    name = _object_name(name)
    if variant not in FEATURE_VARIANTS:
        raise DatagenError(f"--variant: unknown variant {variant!r} (choose from {', '.join(FEATURE_VARIANTS)})")
    mesh_path, features_path = builtin_paths(name)
    if config is not None:
        cfg = load_config(config)
        mesh_path, features_path = object_paths(cfg, name)
        seed, count = cfg.dataset.seed, cfg.features.random_per_object
    features = load_object_features(name, variant, mesh_path=mesh_path, features_path=features_path,
                                    seed=seed, random_count=count)
    source = f"{mesh_path}, seed {seed}" if variant == "random" else features_path
    typer.echo(f"{name}: {len(features)} features, variant {variant}, from {source}")
    typer.echo(describe_features(features))


@assets_app.command("preview")
@user_errors
def assets_preview(
    out: Annotated[Path | None, typer.Option("--out", parser=path_value,
                                             help="Folder for the PNGs (default: previews/ in the current "
                                             "folder; the documentation's are in assets/previews).")] = None,
    objects: Annotated[list[str] | None, typer.Option("--object", help="Only this object (repeatable).")] = None,
    spp: Annotated[int, typer.Option("--spp", min=1, max=MAX_SPP, help="Samples per pixel.")] = 64,
    config: Annotated[Path | None, typer.Option("--config", parser=path_value,
                                                help="Use this config's mesh and feature files.")] = None,
) -> None:
    """Render a contact sheet of each object from six views, feature centres marked."""
    from datagen.assets.loader import builtin_paths, load_features, load_mesh
    from datagen.assets.table import object_paths
    from datagen.report.contact_sheets import write_contact_sheet

    cfg = load_config(config) if config is not None else None
    folder = output_path(out, "--out") if out else Path(PREVIEWS_FOLDER)
    for name in objects or RIGID_OBJECTS:
        name = _object_name(name)
        mesh_path, features_path = object_paths(cfg, name) if cfg else builtin_paths(name)
        mesh = load_mesh(mesh_path, name)
        for line in mesh.warnings:
            typer.echo(line, err=True)
        features = load_features(features_path, name, "baseline")
        variant = cfg.render.variant if cfg else "auto"
        path = write_contact_sheet(folder / f"{name}.png", mesh, features, spp=spp, variant=variant)
        typer.echo(f"wrote {path}")
