"""A fuzz corpus for ``ema identify``: records whose effects were never named by its vocabulary.

Nothing here imports the simulator. The plant is written from scratch and from physics, not from the
effect list: a rotary surface on a crank driven by a motor and ball screw under a cascade servo
(position P, velocity PI, current limit, first-order current loop) at its own control rate, integrated
at 10 kHz. Effects are drawn at random and combined; each is a property of the hardware or the logger,
never a parameter of a model ``ema identify`` fits:

* **drive**: asymmetric current and speed limits (direction asymmetry), Coulomb friction with Stribeck
  stiction (stick-slip), a spring that centres the surface off zero and stiffens with angle (position
  asymmetry), gear backlash between the screw and the crank, a linkage spring to the surface inertia,
  hard travel stops, a crank whose LVDT reads the ram (sin of the angle), a controller that runs at a
  slow rate with its own computation delay;
* **sensors**: white noise, counts, a tone, spikes, dropouts (a reading held stale), slow drift, scale
  and offset errors, on the LVDT, the surface sensor or both;
* **logger**: 50 Hz to 2 kHz, jittery instants, stamps rounded to the millisecond, short and long records.

``record(seed)`` draws one record (its effects are in ``metadata['fuzz']``), ``write(record, path)``
writes it as a data-contract CSV. The held-out records of :mod:`strangers` come from another plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PLANT_S = 1e-4


@dataclass
class Plant:
    """The hardware: every number in surface degrees, seconds and normalised inertia."""

    position_bw_hz: float = 6.0
    velocity_bw_hz: float = 40.0
    accel_up: float = 3000.0
    """Current limit pushing positive, as an acceleration of the drive (deg/s²)."""
    accel_down: float = 3000.0
    speed_up: float = 150.0
    speed_down: float = 150.0
    current_tau_s: float = 4e-4
    control_hz: float = 2000.0
    compute_delay_ticks: int = 0
    coulomb: float = 0.0
    """Coulomb friction as an acceleration (deg/s²); stiction is ``stribeck`` times it."""
    stribeck: float = 1.0
    viscous: float = 2.0
    backlash_deg: float = 0.0
    link_hz: float = 0.0
    """Linkage mode between the crank and the surface (0: rigid)."""
    link_zeta: float = 0.08
    surface_share: float = 0.3
    """Surface inertia as a share of the whole."""
    spring: float = 0.0
    """Centring spring (1/s²) about ``spring_centre_deg``, stiffening by ``spring_cubic`` per deg²."""
    spring_centre_deg: float = 0.0
    spring_cubic: float = 0.0
    hm_gain: float = 0.0
    """Hinge moment to surface acceleration (deg/s² per in·lb)."""
    stop_deg: float = 30.0
    crank: bool = False
    """The LVDT reads the ram: sin of the crank angle, scaled back to degrees linearly."""


@dataclass
class Sensor:
    """One output sensor's defects (all off by default)."""

    noise: float = 0.0
    counts: float = 0.0
    tone_amp: float = 0.0
    tone_hz: float = 0.0
    spikes: int = 0
    spike_amp: float = 0.0
    dropouts: int = 0
    dropout_s: float = 0.05
    drift_per_s: float = 0.0
    scale: float = 1.0
    offset: float = 0.0


@dataclass
class Fuzz:
    """One record's recipe."""

    seed: int
    plant: Plant
    lvdt: Sensor | None
    surface: Sensor | None
    rate_hz: float
    duration_s: float
    jitter_s: float
    ms_stamps: bool
    hinge_moment: bool
    hm_noise: float
    demand: str
    effects: list[str] = field(default_factory=list)


def _demand(kind: str, t: np.ndarray, rng: np.random.Generator, amp: float) -> np.ndarray:
    """A test demand: steps, a sweep, a triangle, a trapezoid, a sine or a random staircase."""
    dur = float(t[-1])
    lead = min(0.4, 0.1 * dur)
    tt = np.clip(t - lead, 0.0, None)
    on = t >= lead
    if kind == "steps":
        n = int(rng.integers(3, 8))
        edges = np.sort(rng.uniform(lead, dur - 0.3, n))
        levels = rng.choice([-1.0, 1.0], n) * amp * rng.choice([0.05, 0.2, 0.5, 1.0], n)
        u = np.zeros_like(t)
        for e, v in zip(edges, levels, strict=True):
            u = np.where(t >= e, v, u)
        return u
    if kind == "sweep":
        f0, f1 = float(rng.uniform(0.2, 1.0)), float(rng.uniform(4.0, 18.0))
        span = max(dur - lead - 0.2, 0.5)
        k = math.log(f1 / f0) / span
        ts = np.clip(tt, 0.0, span)
        return np.where(on & (tt <= span), 0.3 * amp * np.sin(2 * np.pi * f0 * np.expm1(k * ts) / k), 0.0)
    if kind == "triangle":
        f = float(rng.uniform(0.2, 1.5))
        return np.where(on, amp * (2.0 / np.pi) * np.arcsin(np.sin(2 * np.pi * f * tt)), 0.0)
    if kind == "trapezoid":
        f = float(rng.uniform(0.2, 1.0))
        tri = (2.0 / np.pi) * np.arcsin(np.sin(2 * np.pi * f * tt))
        return np.where(on, amp * np.clip(1.6 * tri, -1.0, 1.0), 0.0)
    if kind == "sine":
        f = float(rng.uniform(0.3, 6.0))
        return np.where(on, 0.5 * amp * np.sin(2 * np.pi * f * tt), 0.0)
    # random staircase: holds of random length at random levels (a pilot's stick or a PRBS)
    u = np.zeros_like(t)
    edge = lead
    while edge < dur:
        hold = float(rng.uniform(0.08, 0.8))
        u = np.where(t >= edge, float(rng.uniform(-amp, amp)), u)
        edge += hold
    return u


def _simulate(p: Plant, t: np.ndarray, u: np.ndarray, hm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # noqa: PLR0915
    """Crank angle as the LVDT reads it and surface angle, every :data:`PLANT_S`; ``u`` and ``hm`` on that grid."""
    n = t.size
    lvdt = np.empty(n)
    surf = np.empty(n)
    tick = max(1, round(1.0 / (p.control_hz * PLANT_S)))
    wv = 2 * math.pi * p.velocity_bw_hz
    kp = 2 * math.pi * p.position_bw_hz
    ki = wv * wv / 5.0
    share = min(max(p.surface_share, 0.05), 0.95)
    rigid = p.link_hz <= 0.0
    wl = 2 * math.pi * p.link_hz
    k_link = wl * wl * (1.0 - share)  # relative-mode stiffness per unit surface inertia
    c_link = 2 * p.link_zeta * wl * (1.0 - share)
    th_a = th_s = float(u[0])
    w_a = w_s = 0.0
    cur = 0.0
    integ = 0.0
    i_ref = 0.0
    queue: list[float] = [0.0] * (p.compute_delay_ticks + 1)
    gap = 0.0  # backlash: the crank's position inside the gap
    for k in range(n):
        read = (180.0 / math.pi) * math.sin(math.radians(th_a)) if p.crank else th_a
        if k % tick == 0:
            v_ref = kp * (u[k] - read)
            v_ref = min(max(v_ref, -p.speed_down), p.speed_up)
            ev = v_ref - w_a
            raw = wv * ev + integ
            lo, hi = -p.accel_down, p.accel_up
            out = min(max(raw, lo), hi)
            if out == raw or raw * ev < 0.0:
                integ += ki * ev * tick * PLANT_S
            queue.append(out)
            i_ref = queue.pop(0)
        cur += (i_ref - cur) * PLANT_S / p.current_tau_s
        # linkage: through the backlash gap to the surface's spring (rigid: the surface is the crank)
        if rigid:
            link = 0.0
        else:
            rel = th_a - th_s
            half = 0.5 * p.backlash_deg
            if half > 0.0:
                gap = min(max(gap, rel - half), rel + half)
                rel = rel - gap
            link = k_link * rel + c_link * (w_a - w_s)
        centre = th_s - p.spring_centre_deg
        spring = p.spring * (centre + p.spring_cubic * centre**3)
        load = p.hm_gain * hm[k]
        drive = cur - p.viscous * w_a - spring + load if rigid else cur - p.viscous * w_a - link * share / (1.0 - share)
        stiction = p.coulomb * p.stribeck
        if w_a == 0.0 and abs(drive) <= stiction:
            acc = 0.0
        else:
            sgn = math.copysign(1.0, w_a) if w_a != 0.0 else math.copysign(1.0, drive)
            fric = p.coulomb * (1.0 + (p.stribeck - 1.0) * math.exp(-abs(w_a) / 2.0))
            acc = drive - fric * sgn
            if w_a != 0.0 and (w_a + acc * PLANT_S) * w_a < 0.0:
                acc = -w_a / PLANT_S
        w_a += acc * PLANT_S
        th_a += w_a * PLANT_S
        if abs(th_a) >= p.stop_deg and th_a * w_a > 0.0:
            th_a = math.copysign(p.stop_deg, th_a)
            w_a = 0.0
        if rigid:
            th_s, w_s = th_a, w_a
        else:
            acc_s = link - spring + load
            w_s += acc_s * PLANT_S
            th_s += w_s * PLANT_S
        lvdt[k] = read
        surf[k] = th_s
    return lvdt, surf


def _sense(y: np.ndarray, ts: np.ndarray, s: Sensor, rng: np.random.Generator) -> np.ndarray:
    """The sensor's reading of the true ``y`` at the logged instants ``ts``."""
    out = s.scale * y + s.offset + s.drift_per_s * ts
    if s.tone_amp:
        out = out + s.tone_amp * np.sin(2 * np.pi * s.tone_hz * ts + float(rng.uniform(0, 2 * np.pi)))
    if s.noise:
        out = out + rng.normal(0.0, s.noise, ts.size)
    for _ in range(s.spikes):
        out[int(rng.integers(0, ts.size))] += float(rng.choice([-1.0, 1.0])) * s.spike_amp
    dt = float(np.median(np.diff(ts)))
    for _ in range(s.dropouts):
        a = int(rng.integers(1, ts.size - 1))
        b = min(ts.size, a + max(1, round(s.dropout_s / dt)))
        out[a:b] = out[a - 1]
    if s.counts:
        out = np.round(out / s.counts) * s.counts
    return out


def recipe(seed: int, *, short: bool = True) -> Fuzz:  # noqa: PLR0915
    """Draw one record's recipe: plant, sensors, logger and demand, its effects listed by what they are."""
    rng = np.random.default_rng(seed)
    p = Plant(position_bw_hz=float(rng.uniform(2.5, 12.0)), velocity_bw_hz=float(rng.uniform(25.0, 80.0)))
    p.accel_up = p.accel_down = float(rng.uniform(800.0, 8000.0))
    p.speed_up = p.speed_down = float(rng.uniform(40.0, 300.0))
    effects: list[str] = []

    def pick(prob: float) -> bool:
        return bool(rng.uniform() < prob)

    if pick(0.25):
        p.accel_down *= float(rng.uniform(0.4, 0.8))
        p.speed_down *= float(rng.uniform(0.5, 0.85))
        effects.append("direction asymmetry")
    if pick(0.3):
        p.coulomb = float(rng.uniform(0.01, 0.08)) * min(p.accel_up, p.accel_down)
        p.stribeck = float(rng.uniform(1.0, 2.0))
        effects.append("friction and stick-slip")
    if pick(0.25):
        p.spring = float(rng.uniform(20.0, 400.0))
        p.spring_centre_deg = float(rng.uniform(-3.0, 3.0))
        p.spring_cubic = float(rng.uniform(0.0, 0.01))
        effects.append("position asymmetry (off-centre stiffening spring)")
    if pick(0.3):
        p.link_hz = float(rng.uniform(8.0, 60.0))
        p.link_zeta = float(rng.uniform(0.03, 0.3))
        if pick(0.4):
            p.backlash_deg = float(rng.uniform(0.02, 0.4))
            effects.append("backlash")
        effects.append("linkage mode")
    if pick(0.2):
        p.crank = True
        effects.append("kinematic nonlinearity (crank)")
    if pick(0.2):
        p.control_hz = float(rng.choice([100.0, 200.0, 400.0]))
        p.compute_delay_ticks = int(rng.integers(0, 3))
        effects.append("slow controller")
    amp = float(rng.uniform(1.0, 25.0))
    p.stop_deg = amp * float(rng.uniform(0.85, 2.0))
    if p.stop_deg < amp:
        effects.append("travel stop inside the demand")
    rate = float(rng.choice([50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0]))
    # a short record is a few seconds and never under the contract's 100 rows
    duration = max(float(rng.uniform(1.5, 2.0)), 130.0 / rate) if short else float(rng.uniform(8.0, 40.0))
    has_surface = pick(0.5)
    has_lvdt = not has_surface or pick(0.7)
    hinge = has_surface and pick(0.6)
    if hinge:
        p.hm_gain = float(rng.uniform(0.2, 3.0))
        effects.append("hinge moment")

    def sensor(name: str) -> Sensor:
        s = Sensor(noise=float(rng.choice([0.0, 0.002, 0.01, 0.03])))
        if pick(0.3):
            s.counts = float(rng.choice([0.001, 0.01, 0.05]))
            effects.append(f"{name} counts")
        if pick(0.15):
            s.tone_amp, s.tone_hz = float(rng.uniform(0.01, 0.2)), float(rng.uniform(3.0, 0.45 * rate))
            effects.append(f"{name} tone")
        if pick(0.15):
            s.spikes, s.spike_amp = int(rng.integers(1, 6)), float(rng.uniform(0.5, 5.0))
            effects.append(f"{name} spikes")
        if pick(0.15):
            s.dropouts, s.dropout_s = int(rng.integers(1, 4)), float(rng.uniform(0.02, 0.3))
            effects.append(f"{name} dropouts")
        if pick(0.15):
            s.drift_per_s = float(rng.uniform(-0.05, 0.05))
            effects.append(f"{name} drift")
        if pick(0.2):
            s.scale, s.offset = float(rng.uniform(0.9, 1.1)), float(rng.uniform(-0.3, 0.3))
            effects.append(f"{name} scale and offset")
        return s

    lvdt = sensor("lvdt") if has_lvdt else None
    surface = sensor("surface") if has_surface else None
    jitter = float(rng.choice([0.0, 0.0, 0.1, 0.3])) / rate
    ms = rate <= 500.0 and pick(0.4)
    if jitter:
        effects.append("logger jitter")
    if ms:
        effects.append("millisecond stamps")
    demand = str(rng.choice(["steps", "sweep", "triangle", "trapezoid", "sine", "staircase"]))
    return Fuzz(seed, p, lvdt, surface, rate, duration, jitter, ms, hinge, float(rng.choice([0.0, 2.0])), demand,
                effects)


def record(seed: int, *, short: bool = True) -> tuple[Fuzz, dict[str, np.ndarray]]:
    """One record: the recipe and its logged columns (data-contract names)."""
    f = recipe(seed, short=short)
    rng = np.random.default_rng(seed + 10_000)
    t = np.arange(0.0, f.duration_s, PLANT_S)
    inside = "travel stop inside the demand" in f.effects
    amp = f.plant.stop_deg * 1.3 if inside else max(f.plant.stop_deg / 1.4, 1.0)
    u = _demand(f.demand, t, rng, amp)
    hm = np.zeros_like(t)
    if f.hinge_moment:
        hm_amp = float(rng.uniform(100.0, 1500.0))
        hm = hm_amp * np.sin(2 * np.pi * float(rng.uniform(0.1, 1.5)) * t + float(rng.uniform(0, 6.3)))
    period = 1.0 / f.rate_hz
    inst = np.arange(0.02, f.duration_s - 0.02, period)
    if f.jitter_s:
        inst = inst + np.clip(rng.normal(0.0, f.jitter_s, inst.size), -period / 3, period / 3)
    idx = np.clip(np.round(inst / PLANT_S).astype(int), 0, t.size - 1)
    # the logged command is the demand the controller was given at the sample (held between samples)
    lvdt, surf = _simulate(f.plant, t, u, hm)
    stamps = np.floor(inst * 1e3) / 1e3 if f.ms_stamps else inst
    keep = np.concatenate([[True], np.diff(stamps) > 0])
    cols = {"time_s": stamps[keep] - stamps[0], "command_deg": u[idx][keep]}
    ts = cols["time_s"]
    if f.lvdt is not None:
        cols["position_deg"] = _sense(lvdt[idx][keep], ts, f.lvdt, rng)
    if f.surface is not None:
        cols["surface_deg"] = _sense(surf[idx][keep], ts, f.surface, rng)
    if f.hinge_moment:
        cols["hinge_moment_inlb"] = hm[idx][keep] + (rng.normal(0.0, f.hm_noise, ts.size) if f.hm_noise else 0.0)
    return f, cols


def write(cols: dict[str, np.ndarray], path: Path, meta: dict[str, str] | None = None) -> Path:
    """The columns as a data-contract CSV (metadata lines first)."""
    names = list(cols)
    lines = [f"# {k}: {v}" for k, v in (meta or {}).items()]
    lines.append(",".join(names))
    lines += [",".join(f"{v:.9g}" for v in row) for row in zip(*(cols[n] for n in names), strict=True)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
