"""``datagen assets``: build, show and preview the built-in meshes and feature sets."""


from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from datagen.cli.common import MAX_SPP, assets_app, output_path, path_value, user_errors
from datagen.config import load_config
from datagen.core.conventions import RIGID_OBJECTS
from datagen.core.errors import DatagenError
from datagen.core.features import FEATURE_VARIANTS

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
        features = load_features(features_path, name, "baseline")
        variant = cfg.render.variant if cfg else "auto"
        path = write_contact_sheet(folder / f"{name}.png", mesh, features, spp=spp, variant=variant)
        typer.echo(f"wrote {path}")
