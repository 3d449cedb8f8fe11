"""Measured-like records with known truth for the offline-analysis tests.

A registered model is driven through a section-2 maneuver (``ema simulate``'s path) and its outputs get
white sensor noise (TS-90 inclinometer class, table A3: ≈ 0.003°); the LVDT volts are recomputed from
the noisy LVDT degrees so the record stays self-consistent. Effects the models do not have (crosstalk,
dither, a bus voltage, a feedback transport delay, hysteretic damping) are added by the tests
themselves from their defining equations.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from ema_sim.config import load_channel
from ema_sim.io.measured import MeasuredData
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import csv_columns, simulate

SENSOR_NOISE_DEG = 0.003


@lru_cache(maxsize=64)
def _clean(model: str, maneuver: str, load: str | None, channel: str, overrides: tuple) -> MeasuredData:
    mdl, rec, meta = simulate(model, parse_maneuver(maneuver), parse_load(load) if load else None, channel=channel,
                              **dict(overrides))
    return MeasuredData(metadata=meta, source=f"{model}:{maneuver}", **csv_columns(mdl, rec))


def measured(model: str, maneuver: str, load: str | None = None, *, noise_deg: float = SENSOR_NOISE_DEG,
             seed: int = 0, channel: str = "left_wing", metadata: bool = True, **overrides: float) -> MeasuredData:
    """A simulated record with sensor noise on the LVDT and surface angles."""
    clean = _clean(model, maneuver, load, channel, tuple(sorted(overrides.items())))
    rng = np.random.default_rng(seed)
    pos = clean.position_deg + rng.normal(0.0, noise_deg, clean.time_s.size)
    surf = clean.surface_deg + rng.normal(0.0, noise_deg, clean.time_s.size)
    ch = load_channel(channel)
    return replace(clean, position_deg=pos, surface_deg=surf, position_v=np.asarray(ch.position_deg_to_v(pos)),
                   metadata=dict(clean.metadata) if metadata else {})


def delayed(t: np.ndarray, y: np.ndarray, delay_s: float) -> np.ndarray:
    """``y`` as seen ``delay_s`` later (linear interpolation; held at the start)."""
    return np.interp(t - delay_s, t, y)
