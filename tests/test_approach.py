"""Monte Carlo approaches (paper 3.1): bounds, convergence, contact, PtD truth, purity, sampling."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datagen.assets.rig import HOSE_ATTACH_DROGUE_M, HOSE_PORT_TANKER_M, MOUNTS
from datagen.config import Config, load_config
from datagen.core.transforms import invert_rigid, rotvec_from_rotation
from datagen.scene import approach as ap
from datagen.scene import chains, flight

ROOT = Path(__file__).resolve().parents[1]
BASE = load_config(ROOT / "scenes" / "wingcam55.yaml")


def variant(config: Config = BASE, **sections) -> Config:
    data = config.model_dump()
    for section, values in sections.items():
        data[section].update(values)
    return Config.model_validate(data)


def ypr_of(rotation: np.ndarray) -> tuple[float, float, float]:
    """Inverse of rotation_from_ypr (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    return (math.atan2(rotation[1, 0], rotation[0, 0]), math.asin(-rotation[2, 0]),
            math.atan2(rotation[2, 1], rotation[2, 2]))


def convergence_rates(config: Config, seed: int, index: int, lo: float = 0.05, hi: float = 12.0):
    tr = chains.trace_approach(config, seed, index, every=1)
    keep = (tr["distance_m"] < hi) & (tr["distance_m"] > lo)
    t, v = tr["time_s"][keep], np.abs(tr["ptd_receiver_m"][keep])
    forward = -np.polyfit(t, np.log(v[:, 0]), 1)[0]
    lateral = np.hypot(v[:, 1], v[:, 2])
    ok = lateral > 1e-4
    return forward, -np.polyfit(t[ok], np.log(lateral[ok]), 1)[0]


def test_initial_attitude_perturbations_stay_within_bounds_and_cover_them() -> None:
    # 'time' sampling with stride 1 records each chain's very first step.
    cfg = variant(approach={"sampling": "time", "frames_per_approach": 1, "range_m": [5.0, 120.0]})
    k = cfg.approach
    ypr = []
    starts = []
    for a in range(300):
        st = ap.frame_state(cfg, a)
        tanker_from_receiver = invert_rigid(st.world_from_tanker) @ st.world_from_receiver
        ypr.append(np.degrees(ypr_of(tanker_from_receiver[:3, :3])))
        starts.append(tanker_from_receiver[:3, 3] - (invert_rigid(st.world_from_tanker) @ st.world_from_drogue)[:3, 3])
    ypr = np.abs(np.array(ypr))
    bounds = np.array([k.yaw_deg, k.pitch_deg, k.roll_deg])
    assert (ypr <= bounds + 1e-9).all()
    assert (ypr.max(axis=0) > 0.95 * bounds).all()  # covered, not just bounded
    starts = np.array(starts)
    distance = np.linalg.norm(starts, axis=1)
    assert distance.min() >= k.range_m[0] and distance.max() <= k.range_m[1]
    assert distance.min() < 15 and distance.max() > 110
    azimuth = np.degrees(np.arctan2(starts[:, 1], -starts[:, 0]))
    elevation = np.degrees(np.arcsin(starts[:, 2] / distance))
    assert np.abs(azimuth).max() <= k.start_azimuth_deg + 1e-9
    assert elevation.min() >= k.start_elevation_deg[0] - 1e-9 and elevation.max() <= k.start_elevation_deg[1] + 1e-9
    assert (starts[:, 0] < 0).all()  # always behind the drogue


def test_lateral_and_vertical_converge_twice_as_fast_as_forward() -> None:
    # No attitude perturbation, no turbulence: the rates are the configured gains.
    clean = variant(approach={"range_m": [0.0, 10.0], "yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0,
                              "sampling": "time"}, drogue={"intensity": [0.0, 0.0]})
    forward, lateral = convergence_rates(clean, 1, 0)
    assert forward == pytest.approx(clean.approach.forward_gain, rel=0.02)
    assert lateral / forward == pytest.approx(2.0, abs=0.05)
    # With the paper's perturbations and turbulence it is "about twice".
    ratios = [np.divide(*convergence_rates(BASE, 7, a)[::-1]) for a in range(6)]
    assert 1.7 <= float(np.mean(ratios)) <= 2.3


@pytest.mark.parametrize("path", sorted((ROOT / "scenes").glob("*.yaml")), ids=lambda p: p.stem)
def test_approaches_reach_contact_in_every_scene(path: Path) -> None:
    cfg = load_config(path)
    for a in range(2):
        tr = chains.trace_approach(cfg, cfg.dataset.seed, a, every=50)
        assert tr["distance_m"][-1] < cfg.approach.contact_m
        assert (tr["distance_m"][:-1] >= cfg.approach.contact_m).all()
        assert tr["time_s"][-1] < 400.0


@pytest.mark.parametrize("sampling", ["distance", "time"])
def test_traced_approach_is_the_one_the_frames_come_from(sampling: str) -> None:
    """`datagen approach` plots chain a's first approach: its frames lie on that trace."""
    cfg = variant(approach={"sampling": sampling, "stride_steps": 3})
    trace = chains.trace_approach(cfg, 5, 2, every=1)
    k = cfg.frames_per_chain
    for s in ap.frame_states(cfg, range(2 * k, 3 * k), seed=5):
        if s.approach_number:
            continue
        step = int(np.argmin(np.abs(trace["time_s"] - s.time_s)))
        assert trace["time_s"][step] == pytest.approx(s.time_s, abs=1e-9)
        np.testing.assert_allclose(trace["ptd_receiver_m"][step], s.ptd_receiver_m, atol=1e-9)


def test_time_sampling_restarts_after_contact() -> None:
    cfg = variant(approach={"sampling": "time", "range_m": [2.0, 4.0], "frames_per_approach": 40,
                            "stride_steps": 90})
    states = ap.frame_states(cfg, range(40))
    numbers = [s.approach_number for s in states]
    assert numbers == sorted(numbers) and numbers[-1] >= 1
    first_of_second = numbers.index(1)
    assert states[first_of_second].distance_m > states[first_of_second - 1].distance_m


@settings(max_examples=25)
@given(seed=st.integers(0, 2**32), frame=st.integers(0, 10_000),
       config=st.sampled_from([BASE, variant(camera={"mount": "podcam", "hfov_deg": 15.0}),
                               variant(tanker={"turn_probability": 1.0})]))
def test_recorded_ptd_equals_ptd_recomputed_from_poses(seed, frame, config) -> None:
    s = ap.frame_state(config, frame, seed)
    receiver_from_world = invert_rigid(s.world_from_receiver)
    drogue_in_receiver = receiver_from_world @ s.world_from_drogue[:, 3]
    np.testing.assert_allclose(s.ptd_receiver_m, drogue_in_receiver[:3], atol=1e-9)
    assert s.distance_m == pytest.approx(np.linalg.norm(drogue_in_receiver[:3]), abs=1e-9)
    # The paper's 3.5, through the camera: t_d^p = R_p^c^T (t_d^c - t_p^c), whatever the camera pose.
    cam_from_receiver = s.cam_from_world @ s.world_from_receiver
    cam_from_drogue = s.cam_from_world @ s.world_from_drogue
    via_camera = cam_from_receiver[:3, :3].T @ (cam_from_drogue[:3, 3] - cam_from_receiver[:3, 3])
    np.testing.assert_allclose(via_camera, s.ptd_receiver_m, atol=1e-6)


def test_frame_alone_equals_frame_in_sequence() -> None:
    cfg = variant(dataset={"seed": 1234})
    k = cfg.frames_per_chain
    in_sequence = ap.frame_states(cfg, range(3 * k))
    for i in (0, 5, k - 1, k, 2 * k + 3):
        alone = ap.frame_state(cfg, i)  # simulated afresh: frame_state keeps no cache
        ref = in_sequence[i]
        assert alone.frame_index == ref.frame_index == i
        for field in ("world_from_tanker", "world_from_receiver", "world_from_drogue", "world_from_cam",
                      "hose_points_world", "ptd_receiver_m"):
            np.testing.assert_array_equal(getattr(alone, field), getattr(ref, field), err_msg=field)
        assert alone.time_s == ref.time_s and alone.distance_m == ref.distance_m


def test_different_seeds_give_different_approaches() -> None:
    a, b = ap.frame_state(BASE, 3, seed=1), ap.frame_state(BASE, 3, seed=2)
    assert not np.allclose(a.world_from_receiver, b.world_from_receiver)


def test_distance_stratified_sampling_is_flat_and_time_sampling_is_not() -> None:
    cfg = variant(approach={"range_m": [0.0, 120.0], "frames_per_approach": 16})
    distances = np.array([s.distance_m for s in ap.frame_states(cfg, range(16 * 40))])
    assert distances.min() >= 0.0 and distances.max() <= 120.0
    counts, _ = np.histogram(distances, bins=12, range=(0.0, 120.0))
    expected = len(distances) / 12
    assert np.abs(counts - expected).max() <= 0.15 * expected, counts
    # The same approaches sampled in time crowd near contact: the reason to stratify.
    timed = variant(cfg, approach={"sampling": "time", "stride_steps": 30, "frames_per_approach": 200})
    d_time = np.array([s.distance_m for s in ap.frame_states(timed, range(600))])
    assert np.mean(d_time < 10.0) > 3 * (10.0 / 120.0)


def test_range_limited_scenes_stay_in_range() -> None:
    mid = load_config(ROOT / "scenes" / "wingcam55-mid.yaml")
    d = np.array([s.distance_m for s in ap.frame_states(mid, range(64))])
    assert d.min() >= 25.0 - 0.2 and d.max() <= 50.0 + 1e-9


@pytest.mark.parametrize("mount", ["wingcam", "dashcam", "podcam"])
def test_camera_pose_is_mount_plus_bounded_perturbation(mount: str) -> None:
    cfg = variant(camera={"mount": mount, "hfov_deg": 55.0})
    jitter = cfg.camera.mount_jitter
    body = MOUNTS[mount].body
    nominal = MOUNTS[mount].body_from_cam()
    shifts, angles = [], []
    for a in range(40):
        s = ap.frame_state(cfg, a * cfg.frames_per_chain)
        body_from_cam = invert_rigid(s.world_from(body)) @ s.world_from_cam
        shifts.append(body_from_cam[:3, 3] - nominal[:3, 3])
        angles.append(np.degrees(np.linalg.norm(rotvec_from_rotation(nominal[:3, :3].T @ body_from_cam[:3, :3]))))
    shifts, angles = np.abs(np.array(shifts)), np.array(angles)
    assert (shifts <= jitter.translation_m + 1e-12).all() and shifts.max() > 0.8 * jitter.translation_m
    assert angles.max() <= math.sqrt(3) * jitter.rotation_deg + 1e-9 and angles.max() > 0.5 * jitter.rotation_deg


def test_forward_mounts_look_forward_and_podcam_sees_the_drogue() -> None:
    wing = ap.frame_state(BASE, 0)
    cam_axis_receiver = (invert_rigid(wing.world_from_receiver) @ wing.world_from_cam)[:3, 2]
    assert cam_axis_receiver[0] > 0.99
    pod = ap.frame_state(variant(camera={"mount": "podcam", "hfov_deg": 15.0}), 0)
    drogue_cam = (pod.cam_from_world @ pod.world_from_drogue)[:3, 3]
    assert drogue_cam[2] > 15.0
    # Within the 15 deg field of view (7.5 deg half-angle), allowing for turbulence.
    assert math.degrees(math.atan2(abs(drogue_cam[0]), drogue_cam[2])) < 7.5


def test_hose_runs_from_port_to_drogue_coupling() -> None:
    s = ap.frame_state(BASE, 9)
    port = s.world_from_tanker @ np.append(HOSE_PORT_TANKER_M, 1.0)
    coupling = s.world_from_drogue @ np.append(HOSE_ATTACH_DROGUE_M, 1.0)
    np.testing.assert_allclose(s.hose_points_world[0], port[:3], atol=1e-9)
    np.testing.assert_allclose(s.hose_points_world[-1], coupling[:3], atol=1e-9)
    # In the tanker frame the hose runs steadily aft, and leaves the port downward.
    hose_h = np.c_[s.hose_points_world, np.ones(len(s.hose_points_world))]
    hose_tanker = (invert_rigid(s.world_from_tanker) @ hose_h.T).T
    assert (np.diff(hose_tanker[:, 0]) < 0).all()
    assert hose_tanker[1, 2] < hose_tanker[0, 2]


def test_banking_turn_is_coordinated() -> None:
    cfg = variant(tanker={"turn_probability": 1.0, "bank_deg": [25.0, 25.0]})
    tanker = flight.TankerFlight(cfg, np.random.default_rng(0))
    assert abs(math.degrees(tanker.bank)) == pytest.approx(25.0)
    a, b = tanker.world_from_tanker(10.0), tanker.world_from_tanker(11.0)
    yaw_rate = math.atan2(b[1, 0], b[0, 0]) - math.atan2(a[1, 0], a[0, 0])
    assert yaw_rate == pytest.approx(-9.80665 * math.tan(tanker.bank) / cfg.tanker.speed_mps, rel=1e-6)
    assert np.linalg.norm(b[:3, 3] - a[:3, 3]) == pytest.approx(cfg.tanker.speed_mps, rel=1e-3)
    # Right bank (positive roll) means right wing down and a right (clockwise) turn.
    assert ypr_of(a[:3, :3])[2] == pytest.approx(tanker.bank)
    assert np.sign(yaw_rate) == -np.sign(tanker.bank)


def test_turbulence_amplitude_follows_the_config() -> None:
    cfg = variant(drogue={"intensity": [1.0, 1.0], "rms_m": [0.2, 0.5, 0.3]})
    samples = []
    for seed in range(6):
        turb = flight.DrogueTurbulence(cfg, np.random.default_rng(seed), cfg.approach.dt_s)
        for _ in range(6000):
            turb.step()
            samples.append(turb.position)
    rms = np.sqrt(np.mean(np.square(samples), axis=0))
    np.testing.assert_allclose(rms, [0.2, 0.5, 0.3], rtol=0.3)
    calm = flight.DrogueTurbulence(variant(drogue={"intensity": [0.0, 0.0]}), np.random.default_rng(0), 0.03)
    calm.step()
    np.testing.assert_array_equal(calm.position, 0.0)


# --- approach models ----------------------------------------------------------------------
class _GustFedChain(chains._Chain):
    """Model 1's numpy chain, its drogue gusts taken from model 2's blocks instead of its own stream."""

    def __init__(self, config: Config, rng: np.random.Generator, gusts: np.random.Generator):
        rows: list[list[float]] = []

        def normal() -> list[float]:
            if not rows:
                rows.extend(gusts.standard_normal((chains.GUST_BLOCK, 3)).tolist()[::-1])
            return rows.pop()

        self._normal = normal
        super().__init__(config, rng)

    def _turbulence(self) -> flight.DrogueTurbulence:
        return flight.DrogueTurbulence(self.config, self.rng, self.dt, normals=self._normal)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), index=st.integers(0, 10_000), steps=st.integers(1, 900))
def test_model_2_steps_model_1s_dynamics_given_the_same_gusts(seed: int, index: int, steps: int) -> None:
    """Model 2 (chains stepped as a batch) is model 1's simulation: fed the same draws, the
    two chains stay together to rounding (the models differ only in where the gusts are drawn)."""
    from datagen.core.conventions import approach_rng, gust_rng

    batch = chains._Chains(BASE, seed, [index])  # model 2: a chain alone is a batch of one
    slow = _GustFedChain(BASE, approach_rng(seed, index), gust_rng(seed, index))
    chains._begin_chain(slow)
    state = batch.load([0])
    for _ in range(steps):
        batch.step(state, [0])
        slow.step()
    batch.store(state, [0], [0])
    fast = batch.chains[0]
    a, b = fast.snap(), slow.snap()
    assert abs(float(batch.distance(state)[0]) - slow.distance) < 1e-9
    for name in ("probe_tanker", "attitude_rotvec", "drogue_offset", "probe_velocity", "drogue_velocity"):
        assert np.allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-9), name


def test_approach_model_1_is_still_selectable_and_model_2_samples_other_trajectories() -> None:
    one = ap.frame_states(variant(approach={"model": 1}), range(32), seed=7)
    two = ap.frame_states(variant(approach={"model": 2}), range(32), seed=7)
    assert BASE.approach.model == 2
    # The same chain draws (starts, tanker, mount) in both: only the gusts differ.
    assert (one[0].turbulence_intensity, one[0].bank_deg) == (two[0].turbulence_intensity, two[0].bank_deg)
    assert not np.allclose(one[5].world_from_drogue, two[5].world_from_drogue)
    for states in (one, two):
        assert states[15].distance_m < states[0].distance_m  # each approach closes on the drogue


@pytest.mark.parametrize("sampling", ["distance", "time"])
def test_chains_simulated_together_equal_each_chain_simulated_alone(sampling: str) -> None:
    """simulate_chains steps model 2's chains together, element by element: each chain's
    snapshots are bit for bit its own, whichever chains it shares a batch with."""
    config = variant(approach={"sampling": sampling, "stride_steps": 90, "range_m": [2.0, 12.0]})
    alone = {a: chains.simulate_chain(config, 11, a) for a in range(20, 32)}
    for batch in (range(20, 32), range(26, 29), [31, 20]):
        together = chains.simulate_chains(config, 11, batch)
        assert set(together) == set(batch)
        for a, snapshots in together.items():
            assert len(snapshots) == len(alone[a])
            for x, y in zip(snapshots, alone[a], strict=True):
                assert (x.time_s, x.approach_number) == (y.time_s, y.approach_number)
                for name in ("probe_tanker", "attitude_rotvec", "drogue_offset", "probe_velocity", "drogue_velocity"):
                    assert np.array_equal(getattr(x, name), getattr(y, name)), (a, name)
    if sampling == "time":  # chains that reach contact and begin another approach mid-batch
        assert any(s.approach_number > 0 for snapshots in alone.values() for s in snapshots)
    upto = {20: 1, 23: 5, 31: 9}  # chains stopped early hold at least their wanted first snapshots, the same
    partial = chains.simulate_chains(config, 11, range(20, 32), upto)
    for a, snapshots in partial.items():
        assert upto.get(a, len(alone[a])) <= len(snapshots) <= len(alone[a])
        for x, y in zip(snapshots, alone[a], strict=False):
            assert x.time_s == y.time_s and np.array_equal(x.probe_tanker, y.probe_tanker)
    assert len(partial[20]) < len(alone[20])


def test_prefetched_frame_states_equal_frame_states_made_alone() -> None:
    """Prefetching simulates each chain only up to its last frame asked for; a later frame
    of such a chain is simulated again, the same."""
    states = ap.FrameStates(BASE, 5)
    states.prefetch(range(3, 300, 7))
    k = BASE.frames_per_chain
    for i in (3, 10, 150, 297, k - 1, 290 // k * k + k - 1):
        alone = ap.frame_state(BASE, i, 5)
        assert np.array_equal(states(i).world_from_cam, alone.world_from_cam)
        assert np.array_equal(states(i).hose_points_world, alone.hose_points_world)


def test_the_earlier_state_is_made_on_first_use_motion_dt_before_and_kept() -> None:
    """FrameState.earlier (motion blur's finite difference) is made only when asked for:
    MOTION_DT_S before the frame, without an earlier state of its own, the same object on
    every use, and it survives pickling (a state sent to another process)."""
    import pickle

    state = ap.FrameStates(BASE, 5)(20)
    assert "earlier" not in vars(state)  # not made until it is asked for
    earlier = state.earlier
    assert earlier is state.earlier and earlier.earlier_from is None and earlier.earlier is None
    assert earlier.time_s == pytest.approx(state.time_s - ap.MOTION_DT_S, abs=1e-9)
    moved = np.linalg.norm(earlier.world_from_receiver[:3, 3] - state.world_from_receiver[:3, 3])
    assert 0.0 < moved < 5.0
    copy = pickle.loads(pickle.dumps(ap.FrameStates(BASE, 5)(20)))
    np.testing.assert_array_equal(copy.earlier.world_from_cam, earlier.world_from_cam)


def test_simulating_no_chain_gives_no_snapshots() -> None:
    assert chains.simulate_chains(BASE, 3, []) == {}


@settings(max_examples=60, deadline=None)
@given(frames=st.integers(1, 3000), k=st.integers(1, 40), least=st.integers(1, 20))
def test_a_build_spans_min_approaches_and_a_large_build_keeps_frames_per_approach(frames: int, k: int,
                                                                                   least: int) -> None:
    cfg = variant(approach={"frames_per_approach": k, "min_approaches": least}, dataset={"frames": frames})
    chains_used = len({i // cfg.frames_per_chain for i in range(frames)})
    assert chains_used >= min(frames, least)
    if frames >= k * least:
        assert cfg.frames_per_chain == k


def test_a_small_build_shows_several_approaches_and_a_full_build_draws_what_it_drew() -> None:
    """Twelve frames come from twelve approaches (their own sky, sea and clouds); the full
    build's frames are those it has without the rule (min_approaches 1)."""
    small = variant(dataset={"frames": 12})
    states = ap.frame_states(small, range(12))
    assert len({s.approach_index for s in states}) == 12
    full, unruled = BASE, variant(approach={"min_approaches": 1})
    for i in (0, 17, 9_999):
        assert np.array_equal(ap.frame_state(full, i).world_from_cam, ap.frame_state(unruled, i).world_from_cam)
