"""The approach chains: the Monte Carlo simulation of paper 3.1 that
:mod:`datagen.scene.approach` turns into frame states (pure numpy, no rendering).

A chain is one receiver flying approach after approach behind one tanker, with one
drogue under turbulence; every draw comes from :func:`datagen.core.conventions.approach_rng`
``(seed, a)`` (and, in approach model 2, the drogue's gusts from :func:`gust_rng`). Model 2's
dynamics are written once, for a batch of chains (:class:`_Chains`; a chain alone is a
batch of one); model 1 (:class:`_Chain`, every draw from the chain's one stream, numpy a
step at a time) stays for reproducing datasets built before model 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.rig import MOUNTS
from datagen.config.schema import Config
from datagen.core.conventions import approach_rng, gust_rng
from datagen.core.transforms import (
    make_transform,
    rotation_from_rotvec,
    rotation_from_ypr,
    rotation_rows_from_rotvecs,
    rotvec_from_rotation,
)
from datagen.scene.flight import (
    DrogueTurbulence,
    TankerFlight,
    draw_start,
    mount_jitter,
    start_offset,
)

__all__ = ["ChainSnapshot", "simulate_chain", "simulate_chains", "trace_approach"]

FloatArray = NDArray[np.float64]


# --- the simulation ---------------------------------------------------------------
@dataclass
class ChainSnapshot:
    """A chain's state at one instant (tanker frame), from which a frame's state is made."""

    approach_number: int
    time_s: float
    probe_tanker: FloatArray
    attitude_rotvec: FloatArray
    drogue_offset: FloatArray
    body_from_cam: FloatArray
    tanker: TankerFlight
    intensity: float
    # Rates at this instant (tanker frame), for the state MOTION_DT_S earlier (motion blur).
    probe_velocity: FloatArray = field(default_factory=lambda: np.zeros(3))
    rotvec_rate: FloatArray = field(default_factory=lambda: np.zeros(3))
    drogue_velocity: FloatArray = field(default_factory=lambda: np.zeros(3))

    def earlier(self, dt: float) -> ChainSnapshot:
        """This snapshot ``dt`` seconds earlier, moved back along its rates (the chain's
        motion is smooth on that scale: the simulation step is 1/30 s)."""
        return replace(
            self, time_s=self.time_s - dt, probe_tanker=self.probe_tanker - dt * self.probe_velocity,
            attitude_rotvec=self.attitude_rotvec - dt * self.rotvec_rate,
            drogue_offset=self.drogue_offset - dt * self.drogue_velocity)


class _Chain:
    """One approach chain: the tanker, the turbulence, and a receiver that flies
    approach after approach; every draw from one RNG, in a fixed order."""

    def __init__(self, config: Config, rng: np.random.Generator):
        a = config.approach
        self.config = config
        self.rng = rng
        self.dt = a.dt_s
        self.tanker = TankerFlight(config, rng)
        self.turbulence = self._turbulence()
        self.gains = a.forward_gain * np.array([1.0, a.lateral_gain_ratio, a.lateral_gain_ratio])
        self.limits = np.array([a.max_closure_mps, a.max_lateral_mps, a.max_lateral_mps])
        self.attitude_decay = math.exp(-self.dt / a.attitude_time_constant_s)
        self.time_s = 0.0
        self.approach_number = -1
        self.steps_this_approach = 0

    def _turbulence(self) -> DrogueTurbulence:
        return DrogueTurbulence(self.config, self.rng, self.dt)

    def _sync(self) -> None:
        """Bring the arrays (probe, rotvec, turbulence) up to date (a subclass may step in floats)."""

    def new_approach(self, distance_m: float) -> None:
        self.approach_number += 1
        self.steps_this_approach = 0
        start = draw_start(self.config, self.rng, distance_m)
        self.probe = self.turbulence.position + start_offset(start)
        self.rotvec = rotvec_from_rotation(rotation_from_ypr(start.yaw_rad, start.pitch_rad, start.roll_rad))
        shift, rot = mount_jitter(self.config.camera.mount_jitter, self.rng)
        nominal = MOUNTS[self.config.camera.mount].body_from_cam()
        self.body_from_cam = make_transform(np.eye(3), shift) @ nominal @ make_transform(rot, np.zeros(3))

    @property
    def ptd_tanker(self) -> FloatArray:
        return self.turbulence.position - self.probe

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.ptd_tanker))

    def step(self) -> None:
        if self.steps_this_approach >= self.config.approach.max_steps:
            raise _no_contact(self.config, self.distance)
        drogue_before = self.turbulence.position
        self.turbulence.step()
        rotation = rotation_from_rotvec(self.rotvec)
        ptd_receiver = rotation.T @ (drogue_before - self.probe)
        velocity_receiver = np.clip(self.gains * ptd_receiver, -self.limits, self.limits)
        # Match the drogue's own motion, then close on it along the receiver's axes.
        self.probe = self.probe + (self.turbulence.position - drogue_before) + self.dt * (
            rotation @ velocity_receiver)
        self.rotvec = self.rotvec * self.attitude_decay  # slerp toward the tanker's attitude
        self.time_s += self.dt
        self.steps_this_approach += 1

    def snap(self) -> ChainSnapshot:
        rotation = rotation_from_rotvec(self.rotvec)
        ptd_receiver = rotation.T @ (self.turbulence.position - self.probe)
        closing = rotation @ np.clip(self.gains * ptd_receiver, -self.limits, self.limits)
        return ChainSnapshot(self.approach_number, self.time_s, self.probe.copy(), self.rotvec.copy(),
                         self.turbulence.position.copy(), self.body_from_cam, self.tanker,
                         self.turbulence.intensity,
                         probe_velocity=self.turbulence.velocity + closing,
                         rotvec_rate=self.rotvec * (self.attitude_decay - 1.0) / self.dt,
                         drogue_velocity=self.turbulence.velocity.copy())


#: Rows of gust normals approach model 2 draws at a time.
GUST_BLOCK = 1024


def _no_contact(config: Config, distance: float) -> RuntimeError:
    return RuntimeError(f"an approach did not reach contact in {config.approach.max_steps} steps "
                        f"(distance {distance:.3f} m): check the approach gains and speed limits")


class _FastChain(_Chain):
    """A chain of approach model 2: :class:`_Chain`'s draws, except the drogue's gusts,
    which come in blocks of :data:`GUST_BLOCK` from a stream of their own
    (:func:`gust_rng`). Its state between snapshots lives in plain floats (``_gust``,
    ``_position``, ``_velocity``, ``_probe``, ``_rotvec``) that :class:`_Chains` steps."""

    def __init__(self, config: Config, rng: np.random.Generator, gusts: np.random.Generator):
        self._gusts = gusts
        super().__init__(config, rng)
        t = self.turbulence
        self._sigma_kick = [float(v) * t.kick for v in t.sigma]
        self._gust = [float(v) for v in t.gust]
        self._position = [float(v) for v in t.position]
        self._velocity = [float(v) for v in t.velocity]

    def _turbulence(self) -> DrogueTurbulence:
        return DrogueTurbulence(self.config, self.rng, self.dt, warmup=False)  # _Chains warms it up

    def new_approach(self, distance_m: float) -> None:
        self._sync()
        super().new_approach(distance_m)
        self._probe = [float(v) for v in self.probe]
        self._rotvec = [float(v) for v in self.rotvec]

    def _sync(self) -> None:
        """The float state back into the arrays :meth:`snap` and :meth:`new_approach` read."""
        t = self.turbulence
        t.gust, t.position, t.velocity = np.array(self._gust), np.array(self._position), np.array(self._velocity)
        if hasattr(self, "_probe"):  # after the chain's first approach began
            self.probe, self.rotvec = np.array(self._probe), np.array(self._rotvec)

    def step(self) -> None:
        raise TypeError("a model 2 chain steps in a batch (_Chains)")

    def snap(self) -> ChainSnapshot:
        self._sync()
        return super().snap()


#: The float state of a model 2 chain that :class:`_Chains` steps.
_STATE: Final = ("_gust", "_position", "_velocity", "_probe", "_rotvec", "_sigma_kick")


class _Chains:
    """Chains of approach model 2 stepping together, each step one numpy operation over
    every chain: the one implementation of model 2's dynamics (a chain alone is a batch of
    one). Element by element it is the arithmetic of :class:`_Chain.step`, in another order
    of the same sums (sines and cosines per chain, through :mod:`math`), so that a chain's
    states are bit for bit the same whichever chains it steps with. Creating the batch
    warms every chain's turbulence up and begins each chain's first approach."""

    def __init__(self, config: Config, seed: int, approach_indices: list[int]):
        self.config = config
        self.chains = [_FastChain(config, approach_rng(seed, i), gust_rng(seed, i)) for i in approach_indices]
        first = self.chains[0]
        t = first.turbulence
        self.dt, self.decay = first.dt, t.decay
        self.w2, self.damp = t.omega * t.omega, 2.0 * t.zeta * t.omega
        self.attitude_decay = first.attitude_decay
        self.gains, self.limits = np.array(first.gains, dtype=float), np.array(first.limits, dtype=float)
        self.steps = np.zeros(len(self.chains), dtype=np.int64)  # steps of each chain's current approach
        # Each chain's gusts, a block at a time.
        self._normals = np.array([ch._gusts.standard_normal((GUST_BLOCK, 3)) for ch in self.chains])
        self._used = 0
        every = np.arange(len(self.chains))
        warm = {name: np.array([getattr(ch, name) for ch in self.chains]) for name in ("_gust", "_position",
                                                                                    "_velocity", "_sigma_kick")}
        for _ in range(t.warmup_steps):
            self._gust_step(warm, every)
        for row, ch in enumerate(self.chains):
            ch._gust, ch._position, ch._velocity = (warm[name][row].tolist() for name in ("_gust", "_position",
                                                                                          "_velocity"))
        self.targets = [_begin_chain(ch) for ch in self.chains]

    def load(self, active: list[int]) -> dict[str, FloatArray]:
        """The float state of chains ``active`` as arrays, a row per chain."""
        rows = [self.chains[c] for c in active]
        return {name: np.array([getattr(ch, name) for ch in rows]).reshape(len(rows), -1) for name in _STATE} | {
            "time_s": np.array([ch.time_s for ch in rows])}

    def store(self, state: dict[str, FloatArray], active: list[int], rows) -> None:
        """The state of ``rows`` (of ``active``) back into their chains, which snap and begin approaches."""
        for row in rows:
            ch = self.chains[active[row]]
            for name in _STATE[:-1]:
                setattr(ch, name, state[name][row].tolist())
            ch.time_s = float(state["time_s"][row])
            ch.steps_this_approach = int(self.steps[active[row]])

    @staticmethod
    def distance(state: dict[str, FloatArray]) -> FloatArray:
        """Each chain's PtD distance."""
        p, q = state["_position"], state["_probe"]
        return np.sqrt((p[:, 0] - q[:, 0]) ** 2 + (p[:, 1] - q[:, 1]) ** 2 + (p[:, 2] - q[:, 2]) ** 2)

    def _gust_step(self, state: dict[str, FloatArray], rows: NDArray[np.int64]) -> FloatArray:
        """One step of the turbulence of ``rows``' chains (:meth:`DrogueTurbulence.step`);
        the drogue positions before it."""
        if self._used == self._normals.shape[1]:
            block = np.zeros((len(self.chains), GUST_BLOCK, 3))
            for c in rows.tolist():
                block[c] = self.chains[c]._gusts.standard_normal((GUST_BLOCK, 3))
            self._normals, self._used = block, 0
        before = state["_position"]
        gust = state["_gust"] * self.decay + state["_sigma_kick"] * self._normals[rows, self._used]
        self._used += 1
        velocity = state["_velocity"] + self.dt * (self.w2 * (gust - before) - self.damp * state["_velocity"])
        state["_gust"], state["_velocity"], state["_position"] = gust, velocity, before + self.dt * velocity
        return before

    def step(self, state: dict[str, FloatArray], active: list[int]) -> None:
        """One step of every chain of ``active`` (rows of ``state``): the drogue's turbulence,
        then the receiver's closure along its own axes on top of the drogue's motion, and
        its attitude's slerp back to the tanker's."""
        rows = np.array(active)
        over = self.steps[rows] >= self.config.approach.max_steps
        if over.any():
            raise _no_contact(self.config, float(self.distance(state)[over][0]))
        before = self._gust_step(state, rows)
        r = rotation_rows_from_rotvecs(state["_rotvec"])
        e = before - state["_probe"]
        ptd = np.stack([r[:, 0] * e[:, 0] + r[:, 3] * e[:, 1] + r[:, 6] * e[:, 2],
                        r[:, 1] * e[:, 0] + r[:, 4] * e[:, 1] + r[:, 7] * e[:, 2],
                        r[:, 2] * e[:, 0] + r[:, 5] * e[:, 1] + r[:, 8] * e[:, 2]], axis=1)  # rotation.T @ e
        v = np.minimum(np.maximum(self.gains * ptd, -self.limits), self.limits)
        closing = np.stack([r[:, 0] * v[:, 0] + r[:, 1] * v[:, 1] + r[:, 2] * v[:, 2],
                            r[:, 3] * v[:, 0] + r[:, 4] * v[:, 1] + r[:, 5] * v[:, 2],
                            r[:, 6] * v[:, 0] + r[:, 7] * v[:, 1] + r[:, 8] * v[:, 2]], axis=1)
        state["_probe"] = state["_probe"] + (state["_position"] - before) + self.dt * closing
        state["_rotvec"] = state["_rotvec"] * self.attitude_decay
        state["time_s"] = state["time_s"] + self.dt
        self.steps[rows] += 1


def _start_chain(config: Config, seed: int, approach_index: int) -> tuple[_Chain, FloatArray | None]:
    """Chain ``approach_index`` of approach model 1 with its first approach begun, and for
    'distance' sampling its distance targets (far to near)."""
    chain = _Chain(config, approach_rng(seed, approach_index))
    return chain, _begin_chain(chain)


def _begin_chain(chain: _Chain) -> FloatArray | None:
    """Begin a new chain's first approach; its distance targets or None. The one place that
    fixes the order of a chain's first draws, so that a traced approach is the one its
    frames come from."""
    a = chain.config.approach
    k = chain.config.frames_per_chain
    lo, hi = a.range_m
    if a.sampling == "distance":
        # One frame per distance stratum, visited from far to near, on one approach.
        targets = np.sort(lo + (np.arange(k) + chain.rng.random(k)) * (hi - lo) / k)[::-1]
        chain.new_approach(hi)
        return targets
    chain.new_approach(float(chain.rng.uniform(lo, hi)))
    return None


def simulate_chain(config: Config, seed: int, approach_index: int) -> list[ChainSnapshot]:
    """Simulate approach chain ``approach_index``; return its ``Config.frames_per_chain`` snapshots."""
    if config.approach.model == 2:
        return simulate_chains(config, seed, [approach_index])[approach_index]
    a = config.approach
    k = config.frames_per_chain
    chain, targets = _start_chain(config, seed, approach_index)
    snapshots: list[ChainSnapshot] = []
    if targets is not None:
        while True:
            distance = chain.distance
            contact = distance < a.contact_m
            while len(snapshots) < k and (contact or targets[len(snapshots)] >= distance):
                snapshots.append(chain.snap())
            if len(snapshots) == k:
                return snapshots
            chain.step()
    # 'time': a frame every stride_steps steps, through contact and the next approaches.
    step = 0
    while True:
        if step % a.stride_steps == 0:
            snapshots.append(chain.snap())
            if len(snapshots) == k:
                return snapshots
        if chain.distance < a.contact_m:
            chain.new_approach(float(chain.rng.uniform(*a.range_m)))
        chain.step()
        step += 1


def simulate_chains(config: Config, seed: int, approach_indices,
                    upto: dict[int, int] | None = None) -> dict[int, list[ChainSnapshot]]:
    """:func:`simulate_chain` of many chains. With approach model 2 they step together
    (:class:`_Chains`), so each chain's snapshots are bit for bit those it has alone,
    whichever chains it is simulated with.

    ``upto``: per chain, how many of its first snapshots are wanted; a chain stops once it
    has them (model 2; the rest are not simulated), others run to their last frame."""
    indices = list(dict.fromkeys(int(i) for i in approach_indices))
    a = config.approach
    if a.model == 1 or not indices:
        return {i: simulate_chain(config, seed, i) for i in indices}
    k = config.frames_per_chain
    wanted = np.array([min(max(int((upto or {}).get(i, k)), 1), k) for i in indices])
    batch = _Chains(config, seed, indices)
    chains, targets = batch.chains, batch.targets
    snapshots: list[list[ChainSnapshot]] = [[] for _ in indices]
    active = list(range(len(chains)))
    inf = math.inf
    next_target = np.array([tg[0] if tg is not None else inf for tg in targets])
    state = batch.load(active)
    step = 0
    while active:
        distance = batch.distance(state)
        contact = distance < a.contact_m
        if a.sampling == "distance":
            due = np.flatnonzero(contact | (next_target[np.array(active)] >= distance)).tolist()
        else:
            due = list(range(len(active))) if step % a.stride_steps == 0 else np.flatnonzero(contact).tolist()
        if due:  # a snapshot, a new approach or a chain done: in each chain's own terms
            batch.store(state, active, due)
            for row in due:
                c = active[row]
                chain = chains[c]
                if a.sampling == "distance":
                    due_at = targets[c]
                    assert due_at is not None  # (drawn where frames are sampled by distance)
                    while len(snapshots[c]) < k and (contact[row] or due_at[len(snapshots[c])] >= distance[row]):
                        snapshots[c].append(chain.snap())
                    next_target[c] = due_at[len(snapshots[c])] if len(snapshots[c]) < k else inf
                else:
                    if step % a.stride_steps == 0:
                        snapshots[c].append(chain.snap())
                    if len(snapshots[c]) < k and contact[row]:
                        chain.new_approach(float(chain.rng.uniform(*a.range_m)))
                        batch.steps[c] = chain.steps_this_approach
                        state["_probe"][row], state["_rotvec"][row] = chain._probe, chain._rotvec
            keep = [row for row, c in enumerate(active) if len(snapshots[c]) < wanted[c]]
            if not keep:
                break
            if len(keep) < len(active):
                state = {name: values[keep] for name, values in state.items()}
                active = [active[row] for row in keep]
        batch.step(state, active)
        step += 1
    return dict(zip(indices, snapshots, strict=True))


def trace_approach(config: Config, seed: int, approach_index: int, every: int = 3) -> dict[str, FloatArray]:
    """The first approach of chain ``approach_index`` from start to contact, every ``every``
    steps: ``time_s``, ``distance_m``, ``ptd_receiver_m`` (T, 3) and ``probe_drogue_m``
    (T, 3), the probe tip in the drogue-centred local frame (paper Fig. 7)."""
    a = config.approach
    chain: _Chain | _FastChain
    if a.model == 2:  # a batch of one; its chain's arrays are brought up to date before they are read
        batch = _Chains(config, seed, [approach_index])
        chain, state = batch.chains[0], batch.load([0])

        def distance() -> float:
            return float(batch.distance(state)[0])

        def sync() -> None:
            batch.store(state, [0], [0])
            chain._sync()

        def advance() -> None:
            batch.step(state, [0])
    else:
        chain, _ = _start_chain(config, seed, approach_index)

        def distance() -> float:
            return chain.distance

        def sync() -> None:
            pass

        advance = chain.step
    rows: list[tuple] = []
    step = 0
    while True:
        d = distance()
        if step % every == 0 or d < a.contact_m:
            sync()
            rotation = rotation_from_rotvec(chain.rotvec)
            rows.append((chain.time_s, d, rotation.T @ chain.ptd_tanker, -chain.ptd_tanker))
        if d < a.contact_m:
            break
        advance()
        step += 1
    return {
        "time_s": np.array([r[0] for r in rows]),
        "distance_m": np.array([r[1] for r in rows]),
        "ptd_receiver_m": np.array([r[2] for r in rows]),
        "probe_drogue_m": np.array([r[3] for r in rows]),
    }
