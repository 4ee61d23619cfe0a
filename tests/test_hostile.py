"""Hostile input, by class: every bad config, asset, flag and dataset folder ends in one
line on stderr and exit status 2 (or a failed audit check, exit 1), within a time and
memory bound, and every file the user had is byte-identical afterwards.

Classes: resource bombs, non-finite numbers, wrong types, degenerate geometry, I/O
failures, a user's files next to and inside a dataset, damaged datasets, and messages
that must say the true reason.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MINIMAL = "name: t\ncamera: {mount: wingcam, hfov_deg: 55}\ndataset: {frames: 4}\n"
TINY = ("name: tiny\ncamera: {mount: wingcam, hfov_deg: 55.0, width: 128, height: 68}\n"
        "render: {spp: 1, max_depth: 2}\nlabels: {edge_margin_px: 2.0}\napproach: {frames_per_approach: 4}\n"
        "dataset: {frames: 8, shard_size: 3, min_shards: 1, seed: 7}\n")
#: A guard against a hang, not a limit asserted: a run still going after this many seconds
#: is stopped and reported as hung (a refusal takes a second or two; under load, more).
HANG_GUARD_S = 300.0
#: Every hostile run stays within this many resident megabytes.
RSS_LIMIT_MB = 1500.0


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str
    peak_rss_mb: float

    @property
    def error_lines(self) -> list[str]:
        """stderr without the build's progress lines (``build NAME: ...``, ``shard NAME: ...``)."""
        return [line for line in self.stderr.splitlines()
                if line.strip() and not re.match(r"(build|shard) \S+: ", line)]


def _high_water_mb(pid: int) -> float:
    """The peak resident memory of process ``pid``'s own address space (``VmHWM``), MiB;
    0 once it has exited."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    found = re.search(r"^VmHWM:\s+(\d+) kB", text, re.MULTILINE)
    return int(found.group(1)) / 1024 if found else 0.0


def datagen(*args: str, cwd: Path = ROOT) -> Run:
    """Run the CLI as a user would; measure its own peak RSS: the high water mark of its
    address space, read every 20 ms while it runs (``wait4``'s ``ru_maxrss`` counts the
    memory of the process it was forked from, this test process, before the exec). A run
    past :data:`HANG_GUARD_S` is stopped as hung."""
    import tempfile

    start = time.perf_counter()
    peak_mb = 0.0
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([sys.executable, "-m", "datagen", *args], cwd=cwd, stdout=out, stderr=err)
        while True:
            peak_mb = max(peak_mb, _high_water_mb(proc.pid))
            pid, status, _ = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - start > HANG_GUARD_S:
                proc.kill()
                os.wait4(proc.pid, 0)
                pytest.fail(f"datagen {' '.join(args)[:200]} hung (still running after {HANG_GUARD_S:g} s)")
            time.sleep(0.02)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text = [f.read().decode(errors="backslashreplace") for f in (out, err)]
    return Run(proc.returncode, text[0], text[1], peak_mb)


def refused(run: Run, *expected: str) -> str:
    """The run failed cleanly: exit 2, one line on stderr (no traceback) naming what is expected."""
    assert run.returncode == 2, (run.returncode, run.stderr[-2000:])
    assert len(run.error_lines) == 1, run.stderr[-2000:]
    line = run.error_lines[0]
    assert "Traceback" not in run.stderr
    for text in expected:
        assert text in line, line
    assert run.peak_rss_mb < RSS_LIMIT_MB, run.peak_rss_mb
    return line


def snapshot(folder: Path) -> dict[str, str]:
    """SHA-256 of every file under ``folder`` (links not followed; datagen's lock, which holds
    the pid of the last build, aside)."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink() and p.name != ".datagen.lock"}


def write(tmp: Path, name: str, text: str | bytes) -> Path:
    path = tmp / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


def alias_bomb(levels: int = 9) -> str:
    text = 'a: &a ["x","x","x","x","x","x","x","x","x"]\n'
    for i in range(levels):
        name, prev = chr(98 + i), chr(97 + i)
        text += f"{name}: &{name} [{','.join([f'*{prev}'] * 9)}]\n"
    return text


# --- resource bombs ------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "expected"), [
    (MINIMAL + alias_bomb(), "expands to more than 100,000 values"),
    (MINIMAL + "x: &a [1, *a]\n", "alias *a refers to a value that contains it"),
    (MINIMAL + "x: " + "[" * 5000 + "]" * 5000 + "\n", "nested deeper than 64 levels"),
    (MINIMAL.replace("frames: 4", "frames: " + "9" * 5000), "a number of 5000 characters"),
], ids=["alias-bomb", "recursive-alias", "deep-nesting", "5000-digit-integer"])
def test_yaml_bombs_are_refused_before_they_are_built(tmp_path, text, expected) -> None:
    path = write(tmp_path, "bomb.yaml", text)
    line = refused(datagen("validate", str(path)), expected)
    assert line.startswith(str(path))
    refused(datagen("build", "--config", str(path), "--no-render", "--out", str(tmp_path / "ds")), expected)
    assert not (tmp_path / "ds").exists()


def feature_file(tmp: Path, records_json: str) -> Path:
    """A config whose receiver features come from a hand-written feature file."""
    write(tmp, "mine.json", '{"format": "datagen.features/1", "object": "receiver", "variants": {"baseline": '
          + records_json + "}}")
    return write(tmp, "scene.yaml", MINIMAL + "objects: {receiver: {features: mine.json}}\n")


GOOD = {"class_id": 0, "name": "a", "object": "receiver", "points_m": [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]}


@pytest.mark.parametrize(("records", "expected"), [
    ("[" * 5000 + "]" * 5000, "nested deeper than 64 levels"),
    (json.dumps([GOOD]).replace('"class_id": 0', '"class_id": ' + "9" * 5000), "a number of 5000 characters"),
    (json.dumps([{**GOOD, "points_m": [[i * 1e-6, (i % 7) * 1e-3, 0.0] for i in range(1_000_000)]}]),
     "1000000 points; a feature may have at most 1024"),
    (json.dumps([{**GOOD, "class_id": i, "name": f"f{i}"} for i in range(5000)]), "a variant may have at most 1000"),
], ids=["deep-nesting", "5000-digit-integer", "a-million-points", "5000-features"])
def test_feature_file_bombs_are_refused(tmp_path, records, expected) -> None:
    refused(datagen("validate", str(feature_file(tmp_path, records))), "mine.json", expected)


@pytest.mark.parametrize(("args", "expected"), [
    (["build", "--config", "scenes/wingcam55.yaml", "--no-render", "--workers", "60"], "--workers: 60 is more than"),
    (["build", "--config", "scenes/wingcam55.yaml", "--no-render", "--threads", "60"], "--threads: 60 is not between"),
    (["assets", "show", "tanker", "--variant", "random", "--count", "100000"], "'--count'"),
    (["render", "--config", "scenes/wingcam55.yaml", "--frames", "0-10000000000"], "at most 10,000 at a time"),
    (["approach", "--config", "scenes/wingcam55.yaml", "--frames", "1000000000"], "'--frames'"),
    (["gallery", "--spp", "100000000"], "'--spp'"),
], ids=["workers", "threads", "count", "frame-range", "approach-frames", "spp"])
def test_count_flags_have_upper_bounds_checked_before_any_work(tmp_path, args, expected) -> None:
    run = datagen(*args, "--out", str(tmp_path / "out")) if args[0] in ("build", "render", "gallery") \
        else datagen(*args)
    refused(run, expected)
    assert not (tmp_path / "out").exists()


def test_a_dataset_preview_of_ten_billion_frames_is_refused(tmp_path) -> None:
    root = tmp_path / "ds"
    assert datagen("build", "--config", str(write(tmp_path, "t.yaml", TINY)), "--no-render",
                   "--out", str(root)).returncode == 0
    refused(datagen("preview", str(root), "--frames", "0-10000000000"), "at most 10,000 at a time")
    assert not (root / "preview").exists()


@pytest.mark.parametrize("special", ["fifo", "/dev/zero", "loop"])
def test_special_files_as_configs_neither_block_nor_read_forever(tmp_path, special) -> None:
    if special == "fifo":
        path = tmp_path / "scene.yaml"
        os.mkfifo(path)
    elif special == "loop":
        path = tmp_path / "loop.yaml"
        path.symlink_to(path)
    else:
        path = Path(special)
    refused(datagen("validate", str(path)))


# --- non-finite numbers ------------------------------------------------------------------------------
@pytest.mark.parametrize(("extra", "key"), [
    ("randomization: {exposure_ev: [.nan, 1.0]}", "randomization.exposure_ev[0]"),
    ("approach: {range_m: [0, .inf]}", "approach.range_m[1]"),
    ("drogue: {rms_m: [0.1, .nan, 0.1]}", "drogue.rms_m[1]"),
    ("labels: {edge_margin_px: .inf}", "labels.edge_margin_px"),
    ("labels: {min_box_px: -.inf}", "labels.min_box_px"),
    ("tanker: {speed_mps: .nan}", "tanker.speed_mps"),
], ids=["exposure", "range", "rms", "margin", "min-box", "speed"])
def test_non_finite_numbers_are_refused_by_validate_and_build_alike(tmp_path, extra, key) -> None:
    path = write(tmp_path, "scene.yaml", MINIMAL + extra + "\n")
    line = refused(datagen("validate", str(path)), key, "finite number")
    assert len(line) < 200  # the value, not the whole config
    assert refused(datagen("build", "--config", str(path), "--no-render", "--out", str(tmp_path / "ds"))) == line


@pytest.mark.parametrize("value", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_feature_coordinates_are_refused(tmp_path, value) -> None:
    records = json.dumps([GOOD]).replace("0.1, 0, 0", f"{value}, 0, 0")
    refused(datagen("validate", str(feature_file(tmp_path, records))), "mine.json", "not a finite number")


@pytest.mark.parametrize("radii", ["nan", "1e300", "0,-1", ",".join(["0"] * 50)])
def test_evaluate_noise_radii_are_finite_and_bounded(tmp_path, radii) -> None:
    root = tmp_path / "ds"
    assert datagen("build", "--config", str(write(tmp_path, "t.yaml", TINY)), "--no-render",
                   "--out", str(root)).returncode == 0
    refused(datagen("evaluate", str(root), "--noise-px", radii), "--noise-px")
    assert not (root / "evaluation").exists()


# --- wrong types -----------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "key", "message"), [
    (MINIMAL.replace("frames: 4", "frames: true"), "dataset.frames", "valid integer"),
    (MINIMAL.replace("hfov_deg: 55", "hfov_deg: true"), "camera.hfov_deg", "must be a number, got bool"),
    (MINIMAL.replace("hfov_deg: 55", 'hfov_deg: "55"'), "camera.hfov_deg", "without quotes"),
    (MINIMAL + "tanker: {altitude_m: [1, 1e4]}\n", "tanker.altitude_m[1]", "with a dot"),
    (MINIMAL + "labels: {corrected: 1}\n", "labels.corrected", "valid boolean"),
    (MINIMAL + "approach: {range_m: 5}\n", "approach.range_m", "valid tuple"),
    (MINIMAL.replace("frames: 4", "frames: 4.0"), "dataset.frames", "valid integer"),
    (MINIMAL + "features: {objects: receiver}\n", "features.objects", ""),
], ids=["bool-int", "bool-float", "quoted-number", "exponent-text", "int-bool", "scalar-range", "float-int",
        "string-list"])
def test_values_of_the_wrong_type_are_refused(tmp_path, text, key, message) -> None:
    path = write(tmp_path, "scene.yaml", text)
    refused(datagen("validate", str(path)), key, message)


@pytest.mark.parametrize(("change", "key"), [
    ({"class_id": True}, "class_id"),
    ({"class_id": 0.0}, "class_id"),
    ({"name": "a\nb"}, "name"),
    ({"points_m": "abc"}, "points_m"),
    ({"internal": "yes"}, "internal"),
])
def test_feature_records_of_the_wrong_type_are_refused(tmp_path, change, key) -> None:
    refused(datagen("validate", str(feature_file(tmp_path, json.dumps([{**GOOD, **change}])))),
            f"variants.baseline[0].{key}")


def test_duplicate_keys_in_feature_files_are_refused(tmp_path) -> None:
    refused(datagen("validate", str(feature_file(tmp_path, json.dumps([GOOD]).replace(
        '"name": "a"', '"name": "a", "name": "b"')))), "duplicate key 'name'")


# --- degenerate geometry --------------------------------------------------------------------------------
@pytest.mark.parametrize(("points", "expected"), [
    ([[1, 1, 1]] * 5, "all points coincide"),
    ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], "the points lie on one line"),
    ([[0, 0, 0], [1e-7, 1e-13, 0], [2e-7, 0, 0]], "the points lie on one line"),
    ([[0, 0, 0], [1, 0, 0]], "needs at least 3 points"),
])
def test_feature_point_sets_that_cannot_make_a_box_are_refused(tmp_path, points, expected) -> None:
    refused(datagen("validate", str(feature_file(tmp_path, json.dumps([{**GOOD, "points_m": points}])))),
            "variants.baseline[0].points_m", expected)


# --- I/O failures -----------------------------------------------------------------------------------------
def test_paths_that_cannot_be_created_are_refused_before_anything_is_written(tmp_path) -> None:
    config = write(tmp_path, "t.yaml", TINY)
    refused(datagen("build", "--config", str(config), "--no-render", "--out", str(tmp_path / ("x" * 300))),
            "longer than the 255")
    bad = os.fsdecode(bytes(tmp_path) + b"/bad\xff\xfe")
    refused(datagen("build", "--config", str(config), "--no-render", "--out", bad), "not a UTF-8 path")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.yaml"]
    refused(datagen("build", "--config", str(config), "--no-render", "--out", str(config)), "is a file")
    refused(datagen("build", "--config", str(config), "--no-render", "--out", "/proc/datagen-test"))


def test_reports_into_an_unwritable_place_are_one_line(tmp_path) -> None:
    root = tmp_path / "ds"
    config = write(tmp_path, "t.yaml", TINY)
    assert datagen("build", "--config", str(config), "--no-render", "--out", str(root)).returncode == 0
    before = snapshot(root)
    for args in (["audit", str(root)], ["evaluate", str(root), "--noise-px", "0"], ["preview", str(root)]):
        refused(datagen(*args, "--out", "/proc/datagen-test"), "/proc/datagen-test")
        refused(datagen(*args, "--out", str(config)), str(config))  # a file where a folder should be
    assert snapshot(root) == before and config.read_text() == TINY


def small_disk(tmp_path: Path, kilobytes: int) -> Path:
    """A tmpfs of ``kilobytes`` (skipped where this machine does not let the tests mount one)."""
    mount = tmp_path / f"disk{kilobytes}"
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kilobytes}k", "tmpfs", str(mount)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    return mount


@pytest.fixture
def disks(tmp_path):
    mounts: list[Path] = []
    yield lambda kb: mounts.append(small_disk(tmp_path, kb)) or mounts[-1]
    for mount in mounts:
        subprocess.run(["umount", str(mount)], check=False)


def test_a_full_disk_is_one_line_and_leaves_only_finished_shards(tmp_path, disks) -> None:
    config = write(tmp_path, "t.yaml", TINY.replace("frames: 8", "frames: 400"))
    tiny = disks(16)  # too small for the dataset's metadata: the new folder is removed again
    (tiny / "mine.txt").write_text("mine")
    refused(datagen("build", "--config", str(config), "--no-render", "--out", str(tiny / "ds")),
            "No space left on device")
    assert sorted(p.name for p in tiny.iterdir()) == ["mine.txt"]
    small = disks(300)  # room for a few shards: they are kept, complete, and nothing else is
    refused(datagen("build", "--config", str(config), "--no-render", "--out", str(small / "ds")),
            "No space left on device", "the finished shards are kept")
    root = small / "ds"
    assert not [p for p in root.rglob(".*") if p.name.endswith(".datagen-tmp")]
    import pyarrow.parquet as pq

    for manifest in (root / "manifests").glob("*.parquet"):
        for row in pq.read_table(manifest).to_pylist():
            assert (root / row["label_path"]).is_file()
    done = datagen("build", "--config", str(config), "--no-render", "--out", str(tmp_path / "ds"))
    assert done.returncode == 0
    refused(datagen("evaluate", str(tmp_path / "ds"), "--noise-px", "0", "--out", str(tiny / "ev")),
            "No space left on device")
    assert (tiny / "mine.txt").read_text() == "mine"


# --- a user's files next to and inside a dataset ---------------------------------------------------------------
def test_a_folder_with_only_a_users_hidden_tmp_file_is_not_swept(tmp_path) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / ".mywork.tmp").write_text("draft")
    refused(datagen("build", "--config", str(write(tmp_path, "t.yaml", TINY)), "--no-render", "--out", str(folder)),
            "not a datagen dataset")
    assert snapshot(folder) == {".mywork.tmp": hashlib.sha256(b"draft").hexdigest()}
    assert not (folder / ".datagen.lock").exists()  # a refused folder gets no file at all


def test_overwrite_removes_exactly_what_datagen_wrote(tmp_path) -> None:
    root = tmp_path / "ds"
    config = write(tmp_path, "t.yaml", TINY)
    for args in (["build", "--config", str(config), "--out", str(root)], ["audit", str(root)],
                 ["evaluate", str(root), "--noise-px", "0"], ["preview", str(root), "--frames", "0-1"]):
        assert datagen(*args).returncode == 0, args
    mine = {"notes.txt": "root", "labels/README": "labels", "labels/train/00000/extra.txt": "inside a shard",
            "audit/my-review.md": "audit", "images/train/sketch.png": "not a frame", "evaluation/plots/x.png": "mine",
            ".mywork.tmp": "hidden", "manifests/notes.parquet": "not a manifest"}
    for rel, text in mine.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("keep")
    other = write(tmp_path, "other.yaml", TINY.replace("seed: 7", "seed: 8"))
    refused(datagen("build", "--config", str(other), "--out", str(root)), "dataset.seed 7 -> 8", "--overwrite")
    assert datagen("build", "--config", str(other), "--out", str(root), "--overwrite").returncode == 0
    for rel, text in mine.items():
        assert (root / rel).read_text() == text, rel
    assert not (root / "audit" / "report.json").exists() and not (root / "preview" / "preview.json").exists()
    assert json.loads((root / "dataset.json").read_text())["seed"] == 8
    # The user's file in audit/ keeps the audit from writing there (one line naming it); moved away, the
    # audit runs and names the user's files in images/ and labels/ as orphans.
    refused(datagen("audit", str(root)), "my-review.md", "did not write")
    shutil.move(root / "audit" / "my-review.md", tmp_path / "my-review.md")
    assert datagen("audit", str(root)).returncode == 1
    assert (outside / "keep.txt").read_text() == "keep"


def test_overwrite_never_deletes_through_a_symbolic_link(tmp_path) -> None:
    root = tmp_path / "ds"
    config = write(tmp_path, "t.yaml", TINY)
    assert datagen("build", "--config", str(config), "--no-render", "--out", str(root)).returncode == 0
    elsewhere = tmp_path / "labels-elsewhere"
    (root / "labels").rename(elsewhere)
    (root / "labels").symlink_to(elsewhere)
    before, kept = snapshot(elsewhere), snapshot(root)
    other = write(tmp_path, "other.yaml", TINY.replace("seed: 7", "seed: 8"))
    refused(datagen("build", "--config", str(other), "--no-render", "--out", str(root), "--overwrite"),
            "symbolic link")
    assert snapshot(elsewhere) == before and snapshot(root) == kept  # nothing deleted, manifests included


@pytest.mark.parametrize("folder", ["/", "home"])
def test_a_refused_folder_gets_no_lock(tmp_path, folder) -> None:
    target = Path(folder) if folder == "/" else tmp_path
    if folder != "/":
        (tmp_path / "thesis.tex").write_text("years of work")
    listing = sorted(p.name for p in target.iterdir())
    refused(datagen("build", "--config", str(ROOT / "scenes" / "wingcam55.yaml"), "--no-render", "--out", str(target)),
            "not a datagen dataset")
    assert sorted(p.name for p in target.iterdir()) == listing


# --- damaged datasets ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("hostile")
    root = tmp / "ds"
    assert datagen("build", "--config", str(write(tmp, "t.yaml", TINY)), "--out", str(root)).returncode == 0
    return root


@pytest.fixture
def damaged(rendered, tmp_path) -> Path:
    shutil.copytree(rendered, tmp_path / "ds")
    return tmp_path / "ds"


def audit_fails(root: Path, check: str, text: str) -> None:
    run = datagen("audit", str(root))
    assert run.returncode == 1 and "Traceback" not in run.stderr, run.stderr
    report = json.loads((root / "audit" / "report.json").read_text())
    failed = {c["name"]: c for c in report["checks"] if not c["passed"]}
    assert check in failed and any(text in o for o in failed[check]["offenders"]), failed


def first(root: Path, tree: str, pattern: str) -> Path:
    return sorted((root / tree).rglob(pattern))[0]


def test_the_audit_opens_every_image(damaged) -> None:
    png = first(damaged, "images", "*.png")
    png.write_bytes(png.read_bytes()[:100])
    audit_fails(damaged, "images", "does not decode")
    text = sorted((damaged / "images").rglob("*.png"))[1]
    text.write_text("not an image")
    audit_fails(damaged, "images", "not a PNG or JPEG image")


def test_an_image_whose_header_claims_60000_px_is_not_decoded(damaged) -> None:
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    png = first(damaged, "images", "*.png")
    header = struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0)
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 10**6))
                    + chunk(b"IEND", b""))
    audit_fails(damaged, "images", "60000x60000 px, dataset.json says 128x68")


def test_a_fifo_in_place_of_a_label_or_image_does_not_block(damaged) -> None:
    label, image = first(damaged, "labels", "*.txt"), first(damaged, "images", "*.png")
    for path in (label, image):
        path.unlink()
        os.mkfifo(path)
    audit_fails(damaged, "images", "not a regular file")
    run = datagen("preview", str(damaged))
    assert run.returncode == 0 and "Traceback" not in run.stderr


def test_duplicate_manifest_rows_are_named_as_such(damaged) -> None:
    shutil.copy(first(damaged, "manifests", "train-*.parquet"), damaged / "manifests" / "train-00009.parquet")
    audit_fails(damaged, "files", "a manifest copied or renamed by hand")
    refused(datagen("evaluate", str(damaged), "--noise-px", "0"), "is in 2 manifests")


def test_a_missing_image_list_fails_the_audit(damaged) -> None:
    (damaged / "train.txt").unlink()
    audit_fails(damaged, "training_recipe", "train.txt: no such file; it lists the train images")


@pytest.mark.parametrize(("name", "text", "expected"), [
    ("data.yaml", "a: [\n  b: {\n", "data.yaml:3: invalid YAML"),
    ("data.yaml", alias_bomb(), "expands to more than"),
    ("dataset.json", "[" * 5000, "nested deeper than 64 levels"),
    ("dataset.json", "{\"a\": 1, \"a\": 2}", "duplicate key 'a'"),
    ("features.parquet", "PAR1 not parquet", "features.parquet: unreadable"),
])
def test_damaged_metadata_is_one_line_for_every_reader(damaged, name, text, expected) -> None:
    (damaged / name).write_text(text)
    for args in (["audit"], ["evaluate", "--noise-px", "0"], ["preview"]):
        refused(datagen(args[0], str(damaged), *args[1:]), expected)


def test_a_manifest_path_outside_the_dataset_is_refused(damaged) -> None:
    import pyarrow.parquet as pq

    path = first(damaged, "manifests", "train-*.parquet")
    table = pq.read_table(path)
    labels = table.column("label_path").to_pylist()
    labels[0] = "../../../etc/passwd"
    pq.write_table(table.set_column(table.schema.get_field_index("label_path"), "label_path",
                                    __import__("pyarrow").array(labels)), path)
    refused(datagen("audit", str(damaged)), "is not a path inside the dataset")


# --- messages that say the true reason ------------------------------------------------------------------------------
def test_a_rendered_rebuild_of_a_labels_only_dataset_says_so(tmp_path) -> None:
    config = write(tmp_path, "t.yaml", TINY)
    assert datagen("build", "--config", str(config), "--no-render", "--out", str(tmp_path / "ds")).returncode == 0
    line = refused(datagen("build", "--config", str(config), "--out", str(tmp_path / "ds")))
    assert "render false -> true: the folder holds a labels-only build (--no-render)" in line
    assert "asset files changed" not in line


def test_a_backwards_frame_range_says_so(tmp_path) -> None:
    refused(datagen("render", "--config", "scenes/wingcam55.yaml", "--frames", "5-3", "--out", str(tmp_path)),
            "--frames: 5-3: a range goes from the lower index to the higher")


def test_a_bad_flag_is_one_line_naming_the_command_and_the_flag() -> None:
    line = refused(datagen("build", "--config", "scenes/wingcam55.yaml", "--frames", "0"))
    assert line.startswith("datagen build: ") and "'--frames'" in line
    assert refused(datagen("build", "--confg", "x")).startswith("datagen build: No such option: --confg")
